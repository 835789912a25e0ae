//! Global blendshape fit, the standard production baseline: per frame the shape weights that
//! best explain the markers, min ‖A w − r‖² + l2‖w‖² + penalty·Σ(min(w,0)² + max(w−1,0)²).
//! The objective is a convex, C¹, piecewise quadratic, so an active-set (semi-smooth Newton)
//! iteration solves it exactly in a few steps.
//!
//! Here the solver and its results; it is built in `build` (the dense normal equations, or
//! their low-rank form from `low_rank` where A's rank is low), fits in `fit`, and iterates in
//! `newton`.

use crate::error::{LgiError, Result};

mod build;
mod fit;
mod low_rank;
mod newton;
mod pieces;

pub(crate) use pieces::PieceFactors;

use low_rank::LowRank;

/// Result of one frame's fit.
#[derive(Debug, Clone, PartialEq)]
pub struct BlendshapeSolution {
    /// Shape weights (S).
    pub weights: Vec<f64>,
    /// Newton iterations used (1 when no weight left [0, 1]).
    pub iterations: usize,
    /// Objective value at `weights`.
    pub objective: f64,
    /// The fit's dual point where it was found through its dual (r values, the frame's own
    /// coordinates), else empty: where a fit of a nearby target of the same frame (the same
    /// rows missing) starts ([`FitStart::Nearby`]).
    pub dual: Vec<f64>,
}

/// Solver for a fixed R×S matrix `A` (rows: marker coordinates, columns: shapes' displacements
/// at the markers).
#[derive(Debug, Clone)]
pub struct BlendshapeSolver {
    a: Vec<f64>,
    rows: usize,
    shapes: usize,
    l2: f64,
    penalty: f64,
    // On the dense path only (empty where `low_rank` is used): AᵀA + l2 I over all rows
    // (every complete frame's Hessian before the box terms) and its Cholesky factor (the
    // first step of every complete frame).
    full_gram: Vec<f64>,
    full: Vec<f64>,
    /// The same equations in the span of A's rows, when its rank is low (`low_rank`).
    low_rank: Option<LowRank>,
}

/// Where a fit's iteration starts.
#[derive(Debug, Clone, Copy, Default)]
pub enum FitStart<'a> {
    /// Inside the box (the primal iteration), or at the dual's 0 where the fit has a dual form
    /// (every weight at 0).
    #[default]
    Cold,
    /// At these weights (S, e.g. a nearby target's solution): where the fit has a dual form,
    /// at the dual point nearest them (at a fit's own minimum, its dual point); else the
    /// primal iteration from them.
    Weights(&'a [f64]),
    /// The fit of a nearby target of the same frame, the same rows missing (e.g. the jaw
    /// refinement's previous step): where the fit has a dual form, at that fit's dual point
    /// ([`BlendshapeSolution::dual`]); else the primal iteration from its weights (S).
    Nearby {
        /// Its weights (S).
        weights: &'a [f64],
        /// Its dual point (r values; empty or another length: from 0).
        dual: &'a [f64],
    },
}

/// A fit's target: `rows` values, none infinite (NaN: a missing row).
pub(crate) fn check_target(target: &[f64], rows: usize) -> Result<()> {
    if target.len() != rows {
        return Err(LgiError::Input(format!(
            "expected {rows} target values, got {}",
            target.len()
        )));
    }
    if target.iter().any(|t| t.is_infinite()) {
        return Err(LgiError::Input("target has an infinite value".into()));
    }
    Ok(())
}

#[cfg(test)]
mod tests;
