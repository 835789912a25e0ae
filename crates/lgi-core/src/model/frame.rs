//! What a solve returns besides the vertices it writes into the caller's buffer
//! ([`FrameInfo`]) and the [`FrameState`] a temporal solve carries from frame to frame.

use crate::choose::Choice;
use crate::jaw::JawParams;
use glam::DVec3;

/// What a solve says about a frame besides its vertices (which [`Model::solve`](super::Model::solve)
/// writes into the caller's buffer).
#[derive(Debug, Clone)]
pub struct FrameInfo {
    /// Per bundle: the chosen geometry (`None` for a missing bundle), in dataset shape ids
    /// ([`ShapeId`](super::ShapeId)).
    pub choices: Vec<Option<Choice>>,
    /// Per bundle: distance from target to reconstructed surface point (0 for missing).
    pub residuals: Vec<f64>,
    /// Per bundle: the reconstructed surface position (for missing bundles, the estimate).
    pub bundle_positions: Vec<DVec3>,
    /// The jaw bin whose clouds the frame was looked up in (0 for an unbinned model).
    pub bin: usize,
    /// Per bundle: how far noise-aware solving moved the marker before interpolating it
    /// (data units; empty when the solve was exact).
    pub corrections: Vec<f64>,
    /// The frame's global fit, a weight per dataset shape id (index 0, the neutral, is 0;
    /// empty when no fit was made).
    pub fit_weights: Vec<f64>,
    /// The jaw pose the frame was solved at (`None` without one): the given or tracked pose,
    /// or the fit's refined one ([`JawPose`](super::JawPose)).
    pub theta: Option<JawParams>,
}

impl FrameInfo {
    /// What the next frame needs from this one (to continue a temporal solve,
    /// [`Model::solve`](super::Model::solve)'s `previous`).
    pub fn state(&self) -> FrameState {
        FrameState {
            choices: self.choices.clone(),
            bin: Some(self.bin),
        }
    }
}

/// What the next frame needs from the previous one.
#[derive(Debug, Clone, Default)]
pub struct FrameState {
    /// Previous choices per bundle (dataset shape ids, [`ShapeId`](super::ShapeId), as in
    /// [`FrameInfo::choices`]).
    pub choices: Vec<Option<Choice>>,
    /// The previous frame's jaw bin ([`FrameInfo::bin`]): kept while the opening allows, and the
    /// choices are only preferred within the same bin. `None`: no bin hysteresis.
    pub bin: Option<usize>,
}
