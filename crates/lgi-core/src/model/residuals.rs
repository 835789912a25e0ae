//! What each frame's global fit leaves at the markers: the dataset's own reading of a frame.
//! Marker noise is part of it, so its scale bounds the noise from above whatever the take's
//! frame spacing (a noise estimate from the tracks alone reads motion as noise when frames
//! are far apart).

use super::pose::{FramePoses, JawPose};
use super::prepare::frame_context;
use super::Model;
use crate::error::{LgiError, Result};
use glam::DVec3;
use rayon::prelude::*;

/// The fit residuals of a set of frames ([`Model::fit_residuals`]).
#[derive(Debug, Clone, PartialEq)]
pub struct FitResiduals {
    /// Per frame, per marker: the marker less the fit's position, in the frame's jaw bin
    /// space (jaw unskinned); NaN for a missing marker.
    pub residuals: Vec<Vec<DVec3>>,
    /// Per frame, the rank of the fit's shapes at the bundles (the directions the fit can take
    /// from a residual): the degrees of freedom it spends.
    pub ranks: Vec<usize>,
    /// Per frame, per marker: the marker in the frame's jaw bin space (what the fit fitted);
    /// NaN for a missing marker.
    pub targets: Vec<Vec<DVec3>>,
    /// Per frame, its jaw bin.
    pub bins: Vec<usize>,
}

impl Model {
    /// Each frame's global-fit residual with the jaw pose `pose` (a pose from the fit is
    /// refined, as the solve does). Frames are independent (no bin hysteresis).
    pub fn fit_residuals(&self, frames: &[Vec<DVec3>], pose: &JawPose) -> Result<FitResiduals> {
        let FramePoses { poses, fit_starts } = self.jaw_poses(frames, pose)?;
        let refine = *pose == JawPose::Fit;
        let b = self.bundles.len();
        let per_frame: Vec<(Vec<DVec3>, usize, Vec<DVec3>, usize)> = frames
            .par_iter()
            .enumerate()
            .map(|(f, t)| {
                let theta = poses.as_ref().map(|p| p[f]);
                let mut prep = self
                    .prepare(t, theta, None)
                    .map_err(|e| frame_context(e, f))?;
                if let Some(start) = fit_starts.get(f) {
                    prep.fit_start = Some(self.fit_start_in_bin(prep.bin, start.clone()));
                }
                self.add_fit(&mut prep, false, None, refine, false, None)
                    .map_err(|e| frame_context(e, f))?;
                let lk = &self.lookups[prep.bin];
                let (Some(fit), Some(prior)) = (&prep.fit, &lk.prior) else {
                    return Err(LgiError::Input(
                        "fit residuals need a dataset with shapes".into(),
                    ));
                };
                let rank = prior.low_rank().unwrap_or(lk.members.len()).min(3 * b);
                let residual = prep
                    .lookup
                    .iter()
                    .zip(&fit.positions)
                    .map(|(t, p)| if t.is_nan() { DVec3::NAN } else { *t - *p })
                    .collect();
                Ok((residual, rank, prep.lookup, prep.bin))
            })
            .collect::<Result<_>>()?;
        let mut out = FitResiduals {
            residuals: Vec::with_capacity(frames.len()),
            ranks: Vec::with_capacity(frames.len()),
            targets: Vec::with_capacity(frames.len()),
            bins: Vec::with_capacity(frames.len()),
        };
        for (residual, rank, target, bin) in per_frame {
            out.residuals.push(residual);
            out.ranks.push(rank);
            out.targets.push(target);
            out.bins.push(bin);
        }
        Ok(out)
    }

    /// Jaw bin `bin`'s global fit: its matrix (row-major `3B × S`, row 3n + d coordinate d of
    /// bundle n: each shape's displacement at the bundles in the bin's space) and the bundles'
    /// rest positions there. `None` for a dataset without shapes or a bin out of range.
    pub fn fit_matrix(&self, bin: usize) -> Option<(Vec<f64>, Vec<DVec3>)> {
        let prior = self.lookups.get(bin)?.prior.as_ref()?;
        Some((prior.matrix(), prior.rest().to_vec()))
    }
}
