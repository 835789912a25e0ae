//! Criterion benches of the core's per-frame stages on one workload (ICT-300 when the data is
//! present): grid query, candidate choice, outside projection, Sibson weights, sewing, the full
//! solve, and the model build; the local fits; the frame's global fit, boxed and unbounded.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use glam::DVec3;
use lgi_benches::{build_model, load_workload, make_frames, solve_frame, Workload};
use lgi_core::{
    blend, blend_by_columns, fit_scale, BlendshapeSolver, Choice, FrameState, LocalFits, Model,
    Pieces, RidgeFit, Scratch, SibsonWeights, TakePrior, BLEND_BLOCK, FIT_L2, FIT_PENALTY,
};
use std::hint::black_box;
use std::time::{Duration, Instant};

/// Frames cycled through by the per-frame benches (generating 500 costs more than it measures).
const BENCH_FRAMES: usize = 100;

struct Fixture {
    workload: Workload,
    model: Model,
    frames: Vec<Vec<DVec3>>,
    choices: Vec<Vec<Option<Choice>>>,
}

fn fixture() -> Fixture {
    let workload = load_workload().unwrap_or_else(|e| panic!("cannot load the workload: {e}"));
    let t = Instant::now();
    let model = build_model(&workload).unwrap_or_else(|e| panic!("build failed: {e}"));
    eprintln!("model build (one run): {:.2} s", t.elapsed().as_secs_f64());
    let frames = make_frames(&model, BENCH_FRAMES, 1).unwrap_or_else(|e| panic!("frames: {e}"));
    let mut state: Option<FrameState> = None;
    let mut choices = Vec::new();
    let mut vertices = vec![DVec3::ZERO; model.dataset().num_vertices()];
    for f in &frames {
        let info = solve_frame(&model, f, state.as_ref(), &mut vertices)
            .unwrap_or_else(|e| panic!("solve failed: {e}"));
        choices.push(info.choices.clone());
        state = Some(FrameState {
            choices: info.choices,
            bin: None,
        });
    }
    Fixture {
        workload,
        model,
        frames,
        choices,
    }
}

fn stages(c: &mut Criterion) {
    let fx = fixture();
    let model = &fx.model;
    let b = model.num_bundles();
    let eps = model.config().containment_eps;
    let mut g = c.benchmark_group("stages");
    g.sample_size(10)
        .measurement_time(Duration::from_secs(3))
        .warm_up_time(Duration::from_millis(500));

    // Per bundle: one iteration is every bundle of one frame, so time/B is per bundle.
    g.throughput(Throughput::Elements(b as u64));
    let mut f = 0;
    let mut out = Vec::new();
    g.bench_function("grid_query_all_bundles", |bench| {
        bench.iter(|| {
            f = (f + 1) % fx.frames.len();
            let mut n = 0;
            for (i, &t) in fx.frames[f].iter().enumerate() {
                out.clear();
                model.indices()[i].query(t, eps, &mut out);
                n += out.len();
            }
            black_box(n)
        })
    });

    let mut scratch = Scratch::default();
    let mut f = 0;
    g.bench_function("choose_all_bundles", |bench| {
        bench.iter(|| {
            f = (f + 1) % fx.frames.len();
            let prev = &fx.choices[(f + fx.frames.len() - 1) % fx.frames.len()];
            let targets = &fx.frames[f];
            let errors = model.frame_errors(0, targets);
            let mut acc = 0.0;
            for (i, p) in prev.iter().enumerate() {
                let ch = model.choose_bundle(0, i, targets, &errors, p.as_ref(), &mut scratch);
                acc += ch.distance;
            }
            black_box(acc)
        })
    });

    // Outside projection: only the (bundle, target) pairs outside every tet.
    let mut outside = Vec::new();
    for fr in &fx.frames {
        for (i, &t) in fr.iter().enumerate() {
            out.clear();
            model.indices()[i].query(t, eps, &mut out);
            if out.is_empty() && model.indices()[i].num_tets() > 0 {
                outside.push((i, t));
            }
        }
    }
    let total = fx.frames.len() * b;
    eprintln!(
        "targets outside every tet: {} of {} ({:.1} %)",
        outside.len(),
        total,
        100.0 * outside.len() as f64 / total as f64
    );
    if !outside.is_empty() {
        g.throughput(Throughput::Elements(outside.len() as u64));
        let mut near = Vec::new();
        let k = model.config().projection_candidates;
        // What the solve does for them: the tets around the nearest cloud point, pruned.
        let mut bounds = Vec::new();
        g.bench_function("project_outside_targets", |bench| {
            bench.iter(|| {
                let mut n = 0;
                for &(i, t) in &outside {
                    near.clear();
                    model.indices()[i].project_around(t, k, &mut bounds, &mut near);
                    n += near.len();
                }
                black_box(n)
            })
        });
        // Reference: the exact k nearest tets (not on the solve path; see performance.md).
        g.bench_function("nearest_exact_outside_targets", |bench| {
            bench.iter(|| {
                let mut n = 0;
                for &(i, t) in &outside {
                    near.clear();
                    model.indices()[i].nearest(t, k, &mut near);
                    n += near.len();
                }
                black_box(n)
            })
        });
    }

    // Per frame.
    g.throughput(Throughput::Elements(1));
    let space = model.sewing_space();
    let nv = fx.workload.dataset.num_vertices();
    let queries: Vec<_> = (0..nv)
        .filter(|&v| space.contains(v))
        .map(|v| space.vertex_uv[v])
        .collect();
    eprintln!("sewn vertices: {} of {nv}", queries.len());
    g.bench_function("sibson_precompute", |bench| {
        bench.iter(|| {
            let sib = SibsonWeights::new(&space.bundle_uv, &space.barriers)
                .unwrap_or_else(|e| panic!("sibson: {e}"));
            black_box(sib.weights(&queries).num_rows())
        })
    });

    let mesh = fx.workload.dataset.neutral();
    let mut verts = vec![DVec3::ZERO; nv];
    let pieces: Vec<Pieces> = fx.choices.iter().map(|c| Pieces::from_choices(c)).collect();
    let mut f = 0;
    g.bench_function("sew_blend_frame", |bench| {
        bench.iter(|| {
            f = (f + 1) % fx.frames.len();
            blend(
                &mesh.positions,
                model.dataset().displacements(),
                model.sew_weights(),
                &pieces[f],
                &mut verts,
            );
            black_box(verts[0])
        })
    });

    // The blend as a plan's second and later sewings read it: by column within blocks.
    let columns = model.sew_weights().block_columns(BLEND_BLOCK);
    let mut f = 0;
    g.bench_function("sew_blend_frame_by_columns", |bench| {
        bench.iter(|| {
            f = (f + 1) % fx.frames.len();
            blend_by_columns(
                &mesh.positions,
                model.dataset().displacements(),
                model.sew_weights(),
                &columns,
                &pieces[f],
                &mut verts,
            );
            black_box(verts[0])
        })
    });

    let mut f = 0;
    let mut vertices = vec![DVec3::ZERO; model.dataset().num_vertices()];
    g.bench_function("solve_frame_with_previous", |bench| {
        bench.iter(|| {
            f = (f + 1) % fx.frames.len();
            let prev = FrameState {
                choices: fx.choices[(f + fx.frames.len() - 1) % fx.frames.len()].clone(),
                bin: None,
            };
            let r = solve_frame(model, &fx.frames[f], Some(&prev), &mut vertices)
                .unwrap_or_else(|e| panic!("solve: {e}"));
            black_box((r.residuals.len(), vertices[0]))
        })
    });
    g.finish();

    // Each build is seconds: criterion's minimum of 10 samples, no warm-up to speak of.
    let mut g = c.benchmark_group("build");
    g.sample_size(10)
        .measurement_time(Duration::from_secs(5))
        .warm_up_time(Duration::from_millis(1));
    g.bench_function("model_build", |bench| {
        bench.iter(|| black_box(build_model(&fx.workload).map(|m| m.num_bundles())))
    });
    g.finish();
}

/// The local fits (`solve(local_fits=True)`): their build (a solver per bundle's window) and
/// one frame's fits, every bundle's, of the workload's shapes at the bundles (no jaw).
/// The shapes' displacements at the bundles (rows `3n + d`, S columns, row-major), the
/// bundles' rest positions, and the frames' markers as displacements from rest.
fn fit_matrix(f: &Fixture) -> (Vec<f64>, Vec<DVec3>, Vec<Vec<f64>>) {
    let data = f.model.dataset();
    let neutral = &data.neutral().positions;
    let rest = f
        .model
        .bundle_positions(neutral)
        .unwrap_or_else(|e| panic!("{e}"));
    let (b, s) = (rest.len(), data.num_shapes());
    let mut a = vec![0.0; 3 * b * s];
    for k in 0..s {
        let moved: Vec<DVec3> = (0..neutral.len())
            .map(|v| neutral[v] + data.displacement(k, v))
            .collect();
        let at = f
            .model
            .bundle_positions(&moved)
            .unwrap_or_else(|e| panic!("{e}"));
        for n in 0..b {
            for (d, x) in (at[n] - rest[n]).to_array().iter().enumerate() {
                a[(3 * n + d) * s + k] = *x;
            }
        }
    }
    let targets: Vec<Vec<f64>> = f
        .frames
        .iter()
        .map(|fr| {
            fr.iter()
                .zip(&rest)
                .flat_map(|(p, r)| (*p - *r).to_array())
                .collect()
        })
        .collect();
    (a, rest, targets)
}

/// The frame's global fit: boxed (the recommended call's) and unbounded (`fit="unbounded"`,
/// the ridge fit) on the workload's matrix (fewer shapes than rows: the normal equations), and
/// the ridge fit on 2,000 columns over the same rows (a K = 2,000 scans model: its dual form),
/// two markers missing in every frame (a take's usual dropouts).
fn global_fit(c: &mut Criterion) {
    let f = fixture();
    let (a, rest, mut targets) = fit_matrix(&f);
    let (rows, s) = (3 * rest.len(), f.model.dataset().num_shapes());
    for (i, t) in targets.iter_mut().enumerate() {
        for n in [i % rest.len(), (7 * i + 3) % rest.len()] {
            t[3 * n..3 * n + 3].fill(f64::NAN);
        }
    }
    let scale = fit_scale(&a, s);
    let boxed = BlendshapeSolver::new(a.clone(), rows, s, FIT_L2 * scale, FIT_PENALTY * scale)
        .unwrap_or_else(|e| panic!("{e}"));
    let ridge = RidgeFit::new(a.clone(), rows, s, FIT_L2 * scale).unwrap_or_else(|e| panic!("{e}"));
    // 2,000 columns: the workload's shapes' columns cycled with a deterministic perturbation
    // (the same rows and scale; independent enough to be full rank).
    const SCANS: usize = 2000;
    let wide: Vec<f64> = (0..rows * SCANS)
        .map(|i| {
            let (r, k) = (i / SCANS, i % SCANS);
            a[r * s + k % s] * (1.0 + 0.3 * (((r * 31 + k * 17) % 97) as f64 / 97.0 - 0.5))
        })
        .collect();
    let wide_ridge = RidgeFit::new(wide.clone(), rows, SCANS, FIT_L2 * fit_scale(&wide, SCANS))
        .unwrap_or_else(|e| panic!("{e}"));
    // A take's prior on the 2,000 columns: 20 kept directions (the scans protocol's takes kept
    // 16-23), deterministic values of the weights' scale.
    const KEPT: usize = 20;
    let factor: Vec<f64> = (0..SCANS * KEPT)
        .map(|i| 0.05 * (((i * 37 + 11) % 101) as f64 / 101.0 - 0.5))
        .collect();
    let take =
        TakePrior::new(vec![0.01; SCANS], factor, KEPT, 4e-4).unwrap_or_else(|e| panic!("{e}"));
    let take_fit = take.fit(&wide, rows).unwrap_or_else(|e| panic!("{e}"));
    let mut g = c.benchmark_group("global_fit");
    g.sample_size(20);
    let mut i = 0;
    g.bench_function("boxed_fit_frame", |bench| {
        bench.iter(|| {
            i = (i + 1) % targets.len();
            black_box(boxed.solve(&targets[i]))
        });
    });
    g.bench_function("ridge_fit_frame", |bench| {
        bench.iter(|| {
            i = (i + 1) % targets.len();
            black_box(ridge.solve(&targets[i]))
        });
    });
    g.bench_function("ridge_fit_frame_2000_scans", |bench| {
        bench.iter(|| {
            i = (i + 1) % targets.len();
            black_box(wide_ridge.solve(&targets[i]))
        });
    });
    g.bench_function("ridge_fit_build_2000_scans", |bench| {
        bench.iter(|| black_box(RidgeFit::new(wide.clone(), rows, SCANS, 1.0)));
    });
    g.bench_function("take_prior_fit_frame_2000_scans", |bench| {
        bench.iter(|| {
            i = (i + 1) % targets.len();
            black_box(take_fit.solve(&targets[i]))
        });
    });
    g.bench_function("take_prior_build_2000_scans", |bench| {
        bench.iter(|| black_box(take.fit(&wide, rows)));
    });
    g.finish();
}

fn local_fits(c: &mut Criterion) {
    let f = fixture();
    let (a, rest, targets) = fit_matrix(&f);
    let (b, s) = (rest.len(), f.model.dataset().num_shapes());
    let fits = LocalFits::new(&a, s, &rest, FIT_L2, FIT_PENALTY).unwrap_or_else(|e| panic!("{e}"));
    // Each frame's fits start at 0.
    let starts = vec![0.0; s];
    let mut g = c.benchmark_group("local_fits");
    g.sample_size(10);
    g.bench_function("local_fits_build", |bench| {
        bench.iter(|| black_box(LocalFits::new(&a, s, &rest, FIT_L2, FIT_PENALTY)));
    });
    g.throughput(Throughput::Elements(b as u64));
    let mut i = 0;
    g.bench_function("local_fits_frame", |bench| {
        bench.iter(|| {
            i = (i + 1) % targets.len();
            black_box(fits.solve(&targets[i], &starts))
        });
    });
    // 16 consecutive frames in one call (`lgi.local`'s chunk): every frame but the first
    // starts at the window's fit of the frame before.
    const CHUNK: usize = 16;
    let chunks: Vec<Vec<f64>> = targets.chunks_exact(CHUNK).map(|c| c.concat()).collect();
    let chunk_starts = vec![0.0; CHUNK * s];
    g.throughput(Throughput::Elements((CHUNK * b) as u64));
    let mut j = 0;
    g.bench_function("local_fits_16_frames", |bench| {
        bench.iter(|| {
            j = (j + 1) % chunks.len();
            black_box(fits.solve(&chunks[j], &chunk_starts))
        });
    });
    g.finish();
}

criterion_group!(benches, stages, local_fits, global_fit);
criterion_main!(benches);
