//! Local fits (beyond the paper): each bundle's piece is the blendshape fit of the markers
//! around it, the markers weighted by the Gaussian of their rest distance with the length the
//! noise-aware targets use ([`crate::RESIDUAL_LENGTH`] median marker spacings). A whole-face
//! scan rarely matches a whole frame, but around one marker some blend of the scans does: the
//! global fit has to trade the mouth against the brows, a local fit does not. The pieces are
//! blended over the mesh by the sewing weights and the surface is put through the markers by
//! the caller (`lgi.local`); docs/concepts.md says why and docs/results.md what it measures.

use crate::baselines::{BlendshapeSolver, FitStart};
use crate::error::{LgiError, Result};
use crate::prior::{correlation, fit_scale};
use glam::DVec3;
use rayon::prelude::*;

/// A window keeps the markers within this many lengths of its bundle (weight ≥ e^-4.5, about
/// 1 %): the rest change a fit by less than the ridge does, and leaving them out keeps each
/// window's system small.
pub const WINDOW_REACH: f64 = 3.0;

/// One bundle's window: the markers it fits and the square roots of their weights.
#[derive(Debug, Clone)]
struct Window {
    markers: Vec<usize>,
    root_weights: Vec<f64>,
    solver: BlendshapeSolver,
}

/// The local fits of a marker layout: a box-penalised blendshape fit per bundle over its
/// window of markers.
#[derive(Debug, Clone)]
pub struct LocalFits {
    bundles: usize,
    shapes: usize,
    windows: Vec<Window>,
}

/// The local fits of a set of frames.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalWeights {
    /// Every frame's weights per bundle (F × B × S, row-major).
    pub weights: Vec<f64>,
    /// How many (frame, bundle) fits kept their start instead: no marker of the window
    /// present, or neither the low-rank nor the dense path finished.
    pub kept_start: usize,
}

impl LocalFits {
    /// `a`: the shapes' displacements at the markers, row-major (3B × S, marker b's x, y, z in
    /// rows 3b..3b+3); `rest`: the markers' rest positions (B); `l2` and `penalty` relative to
    /// each window's mean squared column norm, as the global fit's are to its own.
    pub fn new(a: &[f64], shapes: usize, rest: &[DVec3], l2: f64, penalty: f64) -> Result<Self> {
        let bundles = rest.len();
        if shapes == 0 || bundles == 0 || a.len() != 3 * bundles * shapes {
            return Err(LgiError::Input(format!(
                "local fits: expected a {}×{shapes} matrix of shapes at the markers (S > 0), got {} values",
                3 * bundles,
                a.len()
            )));
        }
        if rest.iter().any(|p| !p.is_finite()) || a.iter().any(|x| !x.is_finite()) {
            return Err(LgiError::Input(
                "local fits: the markers' rest positions and the shapes must be finite".into(),
            ));
        }
        let weights = correlation(rest);
        let whole = fit_scale(a, shapes);
        let floor = (-0.5 * WINDOW_REACH * WINDOW_REACH).exp();
        let windows = (0..bundles)
            .into_par_iter()
            .map(|b| {
                let row = &weights[b * bundles..(b + 1) * bundles];
                let markers: Vec<usize> = (0..bundles).filter(|&m| row[m] >= floor).collect();
                let root_weights: Vec<f64> = markers.iter().map(|&m| row[m].sqrt()).collect();
                let mut rows = Vec::with_capacity(3 * markers.len() * shapes);
                for (&m, &g) in markers.iter().zip(&root_weights) {
                    for d in 0..3 {
                        let r = 3 * m + d;
                        rows.extend(a[r * shapes..(r + 1) * shapes].iter().map(|x| x * g));
                    }
                }
                // A window no shape moves takes the whole layout's scale (its fit is then 0).
                let own = fit_scale(&rows, shapes);
                let scale = if own > f64::MIN_POSITIVE { own } else { whole };
                let solver = BlendshapeSolver::new(
                    rows,
                    3 * markers.len(),
                    shapes,
                    l2 * scale,
                    penalty * scale,
                )?;
                Ok(Window {
                    markers,
                    root_weights,
                    solver,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(LocalFits {
            bundles,
            shapes,
            windows,
        })
    }

    /// Number of bundles B.
    pub fn num_bundles(&self) -> usize {
        self.bundles
    }

    /// Number of shapes S.
    pub fn num_shapes(&self) -> usize {
        self.shapes
    }

    /// How many markers each bundle's window holds (B).
    pub fn window_sizes(&self) -> Vec<usize> {
        self.windows.iter().map(|w| w.markers.len()).collect()
    }

    /// Each frame's local fits: `targets` F × 3B (displacements from rest; NaN: a missing
    /// marker, its rows dropped), `starts` F × S (where each frame's fits start, e.g. its
    /// global fit; a window with no marker present, or whose fit does not converge, keeps its
    /// start, counted in [`LocalWeights::kept_start`]).
    pub fn solve(&self, targets: &[f64], starts: &[f64]) -> Result<LocalWeights> {
        let (b, s) = (self.bundles, self.shapes);
        if targets.len() % (3 * b) != 0 {
            return Err(LgiError::Input(format!(
                "local fits: targets of {} values are not frames of {} markers × 3",
                targets.len(),
                b
            )));
        }
        let frames = targets.len() / (3 * b);
        if starts.len() != frames * s || starts.iter().any(|x| !x.is_finite()) {
            return Err(LgiError::Input(format!(
                "local fits: expected {frames} × {s} finite start weights, got {} values",
                starts.len()
            )));
        }
        if targets.iter().any(|t| t.is_infinite()) {
            return Err(LgiError::Input("local fits: a target is infinite".into()));
        }
        let fits: Vec<(Vec<f64>, bool)> = (0..frames * b)
            .into_par_iter()
            .map(|job| {
                let (f, k) = (job / b, job % b);
                let start = &starts[f * s..(f + 1) * s];
                let frame = &targets[f * 3 * b..(f + 1) * 3 * b];
                self.windows[k].fit(frame, start)
            })
            .collect();
        let kept_start = fits.iter().filter(|(_, kept)| *kept).count();
        let weights = fits.into_iter().flat_map(|(w, _)| w).collect();
        Ok(LocalWeights {
            weights,
            kept_start,
        })
    }
}

impl Window {
    /// One window's fit of one frame, and whether it kept its start.
    fn fit(&self, frame: &[f64], start: &[f64]) -> (Vec<f64>, bool) {
        let mut target = Vec::with_capacity(3 * self.markers.len());
        for (&m, &g) in self.markers.iter().zip(&self.root_weights) {
            target.extend(frame[3 * m..3 * m + 3].iter().map(|t| t * g));
        }
        if target.iter().all(|t| t.is_nan()) {
            return (start.to_vec(), true);
        }
        let fit = |solver: &BlendshapeSolver| {
            solver
                .solve_with_derivatives(&target, &[], FitStart::Weights(start))
                .map(|(sol, _)| sol.weights)
        };
        // The low-rank path can circle without finishing where a window's present rows miss
        // some of its directions (seen on ICT with one marker of nine missing); the dense path
        // then solves the same objective.
        match fit(&self.solver).or_else(|_| self.solver.dense_only().and_then(|d| fit(&d))) {
            Ok(weights) => (weights, false),
            Err(_) => (start.to_vec(), true),
        }
    }
}

#[cfg(test)]
mod tests;
