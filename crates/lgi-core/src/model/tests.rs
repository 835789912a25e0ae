//! Tests of the model: sewing plans for missing bundles against plans from scratch, the fused
//! sewing pass against the staged one, jaw bins (members, hysteresis, reported ids) and saved
//! models of every kind loading back to identical frames.

use super::prepare::Prepared;
use super::solve::RESIDUAL_TOLERANCE;
use super::*;
use crate::choose::{Choice, NO_TET};
use crate::geodesic::FieldCache;
use crate::jaw::{JawBins, JawParams, JawRig};
use crate::mesh::Mesh;
use crate::sew::context::SewContext;
use crate::sew::Pieces;
use glam::DVec2;

/// A wavy n×n grid (UVs = xy) with 6 smooth shapes.
fn patch(n: usize) -> Dataset {
    patch_with(n, 6)
}

/// A wavy n×n grid (UVs = xy), each quad split into two triangles, with `shapes` smooth
/// shapes (the model-file tests share it).
pub(crate) fn patch_with(n: usize, shapes: usize) -> Dataset {
    let mut positions = Vec::new();
    let mut uvs = Vec::new();
    for y in 0..n {
        for x in 0..n {
            let (u, v) = (x as f64 / (n - 1) as f64, y as f64 / (n - 1) as f64);
            positions.push(DVec3::new(u, v, 0.1 * (3.0 * u).sin() * (2.0 * v).cos()));
            uvs.push(DVec2::new(u, v));
        }
    }
    let triangles: Vec<[u32; 3]> = patch_quads(n)
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    let mesh = Mesh {
        positions: positions.clone(),
        uv_triangles: triangles.clone(),
        triangles,
        uvs,
    };
    let shapes = (0..shapes)
        .map(|k| {
            let f = k as f64 + 1.0;
            let pos = positions
                .iter()
                .map(|p| *p + DVec3::new(0.0, 0.0, 0.05 * (f * p.x + 0.3 * f * p.y).sin()))
                .collect();
            (format!("s{k}"), pos)
        })
        .collect();
    Dataset::from_shape_positions(mesh, shapes).unwrap()
}

/// The quads of [`patch_with`]'s grid, row by row (corners counter-clockwise).
pub(crate) fn patch_quads(n: usize) -> Vec<[u32; 4]> {
    let n32 = n as u32;
    (0..n32 - 1)
        .flat_map(|y| (0..n32 - 1).map(move |x| y * n32 + x))
        .map(|a| [a, a + 1, a + n32 + 1, a + n32])
        .collect()
}

/// Same sparsity pattern, values within `tol` (0: equal).
fn assert_weights_match(a: &SparseWeights, b: &SparseWeights, tol: f64, missing: &[u32]) {
    assert_eq!(a.row_start, b.row_start, "{missing:?}");
    assert_eq!(a.cols, b.cols, "{missing:?}");
    for (x, y) in a.vals.iter().zip(&b.vals) {
        assert!((x - y).abs() <= tol, "{missing:?}: {x} vs {y}");
    }
}

/// Seeded pseudo-random numbers in [0, 1) (a 64-bit LCG: reproducible, not good).
fn uniforms(seed: u64) -> impl FnMut() -> f64 {
    let mut s = seed;
    move || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// `n` markers on the surface of [`patch`] at seeded pseudo-random (u, v) in [0.05, 0.95]².
fn patch_markers(seed: u64, n: usize) -> Vec<DVec3> {
    let mut uniform = uniforms(seed);
    let mut next = || 0.05 + 0.9 * uniform();
    (0..n)
        .map(|_| {
            let (u, v) = (next(), next());
            DVec3::new(u, v, 0.1 * (3.0 * u).sin() * (2.0 * v).cos())
        })
        .collect()
}

#[test]
fn plan_for_missing_bundles_equals_the_plan_built_from_scratch() {
    let data = patch(24);
    let markers = patch_markers(3, 30);
    let model = Model::build(&data, &markers, &BuildConfig::default()).unwrap();
    let ctx = model
        .sewing
        .geometry()
        .context(&model.dataset, &model.bundles);
    for missing in [vec![0u32], vec![3, 17], vec![5, 6, 7, 29]] {
        let present: Vec<u32> = (0..30).filter(|b| !missing.contains(b)).collect();
        let fresh = ctx.plan(&present).unwrap();
        let derived = ctx
            .plan_without(&present, model.sewing.full(), model.sewing.support())
            .unwrap();
        assert_weights_match(
            &fresh.weights().to_sparse(),
            &derived.weights().to_sparse(),
            1e-12,
            &missing,
        );
    }
}

/// [`patch`] with a mouth-like slit cut across its middle: its rim and the slit are barriers
/// in UV.
fn slit_patch(n: usize) -> Dataset {
    let data = patch(n);
    let mut mesh = data.neutral().clone();
    let keep = |t: &[u32; 3]| {
        let c = t.iter().map(|&v| mesh.uvs[v as usize]).sum::<DVec2>() / 3.0;
        !((c.y - 0.5).abs() < 0.03 && (0.3..0.7).contains(&c.x))
    };
    let triangles: Vec<[u32; 3]> = mesh.triangles.iter().copied().filter(keep).collect();
    mesh.triangles = triangles.clone();
    mesh.uv_triangles = triangles;
    let shapes = (0..data.num_shapes())
        .map(|k| {
            let pos = (0..mesh.num_vertices())
                .map(|v| mesh.positions[v] + data.displacement(k, v))
                .collect();
            (format!("s{k}"), pos)
        })
        .collect();
    Dataset::from_shape_positions(mesh, shapes).unwrap()
}

/// Over a take with a fresh set of missing markers on every frame (10–30 % missing, with runs
/// of neighbouring markers so that rows shared by two and three missing bundles occur), the
/// plans made from the rows kept without one bundle or a pair have the sparsity of the plans
/// derived from the full plan row by row, and the weights of both and of the plans built from
/// scratch to 1e-12 (a kept row was computed with more sites present, which moves the last
/// bits of spade's areas); on a patch and on one with a slit (barriers); the kept rows were
/// used.
#[test]
fn plans_from_kept_rows_match_plans_derived_from_the_full_plan_on_fresh_missing_sets() {
    for (name, data) in [("patch", patch(24)), ("slit", slit_patch(24))] {
        let markers = patch_markers(5, 40);
        let model = Model::build(&data, &markers, &BuildConfig::default()).unwrap();
        assert!(
            name == "patch" || !model.sewing.space().barriers.is_empty(),
            "the slit makes barriers"
        );
        let ctx = model
            .sewing
            .geometry()
            .context(&model.dataset, &model.bundles);
        let mut uniform = uniforms(11);
        let mut worst = 0.0f64;
        for frame in 0..120 {
            let p = 0.1 + 0.2 * (frame % 3) as f64 / 2.0;
            let start = (uniform() * 40.0) as u32;
            let missing: Vec<u32> = (0..40u32)
                .filter(|&b| uniform() < p || (frame % 4 == 0 && (b + 40 - start) % 40 < 3))
                .collect();
            let present: Vec<u32> = (0..40).filter(|b| !missing.contains(b)).collect();
            let kept = model
                .sewing
                .plan_for(&model.dataset, &model.bundles, &present)
                .unwrap();
            let derived = ctx
                .plan_without(&present, model.sewing.full(), model.sewing.support())
                .unwrap();
            let what = format!("{name}, frame {frame}, missing {missing:?}");
            let (kept, derived) = (kept.weights().to_sparse(), derived.weights().to_sparse());
            assert_eq!(kept.row_start, derived.row_start, "{what}");
            assert_weights_match(&kept, &derived, 1e-12, &missing);
            let fresh = ctx.plan(&present).unwrap().weights().to_sparse();
            assert_weights_match(&kept, &fresh, 1e-12, &missing);
            for (a, b) in kept.vals.iter().zip(&derived.vals) {
                worst = worst.max((a - b).abs());
            }
        }
        eprintln!("{name}: kept vs derived rows differ by at most {worst:e}");
        let (ones, pairs) = model.sewing.kept_rows();
        assert!(
            ones > 0 && pairs > 0,
            "{name}: kept {ones} single, {pairs} pair rows"
        );
    }
}

/// A cached distance field may reach farther than a plan asks: plans for a sequence of
/// missing sets built with the model's warm cache equal those built with an empty one
/// exactly, with a detour ratio tight enough that edge-path zigzag drops weights.
#[test]
fn plans_from_cached_distance_fields_equal_plans_from_fresh_fields() {
    let data = patch(24);
    let markers = patch_markers(11, 30);
    let config = BuildConfig {
        detour_ratio: 1.02,
        ..BuildConfig::default()
    };
    let model = Model::build(&data, &markers, &config).unwrap();
    let loose = Model::build(&data, &markers, &BuildConfig::default()).unwrap();
    assert!(
        model.sewing.full().weights().num_entries() < loose.sewing.full().weights().num_entries(),
        "the tight ratio drops weights"
    );
    assert!(
        !model.sewing.geometry().fields().is_empty(),
        "the full plan filled the cache"
    );
    for missing in [
        vec![4u32],
        vec![4, 5],
        vec![3, 4, 5, 6],
        vec![4],
        vec![20, 21, 22],
    ] {
        let present: Vec<u32> = (0..30).filter(|b| !missing.contains(b)).collect();
        let warm = model
            .sewing
            .geometry()
            .context(&model.dataset, &model.bundles)
            .plan_without(&present, model.sewing.full(), model.sewing.support())
            .unwrap();
        let empty = FieldCache::default();
        let cold = SewContext {
            fields: &empty,
            ..model
                .sewing
                .geometry()
                .context(&model.dataset, &model.bundles)
        }
        .plan_without(&present, model.sewing.full(), model.sewing.support())
        .unwrap();
        assert_weights_match(
            &warm.weights().to_sparse(),
            &cold.weights().to_sparse(),
            0.0,
            &missing,
        );
    }
}

/// The patch's jaw: a hinge about the frame's first axis (x for the identity) through a
/// pivot behind and above the patch, weight 1 below y = 0.35, 0 above y = 0.65, linear
/// between.
fn patch_rig(data: &Dataset, frame: glam::DMat3) -> JawRig {
    let weights = data
        .neutral()
        .positions
        .iter()
        .map(|p| ((0.65 - p.y) / 0.3).clamp(0.0, 1.0))
        .collect();
    JawRig::with_frame(DVec3::new(0.5, 0.8, -0.6), weights, frame).unwrap()
}

/// Dataset shape jaw openings of [`jaw_patch`] (radians).
const OPENINGS: [f64; 10] = [0.0, 0.0, 0.0, 0.2, 0.2, 0.3, 0.3, 0.4, 0.5, 0.5];

/// The patch's expressions, each at its opening from [`OPENINGS`] (skinned with the rig),
/// plus markers only where the jaw weight is constant over their triangle (so a marker's
/// own weight skins it exactly like its triangle's vertices).
fn jaw_patch() -> (Dataset, JawRig, Vec<JawParams>, Vec<DVec3>) {
    jaw_patch_in(glam::DMat3::IDENTITY)
}

/// [`jaw_patch`] with the rig's axes the columns of `frame`.
fn jaw_patch_in(frame: glam::DMat3) -> (Dataset, JawRig, Vec<JawParams>, Vec<DVec3>) {
    let base = patch(24);
    let rig = patch_rig(&base, frame);
    let x0 = &base.neutral().positions;
    let mut shapes = Vec::new();
    let mut thetas = Vec::new();
    for (k, &open) in OPENINGS.iter().enumerate() {
        let theta = JawParams {
            open,
            ..JawParams::ZERO
        };
        let expr: Vec<DVec3> = (0..x0.len())
            .map(|v| x0[v] + base.displacement(k % base.num_shapes(), v))
            .collect();
        let mut posed = expr.clone();
        rig.skin(&expr, theta, &mut posed).unwrap();
        shapes.push((format!("e{k}_open{open}"), posed));
        thetas.push(theta);
    }
    let data = Dataset::from_shape_positions(base.neutral().clone(), shapes).unwrap();
    let mut markers = Vec::new();
    for &y in &[0.08, 0.17, 0.26, 0.74, 0.83, 0.92] {
        for &x in &[0.1, 0.3, 0.5, 0.7, 0.9] {
            let (u, v) = (x + 0.013 * y, y);
            markers.push(DVec3::new(u, v, 0.1 * (3.0 * u).sin() * (2.0 * v).cos()));
        }
    }
    (data, rig, thetas, markers)
}

fn binned_model(edges: Vec<f64>, overlap: f64) -> Result<(Model, Dataset, Vec<JawParams>)> {
    let (data, rig, thetas, markers) = jaw_patch();
    let model = jaw_model(
        &data,
        &markers,
        rig,
        &thetas,
        Some(JawBins { edges, overlap }),
    )?;
    Ok((model, data, thetas))
}

/// A model of `data` (default config) with the jaw `rig`, the shapes' poses and `bins`.
fn jaw_model(
    data: &Dataset,
    markers: &[DVec3],
    rig: JawRig,
    thetas: &[JawParams],
    bins: Option<JawBins>,
) -> Result<Model> {
    let jaw = JawInput {
        rig,
        shape_thetas: thetas.to_vec(),
        bins,
    };
    Model::build_shared(
        Arc::new(data.clone()),
        markers,
        &BuildConfig::default(),
        Some(jaw),
    )
}

fn shape_mesh(data: &Dataset, k: usize) -> Vec<DVec3> {
    let x0 = &data.neutral().positions;
    (0..x0.len())
        .map(|v| x0[v] + data.displacement(k, v))
        .collect()
}

/// A solved frame: its vertices and what the solve says about it.
pub(crate) struct Solved {
    pub(crate) vertices: Vec<DVec3>,
    pub(crate) info: FrameInfo,
}

/// [`Model::solve`] into a buffer of its own, frame by frame.
pub(crate) fn solve_with(
    model: &Model,
    frames: &[Vec<DVec3>],
    options: &SolveOptions,
    previous: Option<&FrameState>,
) -> Result<Vec<Solved>> {
    let nv = model.dataset().num_vertices();
    let mut vertices = vec![DVec3::ZERO; frames.len() * nv];
    let infos = model.solve(frames, options, previous, &mut vertices, |_| {})?;
    Ok(infos
        .into_iter()
        .zip(vertices.chunks(nv.max(1)))
        .map(|(info, v)| Solved {
            vertices: v.to_vec(),
            info,
        })
        .collect())
}

/// The paper's exact temporal solve (smoothed over `window` frames), at the given `poses`.
fn given(poses: &[JawParams], window: usize) -> SolveOptions {
    SolveOptions {
        jaw: JawPose::Given(poses.to_vec()),
        ..SolveOptions::exact(true, window)
    }
}

/// One frame solved at pose `theta` (no previous frame).
fn solve_one(model: &Model, targets: &[DVec3], theta: JawParams) -> Solved {
    let frames = [targets.to_vec()];
    let mut out = solve_with(model, &frames, &given(&[theta], 0), None).unwrap();
    out.remove(0)
}

/// The old sewing, one stage after another over every vertex: blend, jaw maps, residual
/// pass (the reference of the fused one-pass sewing).
fn staged_sewing(model: &Model, prep: &Prepared, pieces: &Pieces) -> Vec<DVec3> {
    let plan = model
        .sewing
        .plan_for(&model.dataset, &model.bundles, &prep.present)
        .unwrap();
    let weights = plan.weights().to_sparse();
    let lk = &model.lookups[prep.bin];
    let mesh = model.dataset.neutral();
    let mut v = vec![DVec3::ZERO; mesh.num_vertices()];
    crate::sew::blend(
        &lk.data.neutral().positions,
        lk.data.displacements(),
        &weights,
        pieces,
        &mut v,
    );
    if let Some(j) = &model.jaw {
        if let Some(r) = lk.reference {
            let c = v.clone();
            j.input.rig.unskin(&c, r, &mut v).unwrap();
        }
        if let Some(t) = prep.theta {
            let c = v.clone();
            j.input.rig.skin(&c, t, &mut v).unwrap();
        }
    }
    plan.residual().apply(
        &mesh.triangles,
        &model.bundles,
        &weights,
        &prep.targets,
        RESIDUAL_TOLERANCE * model.diagonal,
        &mut v,
    );
    v
}

#[test]
fn fused_sewing_and_the_markers_alone_equal_blend_then_jaw_maps_then_residual_pass_bit_for_bit() {
    let (binned, data, thetas) = binned_model(vec![0.0, 0.25, 0.5], 0.06).unwrap();
    let plain = Model::build(&patch(24), binned.markers_rest(), &BuildConfig::default()).unwrap();
    let mut checked = 0;
    for (model, jaw) in [(&binned, true), (&plain, false)] {
        for k in [2usize, 5, 8] {
            let mesh = shape_mesh(if jaw { &data } else { plain.dataset() }, k % 6);
            let mut targets = model.bundle_positions(&mesh).unwrap();
            // Off the dataset (noise), and one marker missing in the second case.
            for (i, t) in targets.iter_mut().enumerate() {
                *t += DVec3::new(0.003, -0.002, 0.004) * ((i * 7 + k) % 5) as f64;
            }
            for missing in [None, Some(3usize)] {
                let mut t = targets.clone();
                if let Some(m) = missing {
                    t[m] = DVec3::NAN;
                }
                let theta = jaw.then(|| thetas[k]);
                let prep = model.prepare(&t, theta, None).unwrap();
                let choices = model.choose_all(&prep, None);
                let pieces = Pieces::from_choices(&choices);
                // Twice: a plan's second sewing reads its weights by column.
                let staged = staged_sewing(model, &prep, &pieces);
                for sewing in 0..2 {
                    let mut fused = vec![DVec3::ZERO; model.dataset.num_vertices()];
                    let info = model
                        .sew_frame_into(&prep, choices.clone(), &pieces, Some(&mut fused))
                        .unwrap();
                    let bits = |v: &[DVec3]| -> Vec<[u64; 3]> {
                        v.iter().map(|p| p.to_array().map(f64::to_bits)).collect()
                    };
                    assert_eq!(bits(&fused), bits(&staged), "k {k}, sewing {sewing}");
                    // The markers alone (their triangles' corners sewn): the same bits.
                    let markers = model
                        .sew_frame_into(&prep, choices.clone(), &pieces, None)
                        .unwrap();
                    assert_eq!(
                        bits(&markers.bundle_positions),
                        bits(&info.bundle_positions),
                        "k {k}, sewing {sewing}"
                    );
                    assert_eq!(markers.residuals, info.residuals);
                }
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 12);
}

#[test]
fn every_member_shape_of_every_bin_is_reproduced_at_its_own_jaw_pose() {
    let (model, data, thetas) = binned_model(vec![0.0, 0.25, 0.5], 0.06).unwrap();
    assert_eq!(model.lookups()[0].members(), &[0, 1, 2, 3, 4, 5, 6]);
    assert_eq!(model.lookups()[1].members(), &[3, 4, 5, 6, 7, 8, 9]);
    let diag = model.diagonal();
    for (bin, lk) in model.lookups().iter().enumerate() {
        for &k in lk.members() {
            let k = k as usize;
            let mesh = shape_mesh(&data, k);
            let targets = model.bundle_positions(&mesh).unwrap();
            // The frame after one in `bin` stays there (hysteresis: its opening is a member's).
            let kept = FrameState {
                choices: vec![None; model.num_bundles()],
                bin: Some(bin),
            };
            let frames = [targets];
            let frame = solve_with(&model, &frames, &given(&[thetas[k]], 0), Some(&kept))
                .unwrap()
                .remove(0);
            assert_eq!(frame.info.bin, bin);
            for (i, c) in frame.info.choices.iter().enumerate() {
                let c = c.unwrap();
                let w: f64 = (0..4)
                    .filter(|&j| c.shapes[j] == k as u32 + 1)
                    .map(|j| c.weights[j])
                    .sum();
                // The target matches the cloud point up to the f32 storage of shapes.
                assert!(w > 1.0 - 1e-6, "bin {bin} shape {k} bundle {i}: {c:?}");
            }
            // f32 storage of the re-posed displacements (like the dataset's) bounds the
            // round trip T(θ_k) T(θ_b)⁻¹ (T(θ_b) T(θ_k)⁻¹ x) at ~1e-7 of the motion.
            let err = model
                .sewing_space()
                .sewn()
                .map(|v| frame.vertices[v].distance(mesh[v]))
                .fold(0.0, f64::max);
            assert!(err <= 1e-6 * diag, "bin {bin} shape {k}: {err:e}");
            assert!(frame.info.residuals.iter().all(|&r| r <= 1e-9 * diag));
        }
    }
}

#[test]
fn one_bin_holding_every_shape_matches_the_unbinned_model_to_f32_round_off() {
    let (binned, data, thetas) = binned_model(vec![0.0, 0.5], 0.0).unwrap();
    let (_, rig, _, markers) = jaw_patch();
    let plain = jaw_model(&data, &markers, rig, &thetas, None).unwrap();
    // Frames between shapes: blends of two shapes' meshes at an intermediate pose.
    for (a, b, t) in [(0, 5, 0.3), (3, 8, 0.6), (1, 7, 0.5)] {
        let (ma, mb) = (shape_mesh(&data, a), shape_mesh(&data, b));
        let mesh: Vec<DVec3> = ma.iter().zip(&mb).map(|(p, q)| p.lerp(*q, t)).collect();
        let targets = plain.bundle_positions(&mesh).unwrap();
        let theta = JawParams {
            open: (1.0 - t) * thetas[a].open + t * thetas[b].open,
            ..JawParams::ZERO
        };
        let f0 = solve_one(&plain, &targets, theta);
        let f1 = solve_one(&binned, &targets, theta);
        let err = f0
            .vertices
            .iter()
            .zip(&f1.vertices)
            .map(|(p, q)| p.distance(*q))
            .fold(0.0, f64::max);
        assert!(err <= 1e-5 * plain.diagonal(), "{a}-{b}: {err:e}");
    }
}

#[test]
fn bin_selection_follows_a_hand_written_sequence_with_hysteresis() {
    let bins = JawBins {
        edges: vec![0.0, 0.2, 0.4, 0.6],
        overlap: 0.05,
    };
    bins.validate().unwrap();
    // (opening, expected bin) in order; each frame sees the previous frame's bin.
    let script = [
        (0.0, 0), // core of bin 0
        (0.19, 0),
        (0.23, 0), // past edge 0.2 but inside bin 0's overlap (to 0.25): kept
        (0.26, 1), // outside: core bin 1
        (0.17, 1), // inside bin 1's overlap (from 0.15): kept
        (0.14, 0), // outside: core bin 0
        (-0.3, 0), // below the first edge: clamped to bin 0
        (0.9, 2),  // above the last edge: clamped to the last bin
        (0.36, 2), // inside bin 2's overlap (from 0.35): kept
        (0.34, 1), // outside: core bin 1
        (0.4, 1),  // on an edge, inside bin 1's range: kept
        (0.46, 2), // outside bin 1's overlap (to 0.45)
    ];
    let mut previous = None;
    for (f, &(open, want)) in script.iter().enumerate() {
        let got = bins.select(open, previous);
        assert_eq!(got, want, "frame {f}, opening {open}");
        previous = Some(got);
    }
    // Without a previous frame: the core bin (an edge belongs to the bin above it).
    assert_eq!(bins.select(0.2, None), 1);
    assert_eq!(bins.select(0.6, None), 2);
}

/// Seven frames of shapes at jaw openings that enter bin 1 of the 0 / 0.25 / 0.5 bins at
/// frame 3 and stay there by hysteresis at frame 4: the frames and their poses.
fn hysteresis_take(model: &Model, data: &Dataset) -> (Vec<Vec<DVec3>>, Vec<JawParams>) {
    let opens = [0.0, 0.2, 0.29, 0.32, 0.2, 0.18, 0.5];
    let shapes = [0, 3, 5, 7, 4, 1, 9];
    let frames = shapes
        .iter()
        .map(|&k| model.bundle_positions(&shape_mesh(data, k)).unwrap())
        .collect();
    let poses = opens
        .iter()
        .map(|&open| JawParams {
            open,
            ..JawParams::ZERO
        })
        .collect();
    (frames, poses)
}

#[test]
fn a_temporal_solve_picks_bins_by_hysteresis_and_reports_dataset_shape_ids() {
    let (model, data, _) = binned_model(vec![0.0, 0.25, 0.5], 0.06).unwrap();
    let want = [0, 0, 0, 1, 1, 0, 1];
    let (frames, poses) = hysteresis_take(&model, &data);
    for window in [0, 3] {
        let out = solve_with(&model, &frames, &given(&poses, window), None).unwrap();
        let bins: Vec<usize> = out.iter().map(|f| f.info.bin).collect();
        assert_eq!(bins, want, "window {window}");
        for (f, fr) in out.iter().enumerate() {
            let members = model.lookups()[fr.info.bin].members();
            for c in fr.info.choices.iter().flatten() {
                for j in 0..4 {
                    let s = c.shapes[j];
                    assert!(c.weights[j] == 0.0 || s == 0 || members.contains(&(s - 1)));
                }
            }
            assert!(
                fr.info
                    .residuals
                    .iter()
                    .all(|&r| r <= 1e-9 * model.diagonal()),
                "{f}"
            );
        }
    }
    // Frame 1 is shape 3 at its own pose (0.2): it chooses that shape (id 4), purely.
    let out = solve_with(&model, &frames[..2], &given(&poses[..2], 0), None).unwrap();
    for c in out[1].info.choices.iter().flatten() {
        let w: f64 = (0..4)
            .filter(|&j| c.shapes[j] == 4)
            .map(|j| c.weights[j])
            .sum();
        assert!(w > 1.0 - 1e-6, "{c:?}");
    }
    // A solve continuing from a FrameState applies the same rule.
    let state = FrameState {
        choices: out[1].info.choices.clone(),
        bin: Some(out[1].info.bin),
    };
    let fr = solve_with(&model, &frames[2..3], &given(&poses[2..3], 0), Some(&state)).unwrap();
    assert_eq!(fr[0].info.bin, 0);
}

/// The owned copy of a model's borrowed parts (what a reader of the file produces).
#[test]
fn a_take_solved_in_chunks_each_given_the_last_state_equals_the_take_solved_at_once() {
    let (model, data, _) = binned_model(vec![0.0, 0.25, 0.5], 0.06).unwrap();
    // Bin 1 entered at frame 3 and kept by hysteresis at frame 4 (0.2 lies in its widened
    // range): a chunk boundary after frame 3 must carry the bin and the choices.
    let (frames, poses) = hysteresis_take(&model, &data);
    let nv = data.num_vertices();
    let mut whole = vec![DVec3::ZERO; frames.len() * nv];
    let want = model
        .solve(&frames, &given(&poses, 0), None, &mut whole, |_| {})
        .unwrap();
    for split in [1, 4, 6] {
        let mut parts = vec![DVec3::ZERO; frames.len() * nv];
        let (a, b) = parts.split_at_mut(split * nv);
        let first = model
            .solve(
                &frames[..split],
                &given(&poses[..split], 0),
                None,
                a,
                |_| {},
            )
            .unwrap();
        let state = first.last().map(FrameInfo::state);
        let options = given(&poses[split..], 0);
        let second = model
            .solve(&frames[split..], &options, state.as_ref(), b, |_| {})
            .unwrap();
        assert_eq!(parts, whole, "split after {split}");
        for (got, want) in first.iter().chain(&second).zip(&want) {
            assert_eq!(got.bin, want.bin);
            assert_eq!(got.choices, want.choices);
        }
    }
    // Without the state the chunk after frame 3 starts afresh: frame 4 leaves bin 1.
    let mut rest = vec![DVec3::ZERO; 3 * nv];
    let fresh = model
        .solve(
            &frames[4..],
            &given(&poses[4..], 0),
            None,
            &mut rest,
            |_| {},
        )
        .unwrap();
    assert_eq!((fresh[0].bin, want[4].bin), (0, 1));
}

fn owned_parts(model: &Model) -> ModelParts {
    let p = model.parts();
    ModelParts {
        dataset: model.dataset_shared(),
        jaw: p.jaw.cloned(),
        config: p.config.clone(),
        markers_rest: p.markers_rest.to_vec(),
        bins: p
            .bins
            .iter()
            .map(|b| BinParts {
                clouds: b.clouds.to_vec(),
                tets: b.tets.iter().map(|t| t.to_vec()).collect(),
                fit_basis: b.fit_basis.cloned(),
            })
            .collect(),
    }
}

#[test]
fn a_binned_model_rebuilt_from_its_parts_gives_identical_frames_and_bad_parts_are_named() {
    let (model, data, thetas) = binned_model(vec![0.0, 0.25, 0.5], 0.06).unwrap();
    let rebuilt = Model::from_parts(owned_parts(&model)).unwrap();
    let ks = [0, 3, 5, 7, 9];
    let frames: Vec<Vec<DVec3>> = ks
        .iter()
        .map(|&k| model.bundle_positions(&shape_mesh(&data, k)).unwrap())
        .collect();
    let poses: Vec<JawParams> = ks.iter().map(|&k| thetas[k]).collect();
    let a = solve_with(&model, &frames, &given(&poses, 0), None).unwrap();
    let b = solve_with(&rebuilt, &frames, &given(&poses, 0), None).unwrap();
    for (fa, fb) in a.iter().zip(&b) {
        assert_eq!(fa.vertices, fb.vertices);
        assert_eq!(fa.info.choices, fb.info.choices);
        assert_eq!(fa.info.bin, fb.info.bin);
    }
    // One stored bin short of the jaw's bins.
    let mut short = owned_parts(&model);
    short.bins.pop();
    match Model::from_parts(short) {
        Err(PartsError::Inconsistent(m)) => assert!(m.contains("number of jaw bins"), "{m}"),
        other => panic!("expected inconsistent parts, got {other:?}"),
    }
    // A cloud naming a shape its bin does not have.
    let mut foreign = owned_parts(&model);
    foreign.bins[1].clouds[2].aliases[0].push(99);
    match Model::from_parts(foreign) {
        Err(PartsError::Inconsistent(m)) => {
            assert!(m.contains("bin 1, bundle 2: shape id out of range"), "{m}")
        }
        other => panic!("expected inconsistent parts, got {other:?}"),
    }
}

#[test]
fn binned_model_save_load_round_trip_gives_identical_frames() {
    let (model, data, thetas) = binned_model(vec![0.0, 0.25, 0.5], 0.06).unwrap();
    let path = std::env::temp_dir().join(format!("lgi-bins-{}.lgi", std::process::id()));
    crate::io::model_file::save(&model, &path).unwrap();
    let loaded = crate::io::model_file::load(&path);
    std::fs::remove_file(&path).unwrap();
    let loaded = loaded.unwrap();
    assert_eq!(
        loaded.jaw().unwrap().input.bins,
        model.jaw().unwrap().input.bins
    );
    assert_eq!(loaded.lookups().len(), 2);
    let frames: Vec<Vec<DVec3>> = [0, 3, 5, 7, 9]
        .iter()
        .map(|&k| model.bundle_positions(&shape_mesh(&data, k)).unwrap())
        .collect();
    let poses: Vec<JawParams> = [0, 3, 5, 7, 9].iter().map(|&k| thetas[k]).collect();
    let a = solve_with(&model, &frames, &given(&poses, 3), None).unwrap();
    let b = solve_with(&loaded, &frames, &given(&poses, 3), None).unwrap();
    for (fa, fb) in a.iter().zip(&b) {
        assert_eq!(fa.vertices, fb.vertices);
        assert_eq!(fa.info.choices, fb.info.choices);
        assert_eq!(fa.info.bin, fb.info.bin);
    }
}

/// A jaw frame tilted 0.3 rad about (1, 2, -1), built from the axis-angle formula.
fn tilted_frame() -> glam::DMat3 {
    glam::DMat3::from_axis_angle(DVec3::new(1.0, 2.0, -1.0).normalize(), 0.3)
}

#[test]
fn a_tilted_frame_jaw_model_reproduces_its_shapes_and_its_frame_survives_save_load() {
    let frame = tilted_frame();
    let (data, rig, thetas, markers) = jaw_patch_in(frame);
    let bins = JawBins {
        edges: vec![0.0, 0.25, 0.5],
        overlap: 0.06,
    };
    let model = jaw_model(&data, &markers, rig, &thetas, Some(bins)).unwrap();
    assert_eq!(model.jaw().unwrap().input.rig.frame, frame);
    let diag = model.diagonal();
    for k in [0usize, 3, 5, 7, 9] {
        let mesh = shape_mesh(&data, k);
        let targets = model.bundle_positions(&mesh).unwrap();
        let fr = solve_one(&model, &targets, thetas[k]);
        let err = model
            .sewing_space()
            .sewn()
            .map(|v| fr.vertices[v].distance(mesh[v]))
            .fold(0.0, f64::max);
        assert!(err <= 1e-6 * diag, "shape {k}: {err:e}");
        assert!(fr.info.residuals.iter().all(|&r| r <= 1e-9 * diag));
    }
    let path = std::env::temp_dir().join(format!("lgi-frame-{}.lgi", std::process::id()));
    crate::io::model_file::save(&model, &path).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let loaded = crate::io::model_file::load(&path);
    // A frame that is no rotation (its first axis doubled), checksum fixed: a format error.
    let cols: Vec<u8> = frame
        .to_cols_array()
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let at = bytes
        .windows(cols.len())
        .position(|w| w == &cols[..])
        .unwrap();
    let mut bad = bytes.clone();
    for i in 0..3 {
        let x = f64::from_le_bytes(bad[at + 8 * i..at + 8 * i + 8].try_into().unwrap());
        bad[at + 8 * i..at + 8 * i + 8].copy_from_slice(&(2.0 * x).to_le_bytes());
    }
    let sum = crate::io::model_file::checksum(&bad[28..]);
    bad[20..28].copy_from_slice(&sum.to_le_bytes());
    std::fs::write(&path, bad).unwrap();
    let corrupt = crate::io::model_file::load(&path);
    std::fs::remove_file(&path).unwrap();
    let loaded = loaded.unwrap();
    assert_eq!(
        loaded.jaw().unwrap().input.rig,
        model.jaw().unwrap().input.rig
    );
    let frames: Vec<Vec<DVec3>> = [0, 4, 8]
        .iter()
        .map(|&k| model.bundle_positions(&shape_mesh(&data, k)).unwrap())
        .collect();
    let poses: Vec<JawParams> = [0, 4, 8].iter().map(|&k| thetas[k]).collect();
    let a = solve_with(&model, &frames, &given(&poses, 0), None).unwrap();
    let b = solve_with(&loaded, &frames, &given(&poses, 0), None).unwrap();
    for (fa, fb) in a.iter().zip(&b) {
        assert_eq!(fa.vertices, fb.vertices);
    }
    match corrupt {
        Err(LgiError::ModelFormat { message, .. }) => {
            assert!(message.contains("jaw frame"), "{message}")
        }
        other => panic!("expected a format error, got {other:?}"),
    }
}

#[test]
fn a_version_2_file_still_loads_as_an_unbinned_model() {
    let (data, rig, thetas, markers) = jaw_patch();
    let model = jaw_model(&data, &markers, rig, &thetas, None).unwrap();
    let path = std::env::temp_dir().join(format!("lgi-v2-{}.lgi", std::process::id()));
    crate::io::model_file::save(&model, &path).unwrap();
    // Version 2 is version 5 without its derived section (the fit's basis per bin: a u64 tag,
    // 1 for none), its labels section (names, unit, a u64 0 for no polygons) and the bins
    // section before it (a u64 0 when unbinned).
    let bytes = std::fs::read(&path).unwrap();
    assert!(matches!(
        model.parts().bins[..],
        [BinPartsRef {
            fit_basis: Some(None),
            ..
        }]
    ));
    let derived = 8;
    let names: usize = model.marker_names().iter().map(|n| 8 + n.len()).sum();
    let end = bytes.len() - (8 + names + 8 + model.units().len() + 8) - derived;
    let payload = &bytes[28..end - 8];
    assert_eq!(&bytes[end - 8..end], &[0u8; 8]);
    let mut v2 = bytes[..8].to_vec();
    v2.extend_from_slice(&2u32.to_le_bytes());
    v2.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    v2.extend_from_slice(&crate::io::model_file::checksum_v2(payload).to_le_bytes());
    v2.extend_from_slice(payload);
    std::fs::write(&path, v2).unwrap();
    let loaded = crate::io::model_file::load(&path);
    std::fs::remove_file(&path).unwrap();
    let loaded = loaded.unwrap();
    assert!(loaded.jaw().unwrap().input.bins.is_none());
    let t = model
        .bundle_positions(&shape_mesh(model.dataset(), 5))
        .unwrap();
    let a = solve_one(&model, &t, thetas[5]);
    let b = solve_one(&loaded, &t, thetas[5]);
    assert_eq!(a.vertices, b.vertices);
}

#[test]
fn invalid_bin_specs_are_rejected_with_named_errors() {
    let cases: [(Vec<f64>, f64, &str); 6] = [
        (vec![0.1], 0.0, "at least 2 edges"),
        (vec![0.0, f64::NAN], 0.0, "edge 1 must be finite"),
        (vec![0.0, 0.3, 0.2], 0.0, "edge 2 (0.2) <= edge 1 (0.3)"),
        (vec![0.0, 0.5], -0.1, "overlap must be finite and >= 0"),
        (vec![0.0, 0.5], f64::INFINITY, "overlap must be finite"),
        (
            vec![0.0, 0.1, 0.15, 0.5],
            0.0,
            "jaw bin 1 (opening 0.1 to 0.15 rad",
        ),
    ];
    for (edges, overlap, want) in cases {
        let e = binned_model(edges.clone(), overlap).unwrap_err();
        assert!(matches!(e, LgiError::Input(_)), "{edges:?}: {e:?}");
        assert!(e.to_string().contains(want), "{edges:?}: {e}");
    }
}

#[test]
fn local_and_dataset_shape_ids_round_trip_and_non_members_have_no_local_id() {
    let (model, data, _) = binned_model(vec![0.0, 0.25, 0.5], 0.06).unwrap();
    for lk in model.lookups() {
        assert_eq!(lk.global_id(LocalShapeId(0)), ShapeId::NEUTRAL);
        for j in 0..=lk.members().len() as u32 {
            let g = lk.global_id(LocalShapeId(j));
            assert_eq!(lk.local_id(g), Some(LocalShapeId(j)));
        }
        for k in 0..data.num_shapes() as u32 {
            let member = lk.members().contains(&k);
            assert_eq!(lk.local_id(ShapeId(k + 1)).is_some(), member, "shape {k}");
        }
        assert_eq!(lk.local_id(ShapeId(data.num_shapes() as u32 + 1)), None);
    }
}

#[test]
fn a_shared_fit_piece_blends_as_the_fit_copied_into_every_bundle_that_took_it() {
    let data = patch(24);
    let model = Model::build(&data, &patch_markers(3, 30), &BuildConfig::default()).unwrap();
    let fit = vec![0.0, 0.3, 0.0, 0.25, 0.6, 0.0, 0.1];
    let choices: Vec<Option<Choice>> = (0..model.num_bundles())
        .map(|i| match i % 3 {
            0 => None,
            1 => Some(Choice::of_fit(0.0)),
            _ => Some(Choice {
                shapes: [(i % 6) as u32 + 1, 0, 0, 0],
                weights: [1.0, 0.0, 0.0, 0.0],
                tet: NO_TET,
                projected: false,
                distance: 0.0,
                fit: false,
            }),
        })
        .collect();
    let shared = Pieces::from_choices_with_fit(&choices, &fit);
    assert_eq!(shared.fit_shapes, [1, 3, 4, 6]);
    // The reference: every fit bundle holds its own copy of the fit's entries.
    let mut copied = Pieces {
        start: vec![0],
        ..Pieces::default()
    };
    for b in 0..choices.len() {
        let (s, w) = shared.bundle(b);
        copied.shapes.extend_from_slice(s);
        copied.weights.extend_from_slice(w);
        copied.start.push(copied.shapes.len() as u32);
    }
    let blend = |pieces: &Pieces| {
        let mut v = vec![DVec3::ZERO; data.num_vertices()];
        crate::sew::blend(
            &data.neutral().positions,
            data.displacements(),
            model.sew_weights(),
            pieces,
            &mut v,
        );
        v
    };
    let (a, b) = (blend(&shared), blend(&copied));
    let moved = a
        .iter()
        .zip(&data.neutral().positions)
        .any(|(p, q)| p.distance(*q) > 1e-3);
    assert!(
        moved,
        "the pieces must move the patch for the test to mean anything"
    );
    for (p, q) in a.iter().zip(&b) {
        assert!(p.distance(*q) <= 1e-14, "{p} vs {q}");
    }
}

#[test]
fn the_fits_pose_recovers_each_jaw_shapes_own_pose() {
    let (data, rig, thetas, markers) = jaw_patch();
    let model = jaw_model(&data, &markers, rig, &thetas, None).unwrap();
    let ks = [0usize, 3, 5, 7, 8];
    let frames: Vec<Vec<DVec3>> = ks
        .iter()
        .map(|&k| model.bundle_positions(&shape_mesh(&data, k)).unwrap())
        .collect();
    let options = SolveOptions {
        jaw: JawPose::Fit,
        ..SolveOptions::exact(false, 0)
    };
    let out = solve_with(&model, &frames, &options, None).unwrap();
    for (fr, &k) in out.iter().zip(&ks) {
        let got = fr.info.theta.unwrap();
        // Measured: 2.3e-7 rad at most (the refinement stops on steps below 1e-6).
        let err = (got.open - thetas[k].open).abs();
        assert!(err <= 1e-6, "shape {k}: {got:?} vs {:?}", thetas[k]);
        assert!(fr
            .info
            .residuals
            .iter()
            .all(|&r| r <= 1e-9 * model.diagonal()));
    }
}

#[test]
fn the_tracked_pose_of_pure_jaw_frames_is_their_pose() {
    let (data, rig, thetas, markers) = jaw_patch();
    let model = jaw_model(&data, &markers, rig.clone(), &thetas, None).unwrap();
    let x0 = &data.neutral().positions;
    // A steady opening: the centred moving average of a ramp is the ramp.
    let poses: Vec<JawParams> = (0..6)
        .map(|f| JawParams::from_array([0.06 * f as f64, 0.0, 0.0]))
        .collect();
    let frames: Vec<Vec<DVec3>> = poses
        .iter()
        .map(|&t| {
            let mut mesh = x0.clone();
            rig.skin(x0, t, &mut mesh).unwrap();
            model.bundle_positions(&mesh).unwrap()
        })
        .collect();
    let options = SolveOptions {
        jaw: JawPose::Track,
        ..SolveOptions::exact(true, 0)
    };
    let out = solve_with(&model, &frames, &options, None).unwrap();
    for (f, (fr, want)) in out.iter().zip(&poses).enumerate() {
        let got = fr.info.theta.unwrap().to_array();
        let want = want.to_array();
        assert!(
            (0..3).all(|c| (got[c] - want[c]).abs() <= 1e-9),
            "frame {f}: {got:?} vs {want:?}"
        );
    }
}

#[test]
fn a_pose_needs_a_rig_and_given_poses_one_per_frame() {
    let (data, rig, thetas, markers) = jaw_patch();
    let jawed = jaw_model(&data, &markers, rig, &thetas, None).unwrap();
    let plain = Model::build(&data, &markers, &BuildConfig::default()).unwrap();
    let frames: Vec<Vec<DVec3>> = (0..3)
        .map(|k| jawed.bundle_positions(&shape_mesh(&data, k)).unwrap())
        .collect();
    for jaw in [
        JawPose::Fit,
        JawPose::Track,
        JawPose::Given(vec![JawParams::ZERO; 3]),
    ] {
        let options = SolveOptions {
            jaw,
            ..SolveOptions::default()
        };
        let e = solve_with(&plain, &frames, &options, None).err().unwrap();
        assert!(e.to_string().contains("without a jaw rig"), "{e}");
    }
    let e = solve_with(&jawed, &frames, &given(&thetas[..2], 0), None)
        .err()
        .unwrap();
    assert!(e.to_string().contains("2 jaw poses for 3 frames"), "{e}");
    // The rest pose on a jaw model: no pose.
    let rest = solve_with(&jawed, &frames, &SolveOptions::default(), None).unwrap();
    assert!(rest.iter().all(|f| f.info.theta.is_none()));
}

#[test]
fn the_fit_candidate_is_on_when_asked_or_when_a_marker_noise_is_given() {
    assert_eq!(SolveOptions::default(), SolveOptions::exact(true, 0));
    assert!(!SolveOptions::new(true, 0, None, None).fit);
    assert!(SolveOptions::new(true, 0, None, Some(0.05)).fit);
    assert!(!SolveOptions::new(true, 0, Some(false), Some(0.05)).fit);
    assert!(SolveOptions::new(false, 0, Some(true), None).fit);
}

/// The ICT-FaceKit neutral with its shapes and markers_120 (`$LGI_SHARED_DATA`, else the
/// nearest ancestor's `shared/data`), or `None` (the caller skips, saying why).
fn ict_dataset_and_markers() -> Option<(Dataset, Vec<DVec3>)> {
    let from_env = std::env::var_os("LGI_SHARED_DATA")
        .map(|d| std::path::PathBuf::from(d).join("ict-facekit"));
    let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = from_env
        .into_iter()
        .chain(here.ancestors().map(|a| a.join("shared/data/ict-facekit")))
        .find(|d| d.join("generic_neutral_mesh.obj").is_file())?;
    let mut shapes: Vec<_> = std::fs::read_dir(dir.join("shapes"))
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "obj"))
        .collect();
    shapes.sort();
    let data = Dataset::from_obj_files(&dir.join("generic_neutral_mesh.obj"), &shapes).ok()?;
    let text = std::fs::read_to_string(dir.join("markers_120.csv")).ok()?;
    let markers = text
        .lines()
        .skip(1)
        .filter_map(|l| {
            let f: Vec<f64> = l
                .split(',')
                .skip(1)
                .filter_map(|x| x.trim().parse().ok())
                .collect();
            (f.len() == 3).then(|| DVec3::new(f[0], f[1], f[2]))
        })
        .collect();
    Some((data, markers))
}

/// On the ICT face (mouth and eye barriers, 120 markers), plans made from kept rows over a
/// take of fresh 10 % missing sets have the sparsity of the plans derived row by row from the
/// full plan and their weights to 1e-12.
#[test]
fn on_the_ict_face_plans_from_kept_rows_match_plans_derived_from_the_full_plan() {
    let Some((data, markers)) = ict_dataset_and_markers() else {
        eprintln!("skipped: the ICT-FaceKit data (../shared/data/ict-facekit) is not here");
        return;
    };
    let model = Model::build(&data, &markers, &BuildConfig::default()).unwrap();
    let nb = markers.len() as u32;
    let ctx = model
        .sewing
        .geometry()
        .context(&model.dataset, &model.bundles);
    let mut uniform = uniforms(3);
    let mut worst = 0.0f64;
    for _ in 0..40 {
        let missing: Vec<u32> = (0..nb).filter(|_| uniform() < 0.1).collect();
        let present: Vec<u32> = (0..nb).filter(|b| !missing.contains(b)).collect();
        let kept = model
            .sewing
            .plan_for(&model.dataset, &model.bundles, &present)
            .unwrap()
            .weights()
            .to_sparse();
        let derived = ctx
            .plan_without(&present, model.sewing.full(), model.sewing.support())
            .unwrap()
            .weights()
            .to_sparse();
        assert_weights_match(&kept, &derived, 1e-12, &missing);
        for (a, b) in kept.vals.iter().zip(&derived.vals) {
            worst = worst.max((a - b).abs());
        }
    }
    let (ones, sets) = model.sewing.kept_rows();
    eprintln!(
        "ICT: kept vs derived rows differ by at most {worst:e}; rows kept: {ones} without one \
         bundle, {sets} without two, for {} sewn vertices",
        model.sewing.space().sewn().count()
    );
}

#[test]
fn a_built_or_loaded_model_has_derived_what_a_first_solve_would() {
    let (data, rig, thetas, markers) = jaw_patch();
    let model = jaw_model(&data, &markers, rig, &thetas, None).unwrap();
    let loaded =
        crate::io::model_file::from_bytes(&crate::io::model_file::to_bytes(&model)).unwrap();
    for m in [&model, &loaded] {
        assert!(
            m.rest_fit.get().is_some(),
            "the rest fit a pose from the fit starts from"
        );
        for lk in &m.lookups {
            assert!(
                lk.basis.get().is_some(),
                "the fit's shape basis (or that there is none)"
            );
            assert!(
                lk.spans.get().is_some(),
                "the shapes' spans per blend block"
            );
            assert!(
                lk.prior.as_ref().is_some_and(|p| p.is_derived()),
                "the fit's factors"
            );
        }
    }
}

#[test]
fn a_solve_of_the_markers_alone_reports_the_same_bits_and_one_without_a_surface_its_targets() {
    let (data, rig, thetas, markers) = jaw_patch();
    let model = jaw_model(&data, &markers, rig, &thetas, None).unwrap();
    let mut frames: Vec<Vec<DVec3>> = (0..6)
        .map(|k| model.bundle_positions(&shape_mesh(&data, k % 4)).unwrap())
        .collect();
    // Off the dataset (noise) and a marker missing in two frames.
    for (f, frame) in frames.iter_mut().enumerate() {
        for (i, t) in frame.iter_mut().enumerate() {
            *t += DVec3::new(0.002, -0.003, 0.001) * ((i * 5 + f) % 4) as f64;
        }
        if f % 3 == 1 {
            frame[2] = DVec3::NAN;
        }
    }
    let bits = |v: &[DVec3]| -> Vec<[u64; 3]> {
        v.iter().map(|p| p.to_array().map(f64::to_bits)).collect()
    };
    for temporal in [true, false] {
        let options = SolveOptions {
            jaw: JawPose::Fit,
            ..SolveOptions::new(temporal, 0, None, Some(0.004))
        };
        let whole = solve_with(&model, &frames, &options, None).unwrap();
        let alone = |sewn: Sewn| {
            let options = SolveOptions {
                sewn,
                ..options.clone()
            };
            model
                .solve(&frames, &options, None, &mut [], |_| {})
                .unwrap()
        };
        for (w, m) in whole.iter().zip(alone(Sewn::Markers)) {
            assert_eq!(bits(&m.bundle_positions), bits(&w.info.bundle_positions));
            assert_eq!(m.residuals, w.info.residuals);
            assert_eq!(m.choices, w.info.choices);
            assert_eq!(m.fit_weights, w.info.fit_weights);
            assert_eq!(m.theta, w.info.theta);
        }
        for (f, (w, n)) in whole.iter().zip(alone(Sewn::Nothing)).enumerate() {
            assert_eq!(n.fit_weights, w.info.fit_weights);
            assert_eq!(n.theta, w.info.theta);
            assert_eq!(n.corrections, w.info.corrections);
            for (i, (p, q)) in n
                .bundle_positions
                .iter()
                .zip(&w.info.bundle_positions)
                .enumerate()
            {
                let present = !frames[f][i].is_nan();
                assert_eq!(n.choices[i].is_some(), present);
                assert!(n.choices[i].is_none_or(|c| c.fit && c.tet == NO_TET));
                if present {
                    // The sewn surface passes through the targets to the residual pass's
                    // tolerance.
                    assert!(
                        p.distance(*q) <= 1e-9 * model.diagonal,
                        "frame {f}, bundle {i}"
                    );
                    assert!((n.residuals[i] - w.info.residuals[i]).abs() <= 1e-9 * model.diagonal);
                } else {
                    assert!(p.is_nan() && n.residuals[i] == 0.0);
                }
            }
        }
    }
    // A solve of the whole surface still needs a whole buffer.
    let e = model
        .solve(&frames, &SolveOptions::default(), None, &mut [], |_| {})
        .err()
        .unwrap();
    assert!(e.to_string().contains("output buffer"), "{e}");
}
