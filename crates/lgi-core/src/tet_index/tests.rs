//! Tests of the tet index against brute force: containment scans, nearest tets and the
//! pruned projection against projecting every incident tet.

use super::*;
use crate::tets::{closest_point_in_tet, generate_tets, TetConfig};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};

fn lcg_points(n: usize, seed: u64) -> Vec<DVec3> {
    let mut s = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let mut next = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n)
        .map(|_| DVec3::new(next(), next() * 0.6, next() * 0.3))
        .collect()
}

fn index(n: usize, seed: u64, cfg: &TetConfig) -> TetIndex {
    let pts = lcg_points(n, seed);
    let tets = generate_tets(&pts, cfg);
    TetIndex::new(pts, tets).unwrap()
}

fn brute_query(ix: &TetIndex, p: DVec3, eps: f64) -> Vec<(u32, [f64; 4])> {
    (0..ix.num_tets())
        .filter_map(|t| {
            let b = ix.barycentric(t, p);
            b.iter().all(|&x| x >= -eps).then_some((t as u32, b))
        })
        .collect()
}

fn brute_nearest(ix: &TetIndex, p: DVec3, n: usize) -> Vec<(u32, f64)> {
    let mut all: Vec<(u32, f64)> = ix
        .tets()
        .iter()
        .enumerate()
        .map(|(t, tet)| {
            let (q, _) = closest_point_in_tet(p, tet.map(|i| ix.points()[i as usize]));
            (t as u32, p.distance(q))
        })
        .collect();
    all.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    all.truncate(n);
    all
}

fn config(cases: u32, seed: u64) -> Config {
    Config {
        cases,
        rng_seed: RngSeed::Fixed(seed),
        failure_persistence: None,
        ..Config::default()
    }
}

#[test]
fn single_tet_contains_its_centroid_and_vertices_but_not_outside_points() {
    let pts = vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z];
    let ix = TetIndex::new(pts, vec![[0, 1, 2, 3]]).unwrap();
    let mut out = Vec::new();
    ix.query(DVec3::splat(0.25), 1e-9, &mut out);
    assert_eq!(out.len(), 1);
    assert!(out[0].1.iter().all(|&b| (b - 0.25).abs() < 1e-15));
    for v in [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z] {
        out.clear();
        ix.query(v, 1e-9, &mut out);
        assert_eq!(out.len(), 1, "{v}");
    }
    // Beyond the box by 5e-8 but within eps = 1e-7: found (the grid's box has a margin).
    out.clear();
    ix.query(DVec3::new(1.0 + 5e-8, 0.0, 0.0), 1e-7, &mut out);
    assert_eq!(out.len(), 1);
    out.clear();
    ix.query(DVec3::new(1.0 + 5e-8, 0.0, 0.0), 1e-9, &mut out);
    ix.query(DVec3::splat(0.4), 1e-9, &mut out);
    ix.query(DVec3::new(-0.1, 0.2, 0.2), 1e-9, &mut out);
    ix.query(DVec3::splat(5.0), 1e-9, &mut out);
    ix.query(DVec3::NAN, 1e-9, &mut out);
    assert!(out.is_empty());
}

#[test]
fn bad_input_is_an_input_error() {
    let pts = vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z];
    assert!(matches!(
        TetIndex::new(pts.clone(), vec![[0, 1, 2, 4]]),
        Err(LgiError::Input(_))
    ));
    let mut bad = pts;
    bad[2] = DVec3::NAN;
    assert!(matches!(
        TetIndex::new(bad, vec![[0, 1, 2, 3]]),
        Err(LgiError::Input(_))
    ));
}

#[test]
fn empty_and_flat_tets_contain_nothing_but_flat_ones_are_still_nearest() {
    let ix = TetIndex::new(vec![DVec3::ZERO], vec![]).unwrap();
    let mut out = Vec::new();
    ix.query(DVec3::ZERO, 1e-9, &mut out);
    assert!(out.is_empty());
    let mut near = Vec::new();
    ix.nearest(DVec3::ZERO, 3, &mut near);
    assert!(near.is_empty());

    let flat = vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(0.5, 0.5, 0.0)];
    let ix = TetIndex::new(flat, vec![[0, 1, 2, 3]]).unwrap();
    ix.query(DVec3::new(0.2, 0.2, 0.0), 1e-9, &mut out);
    ix.query(DVec3::new(0.2, 0.2, 0.0), 1.0, &mut out);
    assert!(out.is_empty());
    ix.nearest(DVec3::new(0.2, 0.2, 1.0), 3, &mut near);
    assert_eq!(near.len(), 1);
    assert!((near[0].2 - 1.0).abs() < 1e-12);
}

#[test]
fn query_and_nearest_append_without_touching_existing_entries() {
    let ix = index(40, 5, &TetConfig::default());
    let p = ix.points()[3];
    let mut out = vec![(u32::MAX, [9.0; 4])];
    ix.query(p, 1e-9, &mut out);
    assert_eq!(out[0].0, u32::MAX);
    assert_eq!(out[1..], brute_query(&ix, p, 1e-9)[..]);
    let mut near = vec![(u32::MAX, [9.0; 4], -1.0)];
    ix.nearest(DVec3::splat(3.0), 5, &mut near);
    assert_eq!(near[0].0, u32::MAX);
    let got: Vec<(u32, f64)> = near[1..].iter().map(|e| (e.0, e.2)).collect();
    assert_eq!(got, brute_nearest(&ix, DVec3::splat(3.0), 5));
}

#[test]
fn large_eps_falls_back_to_scanning_and_still_matches_brute_force() {
    let ix = index(30, 9, &TetConfig::default());
    let mut out = Vec::new();
    for p in [DVec3::new(1.05, 0.3, 0.1), DVec3::new(0.5, 0.3, 0.15)] {
        out.clear();
        ix.query(p, 0.1, &mut out);
        assert_eq!(out, brute_query(&ix, p, 0.1));
    }
}

/// A random point of the kind named by `kind` on tet `t`: 0 vertex, 1 edge, 2 face, 3 interior,
/// 5 just outside a vertex (kind 4, a point near the cloud, is made by the caller).
fn special_point(ix: &TetIndex, t: usize, kind: u8, w: [f64; 4]) -> DVec3 {
    let v = ix.tets()[t].map(|i| ix.points()[i as usize]);
    let mut w = w;
    match kind {
        0 => w = [1.0, 0.0, 0.0, 0.0],
        // Just beyond a vertex, by less than eps = 1e-7 in every barycentric coordinate.
        5 => w = [1.0 + 9e-8, -3e-8, -3e-8, -3e-8],
        1 => {
            w[2] = 0.0;
            w[3] = 0.0;
        }
        2 => w[3] = 0.0,
        _ => {}
    }
    let s: f64 = w.iter().sum();
    // Rotate which vertices get the zero weights so every vertex, edge and face is hit.
    let r = (w[0] * 1e6) as usize % 4;
    (0..4).map(|i| v[(i + r) % 4] * (w[i] / s)).sum()
}

/// `query(p, eps)` equals the scan of every tet, at the tolerances the grid answers.
fn query_equals_brute_force(ix: &TetIndex, p: DVec3) -> Result<(), TestCaseError> {
    let mut out = Vec::new();
    for eps in [0.0, 1e-9, 1e-7] {
        out.clear();
        ix.query(p, eps, &mut out);
        prop_assert_eq!(&out, &brute_query(ix, p, eps));
    }
    Ok(())
}

proptest! {
    #![proptest_config(config(128, 0x9e1d_0001))]

    #[test]
    fn query_matches_brute_force_on_random_and_special_points(
        n in 5usize..80,
        seed in any::<u64>(),
        k in 3usize..12,
        samples in prop::collection::vec(
            (any::<prop::sample::Index>(), 0u8..6, [0.01..1.0f64, 0.01..1.0, 0.01..1.0, 0.01..1.0],
             (-0.2..1.2f64, -0.2..0.8f64, -0.2..0.5f64)),
            20..60),
    ) {
        let cfg = TetConfig { neighbours: k, ..TetConfig::default() };
        let ix = index(n, seed, &cfg);
        prop_assume!(ix.num_tets() > 0);
        let mut out = Vec::new();
        for (t, kind, w, (x, y, z)) in samples {
            let p = if kind == 4 {
                DVec3::new(x, y, z)
            } else {
                special_point(&ix, t.index(ix.num_tets()), kind, w)
            };
            query_equals_brute_force(&ix, p)?;
            if kind != 4 {
                // A point built on a tet is found in that tet (up to rounding).
                out.clear();
                ix.query(p, if kind == 5 { 1e-7 } else { 1e-9 }, &mut out);
                prop_assert!(!out.is_empty());
            }
        }
    }

    #[test]
    fn nearest_matches_brute_force_closest_points(
        n in 5usize..60,
        seed in any::<u64>(),
        count in 1usize..12,
        queries in prop::collection::vec((-1.0..2.0f64, -1.0..1.6f64, -1.0..1.3f64), 10),
    ) {
        let ix = index(n, seed, &TetConfig::default());
        let mut out = Vec::new();
        for (x, y, z) in queries {
            let p = DVec3::new(x, y, z);
            out.clear();
            ix.nearest(p, count, &mut out);
            let got: Vec<(u32, f64)> = out.iter().map(|e| (e.0, e.2)).collect();
            prop_assert_eq!(got, brute_nearest(&ix, p, count));
            for (t, b, d) in &out {
                let v = ix.tets()[*t as usize].map(|i| ix.points()[i as usize]);
                let q: DVec3 = (0..4).map(|i| v[i] * b[i]).sum();
                prop_assert!((p.distance(q) - d).abs() < 1e-9);
                prop_assert!(b.iter().all(|&x| x >= 0.0));
            }
        }
    }
}

#[test]
fn index_is_send_and_sync() {
    fn check<T: Send + Sync>() {}
    check::<TetIndex>();
}

#[test]
fn nearest_around_returns_exactly_the_tets_of_the_nearest_points_with_exact_distances() {
    let cfg = TetConfig::default();
    let ix = index(60, 11, &cfg);
    let pts = ix.points().to_vec();
    for (qi, q) in [
        DVec3::new(2.0, -1.0, 0.5),
        DVec3::new(0.3, 0.2, 0.1),
        DVec3::splat(-3.0),
    ]
    .into_iter()
    .enumerate()
    {
        for k in [1usize, 3] {
            let mut out = Vec::new();
            ix.nearest_around(q, k, &mut out);
            // Brute force: the k nearest points (ties by index) and every tet touching one.
            let mut order: Vec<usize> = (0..pts.len()).collect();
            order.sort_by(|&a, &b| {
                pts[a]
                    .distance_squared(q)
                    .total_cmp(&pts[b].distance_squared(q))
                    .then(a.cmp(&b))
            });
            let near = &order[..k];
            let mut want: Vec<u32> = (0..ix.num_tets() as u32)
                .filter(|&t| {
                    ix.tets()[t as usize]
                        .iter()
                        .any(|v| near.contains(&(*v as usize)))
                })
                .collect();
            want.sort_unstable();
            let mut got: Vec<u32> = out.iter().map(|c| c.0).collect();
            got.sort_unstable();
            assert_eq!(got, want, "query {qi}, k {k}");
            for w in out.windows(2) {
                assert!(w[0].2 <= w[1].2);
            }
            for &(t, _, d) in &out {
                let corners = ix.tets()[t as usize].map(|i| pts[i as usize]);
                let (c, _) = crate::tets::closest_point_in_tet(q, corners);
                assert!((c.distance(q) - d).abs() <= 1e-12 * (1.0 + d));
            }
        }
    }
}

/// `project_around(q, n)` equals projecting every tet around the nearest point, dropping
/// closest points at a vertex and keeping the n nearest.
fn projection_equals_unpruned(ix: &TetIndex, q: DVec3, n: usize) -> Result<(), TestCaseError> {
    let (mut bounds, mut got, mut all) = (Vec::new(), Vec::new(), Vec::new());
    ix.project_around(q, n, &mut bounds, &mut got);
    ix.nearest_around(q, 1, &mut all);
    all.retain(|c| c.1.iter().all(|&b| b < 1.0 - 1e-12));
    all.truncate(n);
    prop_assert_eq!(&got, &all);
    Ok(())
}

proptest! {
    #![proptest_config(config(96, 0x9e1d_0007))]

    /// The pruned projection gives bit for bit what projecting every incident tet, dropping
    /// vertex closest points and keeping the n nearest gives.
    #[test]
    fn project_around_equals_the_unpruned_projection_filtered_and_truncated(
        npts in 5usize..80,
        seed in any::<u64>(),
        n in 1usize..12,
        samples in prop::collection::vec(
            (-1.5f64..1.5, -1.5f64..1.5, -1.5f64..1.5), 1..16),
    ) {
        let ix = index(npts, seed, &TetConfig::default());
        for (x, y, z) in samples {
            // Far and near points, outside and inside the cloud.
            for q in [DVec3::new(x, y, z), DVec3::new(x, y, z) * 3.0] {
                projection_equals_unpruned(&ix, q, n)?;
            }
        }
    }

    /// The same on arbitrary tets over a cloud with a coplanar part: flat tets (singular
    /// frames, bound 0), tets with a repeated corner and sliver tets go through the inline
    /// corners and the bound like any other.
    #[test]
    fn project_around_equals_the_unpruned_projection_with_flat_and_degenerate_tets(
        npts in 5usize..40,
        seed in any::<u64>(),
        picks in prop::collection::vec(any::<[u16; 4]>(), 1..120),
        n in 1usize..10,
        samples in prop::collection::vec(
            (-1.5f64..1.5, -1.5f64..1.5, -1.5f64..1.5), 1..10),
    ) {
        let mut pts = lcg_points(npts, seed);
        // A third of the points on the plane z = 0: tets among them are flat.
        for p in pts.iter_mut().step_by(3) {
            p.z = 0.0;
        }
        let tets: Vec<Tet> = picks
            .iter()
            .map(|c| c.map(|i| u32::from(i) % npts as u32))
            .collect();
        let ix = TetIndex::new(pts, tets).unwrap();
        for (x, y, z) in samples {
            for q in [DVec3::new(x, y, z), DVec3::new(x, y, 0.0), DVec3::new(x, y, z) * 3.0] {
                projection_equals_unpruned(&ix, q, n)?;
            }
        }
    }
}

proptest! {
    #![proptest_config(config(256, 0x9e1d_0008))]

    /// The face-plane bound of a tet seen from a corner never exceeds the exact distance to
    /// the tet, and is that distance for a point straight out from a face's interior.
    #[test]
    fn plane_lower_bound_is_below_the_exact_distance_and_exact_off_a_face(
        corners in prop::array::uniform4((-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0)),
        point in (-2.0f64..2.0, -2.0f64..2.0, -2.0f64..2.0),
        corner in 0usize..4,
        face in 0usize..4,
        w in (0.05f64..1.0, 0.05f64..1.0, 0.05f64..1.0),
        out in 0.01f64..1.0,
    ) {
        let c = corners.map(|(x, y, z)| DVec3::new(x, y, z));
        prop_assume!(crate::tets::tet_quality(c) > 0.02);
        // Seen from `corner`, the others in cyclic order (as the projection passes them).
        let o = c[corner];
        let e = [1, 2, 3].map(|k| c[(corner + k) % 4] - o);
        let bound = |p: DVec3| nearest::plane_lower_bound(e, p - o);
        let p = DVec3::new(point.0, point.1, point.2);
        let (q, _) = closest_point_in_tet(p, c);
        prop_assert!(bound(p) <= p.distance(q) * (1.0 + 1e-12) + 1e-15);
        // A point `out` along the outward normal of a face, from inside that face.
        let f: Vec<DVec3> = (0..4).filter(|&k| k != face).map(|k| c[k]).collect();
        let s = w.0 + w.1 + w.2;
        let inside = (f[0] * w.0 + f[1] * w.1 + f[2] * w.2) / s;
        let mut n = (f[1] - f[0]).cross(f[2] - f[0]).normalize();
        if n.dot(c[face] - f[0]) > 0.0 {
            n = -n;
        }
        let away = inside + n * out;
        prop_assert!((bound(away) - out).abs() <= 1e-9, "{} against {}", bound(away), out);
    }
}

proptest! {
    #![proptest_config(config(24, 0x9e1d_0009))]

    /// A cloud crowded around one point (as bundle clouds are around the neutral) has cells
    /// listing many tets; those are split, and the sub-cells answer exactly as a scan does.
    #[test]
    fn query_in_split_dense_cells_matches_brute_force(
        seed in any::<u64>(),
        crowd in 150usize..400,
        k in 6usize..12,
        samples in prop::collection::vec(
            (any::<prop::sample::Index>(), 0u8..6, [0.01..1.0f64, 0.01..1.0, 0.01..1.0, 0.01..1.0],
             (-0.02..0.02f64, -0.02..0.02f64, -0.02..0.02f64)),
            20..60),
    ) {
        // A few points over the unit box, the crowd within 0.01 of its centre.
        let centre = DVec3::splat(0.5);
        let mut pts = lcg_points(40, seed);
        pts.extend(lcg_points(crowd, seed ^ 0x5a5a).iter().map(|p| centre + (*p - centre) * 0.02));
        let tets = generate_tets(&pts, &TetConfig { neighbours: k, ..TetConfig::default() });
        let ix = TetIndex::new(pts, tets).unwrap();
        prop_assert!(ix.grid_split().0 > 0, "no cell was split");
        for (t, kind, w, (x, y, z)) in samples {
            let p = if kind == 4 {
                centre + DVec3::new(x, y, z)
            } else {
                special_point(&ix, t.index(ix.num_tets()), kind, w)
            };
            query_equals_brute_force(&ix, p)?;
        }
    }
}
