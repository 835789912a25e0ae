//! Per-frame solve time with a fresh set of missing markers on every frame, beside clean frames
//! of the same take: where the sewing plans' cost shows. Each pass solves the 100 clean frames
//! and then the same frames with a new random set missing on each (no set repeats); it reports
//! the fastest pass's wall time (contention only adds time) and the process CPU time per frame
//! (median over passes after the first, whose plans start from an empty memo; at one thread
//! CPU time is the work, whatever else the machine runs), and the first pass apart.
//! `cargo run --release -p lgi-benches --example dropout_times [fraction]`; `LGI_PASSES=n`.

use glam::DVec3;
use lgi_benches::{
    build_model, cpu_seconds, dropout_settings, load_workload, make_frames, median, solve_frame,
    with_dropouts, Rng,
};
use lgi_core::FrameState;
use std::time::Instant;

const FRAMES: usize = 100;
const PASSES: usize = 6;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (fraction, passes) = dropout_settings(PASSES);
    let workload = load_workload()?;
    let model = build_model(&workload)?;
    let clean = make_frames(&model, FRAMES, 1)?;
    let mut rng = Rng::new(5);
    let mut out = vec![DVec3::ZERO; model.dataset().num_vertices()];
    let mut solve = |frames: &[Vec<DVec3>]| -> Result<(f64, f64), Box<dyn std::error::Error>> {
        let (t, c) = (Instant::now(), cpu_seconds());
        let mut state: Option<FrameState> = None;
        for targets in frames {
            let info = solve_frame(&model, targets, state.as_ref(), &mut out)?;
            state = Some(info.state());
        }
        let n = frames.len() as f64;
        Ok((t.elapsed().as_secs_f64() / n, (cpu_seconds() - c) / n))
    };
    // The first frame with a missing marker makes every bundle's kept rows: timed alone.
    let mut one = clean[0].clone();
    one[0] = DVec3::NAN;
    let mut vertices = vec![DVec3::ZERO; model.dataset().num_vertices()];
    let t = Instant::now();
    solve_frame(&model, &one, None, &mut vertices)?;
    let first_missing = t.elapsed().as_secs_f64();
    let t = Instant::now();
    solve_frame(&model, &clean[0], None, &mut vertices)?;
    let first_clean = t.elapsed().as_secs_f64();
    let (mut wall, mut cpu) = ([f64::INFINITY; 2], [Vec::new(), Vec::new()]);
    let mut first = [0.0; 2];
    for pass in 0..passes {
        let messy = with_dropouts(&clean, fraction, &mut rng);
        for (k, frames) in [&clean, &messy].into_iter().enumerate() {
            // LGI_STAGE=clean or messy solves only those frames (for profiling one alone).
            if std::env::var("LGI_STAGE").is_ok_and(|s| s != ["clean", "messy"][k]) {
                continue;
            }
            let (w, c) = solve(frames)?;
            wall[k] = wall[k].min(w);
            if pass == 0 {
                first[k] = w;
            } else {
                cpu[k].push(c);
            }
        }
    }
    let [cpu_clean, cpu_messy] = cpu.map(median);
    println!(
        "{:.0} % fresh dropouts, {passes} passes of {FRAMES} frames: wall (fastest pass) clean \
         {:.3} ms, messy {:.3} ms ({:.2}x); CPU (median after the first pass) clean {:.3} ms, \
         messy {:.3} ms ({:.2}x); first pass wall clean {:.3} ms, messy {:.3} ms; the take's \
         first frame with a missing marker {:.1} ms (the same frame clean {:.1} ms)",
        fraction * 100.0,
        wall[0] * 1e3,
        wall[1] * 1e3,
        wall[1] / wall[0],
        cpu_clean * 1e3,
        cpu_messy * 1e3,
        cpu_messy / cpu_clean,
        first[0] * 1e3,
        first[1] * 1e3,
        first_missing * 1e3,
        first_clean * 1e3,
    );
    Ok(())
}
