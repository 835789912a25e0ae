//! Per-frame solve time with a fresh set of missing markers on every frame, beside clean frames
//! of the same take (the fastest of several passes): where the sewing plans' cost shows.
//! `cargo run --release -p lgi-benches --example dropout_times [fraction]`.

use glam::DVec3;
use lgi_benches::{build_model, load_workload, make_frames, Rng};
use lgi_core::FrameState;
use std::time::Instant;

const FRAMES: usize = 100;
const PASSES: usize = 5;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let fraction: f64 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(0.1);
    let workload = load_workload()?;
    let model = build_model(&workload)?;
    let clean = make_frames(&model, FRAMES, 1)?;
    let mut rng = Rng::new(5);
    let mut passes: Vec<Vec<Vec<DVec3>>> = Vec::new();
    for _ in 0..PASSES {
        // A fresh missing set on every frame of every pass (no plan is ever reused).
        let frames = clean
            .iter()
            .map(|f| {
                let mut f = f.clone();
                for t in &mut f {
                    if rng.uniform() < fraction {
                        *t = DVec3::NAN;
                    }
                }
                f
            })
            .collect();
        passes.push(frames);
    }
    let time = |frames: &[Vec<DVec3>]| -> Result<f64, Box<dyn std::error::Error>> {
        let t = Instant::now();
        let mut state: Option<FrameState> = None;
        for targets in frames {
            let frame = model.solve_frame(targets, state.as_ref(), None)?;
            state = Some(frame.info.state());
        }
        Ok(t.elapsed().as_secs_f64() / frames.len() as f64)
    };
    let (mut clean_best, mut messy_best) = (f64::INFINITY, f64::INFINITY);
    // LGI_STAGE=clean or messy times only that one (for profiling it alone).
    let stage = std::env::var("LGI_STAGE").unwrap_or_default();
    for frames in &passes {
        if stage != "messy" {
            clean_best = clean_best.min(time(&clean)?);
        }
        if stage != "clean" {
            messy_best = messy_best.min(time(frames)?);
        }
    }
    println!(
        "clean {:.3} ms/frame, {:.0} % fresh dropouts {:.3} ms/frame ({:.2}×)",
        clean_best * 1e3,
        fraction * 100.0,
        messy_best * 1e3,
        messy_best / clean_best
    );
    Ok(())
}
