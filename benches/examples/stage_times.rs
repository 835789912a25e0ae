//! Per-frame stage times that survive a busy machine: every stage is timed over the same 100
//! frames several times and the fastest pass is reported (contention only adds time). Used to
//! compare two builds side by side: `cargo run --release -p lgi-benches --example stage_times`.

use glam::DVec3;
use lgi_benches::{build_model, load_workload, make_frames, solve_frame};
use lgi_core::{blend, blend_by_columns, FrameState, Pieces, Scratch, BLEND_BLOCK};
use std::hint::black_box;
use std::time::Instant;

const FRAMES: usize = 100;
const PASSES: usize = 15;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let workload = load_workload()?;
    let model = build_model(&workload)?;
    let frames = make_frames(&model, FRAMES, 1)?;
    let mut scratch = Scratch::default();
    let (mut choose_best, mut solve_best, mut blend_best) =
        (f64::INFINITY, f64::INFINITY, f64::INFINITY);
    let (mut columns_best, mut transpose_best) = (f64::INFINITY, f64::INFINITY);

    let mut pieces: Vec<Pieces> = Vec::new();
    let mesh = model.dataset().neutral();
    let mut verts = vec![DVec3::ZERO; mesh.num_vertices()];
    let mut by_columns = verts.clone();
    // LGI_STAGE=solve times only the solve (for profiling it alone).
    let only_solve = std::env::var("LGI_STAGE").is_ok_and(|s| s == "solve");
    for _ in 0..PASSES {
        // Serial choice of every bundle (no temporal preference).
        let t = Instant::now();
        for targets in frames.iter().filter(|_| !only_solve) {
            let errors = model.frame_errors(0, targets);
            for i in 0..targets.len() {
                black_box(model.choose_bundle(0, i, targets, &errors, None, &mut scratch));
            }
        }
        choose_best = choose_best.min(t.elapsed().as_secs_f64() / FRAMES as f64);
        // Full temporal solve (rayon's threads).
        let t = Instant::now();
        let mut state: Option<FrameState> = None;
        for targets in &frames {
            let info = solve_frame(&model, targets, state.as_ref(), &mut verts)?;
            if pieces.len() < FRAMES {
                pieces.push(Pieces::from_choices(&info.choices));
            }
            let info = black_box(info);
            state = Some(FrameState {
                choices: info.choices,
                bin: Some(info.bin),
            });
        }
        solve_best = solve_best.min(t.elapsed().as_secs_f64() / FRAMES as f64);
        // Sewing's blend alone (rayon's threads), on the solve's choices.
        let t = Instant::now();
        for p in &pieces {
            blend(
                &mesh.positions,
                model.dataset().displacements(),
                model.sew_weights(),
                p,
                &mut verts,
            );
            black_box(verts[0]);
        }
        blend_best = blend_best.min(t.elapsed().as_secs_f64() / FRAMES as f64);
        // The same blend read by column within blocks (a plan's second sewing on), and the
        // transposition that makes those columns.
        let t = Instant::now();
        let columns = model.sew_weights().block_columns(BLEND_BLOCK);
        transpose_best = transpose_best.min(t.elapsed().as_secs_f64());
        let t = Instant::now();
        for p in &pieces {
            blend_by_columns(
                &mesh.positions,
                model.dataset().displacements(),
                model.sew_weights(),
                &columns,
                p,
                &mut by_columns,
            );
            black_box(by_columns[0]);
        }
        columns_best = columns_best.min(t.elapsed().as_secs_f64() / FRAMES as f64);
    }
    println!("{}", workload.name);
    println!(
        "choose, all bundles, serial: {:.3} ms/frame (fastest of {PASSES} passes)",
        choose_best * 1e3
    );
    println!(
        "solve_frame with previous:   {:.3} ms/frame (fastest of {PASSES} passes)",
        solve_best * 1e3
    );
    println!(
        "blend (sewing, no residual pass): {:.3} ms/frame (fastest of {PASSES} passes)",
        blend_best * 1e3
    );
    println!(
        "blend by columns: {:.3} ms/frame (fastest of {PASSES} passes); transposing the \
         weights once: {:.3} ms",
        columns_best * 1e3,
        transpose_best * 1e3
    );
    Ok(())
}
