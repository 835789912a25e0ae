//! A frame's targets checked and mapped for the lookup ([`Prepared`]): the station before the
//! jaw pose's refinement (pose.rs) and the choice and sewing (solve.rs), which both read it.

use super::Model;
use crate::error::{LgiError, Result};
use crate::jaw::JawParams;
use crate::magnitude::Extent;
use crate::prior::FrameFit;
use glam::DVec3;

/// A frame's targets after the checks: as given (NaN rows missing) and as looked up (jaw
/// unskinned), with the present bundles and the jaw pose; with a fit, the frame's global fit
/// and whether it is offered as a candidate, and how far noise-aware solving moved each
/// marker (`corrections`, empty when it did not).
pub(super) struct Prepared {
    pub(super) targets: Vec<DVec3>,
    pub(super) lookup: Vec<DVec3>,
    pub(super) present: Vec<u32>,
    pub(super) theta: Option<JawParams>,
    pub(super) bin: usize,
    pub(super) fit: Option<FrameFit>,
    pub(super) offer_fit: bool,
    /// The fit's weights re-expressed over the bin's shape basis for sewing (the same
    /// displacement; [`Lookup::fit_basis`](super::lookup::Lookup::fit_basis)); empty: the
    /// fit's own weights.
    pub(super) blend: Vec<f64>,
    pub(super) corrections: Vec<f64>,
    /// Where the frame's fit in its bin starts (bin-local shape order, no neutral): the
    /// weights of the fit its jaw pose came from; `None`: inside the box.
    pub(super) fit_start: Option<Vec<f64>>,
    /// The targets as given when noise-aware solving moved them (residuals are measured
    /// against what the user gave).
    pub(super) given: Option<Vec<DVec3>>,
}

impl Prepared {
    /// Each bundle's distance from the marker as given to its position `at` (0 for a missing
    /// one): the residuals are measured against what the user gave, not the noise-aware
    /// targets.
    pub(super) fn residuals(&self, at: &[DVec3]) -> Vec<f64> {
        let given = self.given.as_deref().unwrap_or(&self.targets);
        given
            .iter()
            .zip(at)
            .map(|(g, p)| if g.is_nan() { 0.0 } else { g.distance(*p) })
            .collect()
    }

    /// The fit's weights per local shape id, empty without a fit on offer.
    pub(super) fn fit_weights(&self) -> &[f64] {
        match &self.fit {
            Some(_) if self.offer_fit && !self.blend.is_empty() => &self.blend,
            Some(f) if self.offer_fit => &f.weights,
            _ => &[],
        }
    }
}

impl Model {
    /// Checks a frame's targets: one per bundle, and the magnitude policy ([`Extent`]).
    pub(super) fn check_targets(&self, extent: &Extent, targets: &[DVec3]) -> Result<()> {
        let b = self.bundles.len();
        if targets.len() != b {
            return Err(LgiError::Input(format!(
                "frame has {} bundles, the model has {b}",
                targets.len()
            )));
        }
        let naming = crate::magnitude::Naming {
            names: &self.labels.marker_names,
            units: &self.labels.units,
        };
        extent.check_frame(targets, naming)
    }

    /// Checks a frame's targets, picks its jaw bin and, with a jaw, maps them into the bin's
    /// space for the lookup.
    pub(super) fn prepare(
        &self,
        targets: &[DVec3],
        jaw: Option<JawParams>,
        previous_bin: Option<usize>,
    ) -> Result<Prepared> {
        let b = self.bundles.len();
        let extent = Extent::new(&self.markers_rest, self.diagonal);
        self.check_targets(&extent, targets)?;
        if let Some(t) = &jaw {
            extent.check_jaw(t)?;
        }
        // `check_frame` refused infinite coordinates and too few present markers.
        let mut present = Vec::with_capacity(b);
        let mut targets_clean = targets.to_vec();
        for (i, t) in targets.iter().enumerate() {
            if t.is_nan() {
                targets_clean[i] = DVec3::NAN;
            } else {
                present.push(i as u32);
            }
        }
        // With a jaw, bundles are indexed in the unskinned space of the dataset's pieces.
        let theta = match jaw {
            Some(t) => {
                self.jaw_setup()?;
                t.validate()?;
                Some(t)
            }
            None => None,
        };
        let bin = match self.jaw.as_ref().and_then(|j| j.input.bins.as_ref()) {
            Some(bins) => bins.select(theta.unwrap_or(JawParams::ZERO).open, previous_bin),
            None => 0,
        };
        let lookup = self.lookup_targets(&targets_clean, theta, bin)?;
        Ok(Prepared {
            targets: targets_clean,
            lookup,
            present,
            theta,
            bin,
            fit: None,
            offer_fit: false,
            blend: Vec::new(),
            corrections: Vec::new(),
            fit_start: None,
            given: None,
        })
    }
}

/// `e` naming the frame it is about (input errors).
pub(super) fn frame_context(e: LgiError, frame: usize) -> LgiError {
    match e {
        LgiError::Input(m) => LgiError::Input(format!("frame {frame}: {m}")),
        other => other,
    }
}
