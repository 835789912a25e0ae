//! Tests of the tets' choice: the frame tables' score against the general one, the pruned
//! choice against scoring every candidate, and the frame errors.

use super::*;
use proptest::prelude::*;

/// Shape positions `(S + 1) × B` and targets (every third one missing) from `seed`.
fn frame(shapes: usize, bundles: usize, seed: u64) -> (Vec<DVec3>, Vec<DVec3>) {
    let mut state = seed | 1;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let positions = (0..(shapes + 1) * bundles)
        .map(|_| DVec3::new(next(), next(), next()))
        .collect();
    let targets = (0..bundles)
        .map(|n| {
            let t = DVec3::new(next(), next(), next());
            if n % 3 == 2 {
                DVec3::NAN
            } else {
                t
            }
        })
        .collect();
    (positions, targets)
}

proptest! {
    /// The table lookups give bit for bit the score the general formula gives a cloud
    /// point alone, with missing targets and a temporal preference.
    #[test]
    fn point_score_from_the_frame_tables_equals_the_general_score(
        seed in any::<u64>(),
        shapes in 1usize..12,
        bundles in 2usize..20,
        d in 0.0f64..2.0,
    ) {
        let (positions, targets) = frame(shapes, bundles, seed);
        let errors = FrameErrors::new(&positions, bundles, &targets);
        let neighbours: Vec<u32> = (0..bundles as u32).filter(|n| n % 2 == 0).collect();
        let previous = Choice {
            shapes: [1, 0, 0, 0],
            weights: [1.0, 0.0, 0.0, 0.0],
            tet: NO_TET,
            projected: false,
            distance: 0.0,
            fit: false,
        };
        let mut scoring = Scoring {
            shape_positions: &positions,
            num_bundles: bundles,
            neighbours: &neighbours,
            targets: &targets,
            previous: Some(&previous),
            temporal_weight: 0.25,
            pure_errors: &errors.pure,
            distances: &errors.distances,
        };
        for k in 0..=shapes as u32 {
            let general = scoring.score(&[k; 4], &[1.0, 0.0, 0.0, 0.0], d);
            prop_assert_eq!(scoring.point_score(k, d).to_bits(), general.to_bits());
        }
        scoring.distances = &[];
        for k in 0..=shapes as u32 {
            let general = scoring.score(&[k; 4], &[1.0, 0.0, 0.0, 0.0], d);
            prop_assert_eq!(scoring.point_score(k, d).to_bits(), general.to_bits());
        }
    }
}

/// `choose` without any pruning: every candidate scored and kept, all sorted, the best
/// few and every hit refined in that order (the definition the pruned `choose` keeps).
fn choose_unpruned(
    index: &TetIndex,
    cloud: &BundleCloud,
    groups: &[AliasGroups],
    target: DVec3,
    scoring: &Scoring<'_>,
    params: &ChoiceParams,
) -> Option<Choice> {
    let reps = |tet: &[u32; 4]| tet.map(|p| cloud.aliases[p as usize][0]);
    let mut scored: Vec<Scored> = Vec::new();
    let mut inside = Vec::new();
    index.query(target, params.eps, &mut inside);
    let projected = inside.is_empty();
    let point = |p: usize, d: f64| -> Scored {
        let s = scoring.point_score(cloud.aliases[p][0], d);
        (s, NO_TET, [p as u32; 4], [1.0, 0.0, 0.0, 0.0], d)
    };
    if !projected {
        for &(t, l) in &inside {
            let tet = index.tets()[t as usize];
            let w = clean_weights(l);
            scored.push((scoring.score(&reps(&tet), &w, 0.0), t, tet, w, 0.0));
        }
        for (p, q) in cloud.points.iter().enumerate() {
            let d = q.distance(target);
            if d <= params.hit_distance {
                scored.push(point(p, d));
            }
        }
    } else if index.num_tets() > 0 {
        let (mut bounds, mut near) = (Vec::new(), Vec::new());
        index.project_around(target, params.projection_candidates, &mut bounds, &mut near);
        for &(t, l, d) in &near {
            let tet = index.tets()[t as usize];
            let w = clean_weights(l);
            scored.push((scoring.score(&reps(&tet), &w, d), t, tet, w, d));
        }
        for (p, q) in cloud.points.iter().enumerate() {
            scored.push(point(p, q.distance(target)));
        }
    } else {
        lower_simplices(cloud, target, scoring, &mut scored);
    }
    scored.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    let refine = params.alias_refine.max(1);
    let mut best: Option<(f64, Choice)> = None;
    for (r, &(_, t, tet, w, d)) in scored.iter().enumerate() {
        if r >= refine && !(t == NO_TET && d <= params.hit_distance) {
            continue;
        }
        let shapes = refine_aliases(cloud, groups, &tet, &w, scoring);
        let s = scoring.score(&shapes, &w, d);
        if best.as_ref().is_none_or(|(bs, _)| s < *bs) {
            let choice = Choice {
                shapes,
                weights: w,
                tet: t,
                projected,
                distance: d,
                fit: false,
            };
            best = Some((s, choice));
        }
    }
    best.map(|(_, c)| c)
}

proptest! {
    /// The pruned choice (points skipped by distance, candidates that cannot enter the
    /// best few dropped, the nearest point shared with the projection) equals the
    /// unpruned definition: targets inside, outside and on cloud points, aliases that
    /// only the neighbours tell apart, a temporal preference, missing neighbours.
    #[test]
    fn choose_equals_the_unpruned_choice(
        seed in any::<u64>(),
        npoints in 5usize..40,
        on_point in proptest::bool::ANY,
        spread in 0.2f64..3.0,
        hit in prop_oneof![Just(0.0), 0.0f64..0.3],
    ) {
        let nb = 6usize;
        let (positions0, mut targets) = frame(npoints + 8, nb, seed);
        // Shape k's own bundle (0) is cloud point k; shapes npoints.. alias points 1..9,
        // moving the neighbours differently.
        let mut positions = positions0;
        for j in 0..8 {
            positions[(npoints + j) * nb] = positions[(1 + j % (npoints - 1)) * nb];
        }
        positions[0] = DVec3::ZERO;
        let points: Vec<DVec3> = (0..npoints).map(|k| positions[k * nb]).collect();
        let mut aliases: Vec<Vec<u32>> = (0..npoints as u32).map(|k| vec![k]).collect();
        for j in 0..8 {
            aliases[1 + j % (npoints - 1)].push((npoints + j) as u32);
        }
        let cloud = BundleCloud { points: points.clone(), aliases };
        let neighbours: Vec<u32> = (1..nb as u32).collect();
        let groups = alias_groups(&cloud, &neighbours, &positions, nb);
        let tets = crate::tets::generate_tets(&points, &crate::tets::TetConfig::default());
        let index = TetIndex::new(points.clone(), tets).unwrap();
        let mut state = seed ^ 0x9e37_79b9_7f4a_7c15;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 11) as f64) / ((1u64 << 53) as f64) * 2.0 - 1.0
        };
        targets[0] = match on_point {
            true => points[(seed % npoints as u64) as usize],
            false => DVec3::new(next(), next(), next()) * spread,
        };
        let errors = FrameErrors::new(&positions, nb, &targets);
        let previous = Choice {
            shapes: [1, 2, 0, 0],
            weights: [0.5, 0.5, 0.0, 0.0],
            tet: NO_TET,
            projected: false,
            distance: 0.0,
            fit: false,
        };
        let params = ChoiceParams { hit_distance: hit, ..ChoiceParams::default() };
        let mut scratch = Scratch::default();
        for tables in [true, false] {
            let scoring = Scoring {
                shape_positions: &positions,
                num_bundles: nb,
                neighbours: &neighbours,
                targets: &targets,
                previous: Some(&previous),
                temporal_weight: 0.01,
                pure_errors: if tables { &errors.pure } else { &[] },
                distances: if tables { &errors.distances } else { &[] },
            };
            let want = choose_unpruned(&index, &cloud, &groups, targets[0], &scoring, &params);
            let got = choose(&index, &cloud, &groups, targets[0], &scoring, &params, &mut scratch);
            prop_assert_eq!(Some(got), want);
        }
    }
}

#[test]
fn frame_errors_are_squared_distances_and_their_sums_over_present_targets() {
    let (positions, targets) = frame(3, 5, 7);
    let errors = FrameErrors::new(&positions, 5, &targets);
    assert_eq!(errors.distances.len(), 4 * 5);
    for k in 0..4 {
        let mut sum = 0.0;
        for n in 0..5 {
            let d = errors.distances[k * 5 + n];
            if targets[n].is_nan() {
                assert_eq!(d, 0.0);
            } else {
                let e = positions[k * 5 + n] - targets[n];
                assert!((d - (e.x * e.x + e.y * e.y + e.z * e.z)).abs() < 1e-15);
                sum += d;
            }
        }
        assert!((errors.pure[k] - sum).abs() < 1e-14);
    }
}
