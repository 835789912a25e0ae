//! The temporal sequence solve as the Python binding runs it (pipelined: frame f + 1's choice
//! beside frame f's sewing; inside a pool job) on 200 clean frames and on the same frames
//! with a fresh random set of missing markers on every frame, into one reused buffer. Reports
//! the fastest pass's wall time per frame (contention only adds time) and the median process
//! CPU time per frame over the passes. With `LGI_OUTSIDE=1` the solve is called from outside
//! the pool, as a Rust caller on its main thread does (each frame's parallel steps are then
//! handed to the pool and waited for): alternate runs measured no difference (ICT-300, 1 and
//! 2 threads).
//! `cargo run --release -p lgi-benches --example sequence_times [fraction]`; `LGI_PASSES=n`;
//! `LGI_STAGE=clean|messy` times only those frames (for profiling one alone); `LGI_NOISE=σ`
//! solves noise-aware (`marker_noise = σ`, data units, with the fit candidate).

use glam::DVec3;
use lgi_benches::{
    build_model, cpu_seconds, dropout_settings, load_workload, make_frames, median, with_dropouts,
    Rng,
};
use std::time::Instant;

const FRAMES: usize = 200;
const PASSES: usize = 6;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (fraction, passes) = dropout_settings(PASSES);
    let stage = std::env::var("LGI_STAGE").unwrap_or_default();
    let outside = std::env::var("LGI_OUTSIDE").is_ok_and(|s| s == "1");
    let noise = std::env::var("LGI_NOISE")
        .ok()
        .and_then(|s| s.parse::<f64>().ok());
    let options = lgi_core::SolveOptions::new(true, 1, None, noise);
    let workload = load_workload()?;
    let model = build_model(&workload)?;
    let clean = make_frames(&model, FRAMES, 1)?;
    let nv = model.dataset().num_vertices();
    let mut out = vec![DVec3::ZERO; FRAMES * nv];
    let mut rng = Rng::new(5);
    let mut messy = || with_dropouts(&clean, fraction, &mut rng);
    let mut solve = |frames: &[Vec<DVec3>]| -> Result<(f64, f64), lgi_core::LgiError> {
        let (t, c) = (Instant::now(), cpu_seconds());
        let mut run = || model.solve(frames, &options, None, &mut out, |_| {});
        match outside {
            true => run()?,
            false => rayon::scope(|_| run())?,
        };
        let n = frames.len() as f64;
        Ok((t.elapsed().as_secs_f64() / n, (cpu_seconds() - c) / n))
    };
    // Warm-up: the result buffer's pages, and the rows kept without each missing bundle.
    solve(&clean)?;
    solve(&messy())?;
    let (mut wall, mut cpu) = ([f64::INFINITY; 2], [Vec::new(), Vec::new()]);
    for _ in 0..passes {
        let sets = messy();
        for (k, frames) in [&clean, &sets].into_iter().enumerate() {
            if !stage.is_empty() && stage != ["clean", "messy"][k] {
                continue;
            }
            let (w, c) = solve(frames)?;
            wall[k] = wall[k].min(w);
            cpu[k].push(c);
        }
    }
    let [cpu_clean, cpu_messy] = cpu.map(median);
    println!(
        "{} temporal solve, {} threads, {passes} passes of {FRAMES} frames, {:.0} % fresh \
         dropouts: wall (fastest pass) clean {:.3} ms, messy {:.3} ms ({:.2}x); CPU (median) \
         clean {:.3} ms, messy {:.3} ms ({:.2}x)",
        if outside {
            "outside the pool:"
        } else {
            "in a pool job:"
        },
        rayon::current_num_threads(),
        fraction * 100.0,
        wall[0] * 1e3,
        wall[1] * 1e3,
        wall[1] / wall[0],
        cpu_clean * 1e3,
        cpu_messy * 1e3,
        cpu_messy / cpu_clean,
    );
    Ok(())
}
