//! Local fits (beyond the paper): each bundle's piece is the blendshape fit of the markers
//! around it, the markers weighted by the Gaussian of their rest distance with a length of
//! [`LOCAL_LENGTH`] median marker spacings. A whole-face
//! scan rarely matches a whole frame, but around one marker some blend of the scans does: the
//! global fit has to trade the mouth against the brows, a local fit does not. The pieces are
//! blended over the mesh by the sewing weights and the surface is put through the markers by
//! the caller (`lgi.local`); docs/concepts.md says why and docs/results.md what it measures.

use crate::baselines::{BlendshapeSolver, FitStart, PieceFactors};
use crate::error::{LgiError, Result};
use crate::frame_blocks::frame_blocks;
use crate::linalg::dot8;
use crate::prior::{correlation_over, fit_scale};
use crate::ridge::RidgeFit;
use crate::simd::with_avx2;
use glam::DVec3;
use rayon::prelude::*;

/// The windows' Gaussian length in median nearest-marker distances: a little wider than the
/// noise-aware targets' own length of 1, which was too narrow on some layouts, and no worse
/// than it anywhere measured (docs/concepts.md; the study: docs/journal/2026-12-06.md). A
/// constant, not read from the take: a take's left-out markers always prefer wider windows.
pub const LOCAL_LENGTH: f64 = 1.2;

/// A window keeps the markers within this many lengths of its bundle (weight ≥ e^-4.5, about
/// 1 %): the rest change a fit by less than the ridge does, and leaving them out keeps each
/// window's system small.
pub const WINDOW_REACH: f64 = 3.0;

/// One bundle's window: the markers it fits and the square roots of their weights.
#[derive(Debug, Clone)]
struct Window {
    markers: Vec<usize>,
    root_weights: Vec<f64>,
    fit: WindowFit,
}

/// How a window's fit is solved: held to the box by its penalty (an active-set iteration), or,
/// without a penalty (the unbounded fits), the ridge fit alone in closed form: its equations
/// inverted once and a frame's missing rows taken off the inverse ([`RidgeFit`]), several
/// times faster than the iteration that reaches the same minimum.
#[derive(Debug, Clone)]
enum WindowFit {
    Boxed(Box<BlendshapeSolver>),
    Ridge(RidgeFit),
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
    /// Windows [`LOCAL_LENGTH`] spacings wide. `a`: the shapes' displacements at the markers,
    /// row-major (3B × S, marker b's x, y, z in rows 3b..3b+3); `rest`: the markers' rest
    /// positions (B); `l2` and `penalty` relative to each window's mean squared column norm,
    /// as the global fit's are to its own.
    pub fn new(a: &[f64], shapes: usize, rest: &[DVec3], l2: f64, penalty: f64) -> Result<Self> {
        Self::with_length(a, shapes, rest, l2, penalty, LOCAL_LENGTH)
    }

    /// [`LocalFits::new`] with windows `lengths` median marker spacings wide (finite, > 0).
    pub fn with_length(
        a: &[f64],
        shapes: usize,
        rest: &[DVec3],
        l2: f64,
        penalty: f64,
        lengths: f64,
    ) -> Result<Self> {
        if !(lengths.is_finite() && lengths > 0.0) {
            return Err(LgiError::Input(format!(
                "local fits: the windows' length must be a positive number of marker spacings, got {lengths}"
            )));
        }
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
        let weights = correlation_over(rest, lengths);
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
                let n = 3 * markers.len();
                let fit = if penalty == 0.0 && l2 * scale > 0.0 {
                    WindowFit::Ridge(RidgeFit::new(rows, n, shapes, l2 * scale)?)
                } else {
                    let solver =
                        BlendshapeSolver::new(rows, n, shapes, l2 * scale, penalty * scale)?;
                    WindowFit::Boxed(Box::new(solver))
                };
                Ok(Window {
                    markers,
                    root_weights,
                    fit,
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
    /// marker, its rows dropped), `starts` F × S (e.g. each frame's global fit: where the
    /// first frame's fits start, and a window's after one that kept its start; the others
    /// start at the window's fit of the frame before, the same minimum in fewer steps; a
    /// window with no marker present, or whose fit does not converge, keeps its start,
    /// counted in [`LocalWeights::kept_start`]). Pass a take's frames in order.
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
        // Bundles in parallel, each bundle's frames in order: a frame's fit starts at the
        // previous frame's (the same window, a nearby target: a few steps), the first at
        // its own start. The minimum is unique, so the start changes only the steps taken.
        let per_bundle: Vec<Vec<(Vec<f64>, bool)>> = (0..b)
            .into_par_iter()
            .map(|k| {
                let window = &self.windows[k];
                let mut previous: Option<Fitted> = None;
                let mut pieces = PieceFactors::default();
                (0..frames)
                    .map(|f| {
                        let frame = &targets[f * 3 * b..(f + 1) * 3 * b];
                        let start = &starts[f * s..(f + 1) * s];
                        previous = window.fit(frame, start, previous.as_ref(), &mut pieces);
                        match &previous {
                            Some(done) => (done.weights.clone(), false),
                            None => (start.to_vec(), true),
                        }
                    })
                    .collect()
            })
            .collect();
        let mut weights = vec![0.0; frames * b * s];
        let mut kept_start = 0;
        for (k, fits) in per_bundle.into_iter().enumerate() {
            for (f, (w, kept)) in fits.into_iter().enumerate() {
                weights[(f * b + k) * s..(f * b + k + 1) * s].copy_from_slice(&w);
                kept_start += usize::from(kept);
            }
        }
        Ok(LocalWeights {
            weights,
            kept_start,
        })
    }
}

/// Vertices per parallel task of [`blend_local`].
const BLEND_VERTICES: usize = 512;

/// The sewing weights as compressed rows: vertex v's bundles `indices[indptr[v]..indptr[v+1]]`
/// with weights `data[..]` (scipy's CSR layout).
#[derive(Debug, Clone, Copy)]
pub struct SewingRows<'a> {
    /// V + 1 offsets into `indices` and `data`.
    pub indptr: &'a [usize],
    /// Bundle of each entry.
    pub indices: &'a [usize],
    /// Sewing weight of each entry.
    pub data: &'a [f64],
}

/// One frame's blend of the local fits over the mesh: vertex v is
/// `neutral[v] + Σ_j (Σ_b s_vb w_bj) shapes[v][·][j]`, s the sewing weights, `weights` the
/// bundles' weights (B × q, over the q blended shapes), `shapes` V × 3 × q vertex-major (a
/// vertex's three rows of q values contiguous). Vertices in parallel.
pub fn blend_local(
    neutral: &[DVec3],
    shapes: &[f32],
    sewing: SewingRows<'_>,
    weights: &[f64],
    out: &mut [DVec3],
) -> Result<()> {
    if out.len() != neutral.len() {
        return Err(LgiError::Input(format!(
            "local fits' blend: expected {} vertices' output, got {}",
            neutral.len(),
            out.len()
        )));
    }
    blend_local_frames(neutral, shapes, sewing, weights, out)
}

/// [`blend_local`] of F frames at once: `weights` F × B × q, `out` F × V (frame after frame),
/// each frame's vertices the same bits as its own `blend_local`. A block of vertices is
/// blended for every frame in turn, so its shapes are read from memory once for all of them.
pub fn blend_local_frames(
    neutral: &[DVec3],
    shapes: &[f32],
    sewing: SewingRows<'_>,
    weights: &[f64],
    out: &mut [DVec3],
) -> Result<()> {
    let v = neutral.len();
    let q = shapes.len().checked_div(3 * v).unwrap_or(0);
    let frames = out.len().checked_div(v).unwrap_or(0);
    let bundles = weights.len().checked_div(q * frames).unwrap_or(0);
    let bad = |what: String| Err(LgiError::Input(format!("local fits' blend: {what}")));
    if v == 0 || q == 0 || shapes.len() != 3 * v * q || frames == 0 || out.len() != frames * v {
        return bad(format!(
            "expected {v} vertices' shapes (V × 3 × q) and whole frames of output, got {} values and {} outputs",
            shapes.len(),
            out.len()
        ));
    }
    if weights.len() != frames * bundles * q || bundles == 0 {
        return bad(format!(
            "{} weights are not {frames} frames × bundles × {q}",
            weights.len()
        ));
    }
    let nnz = sewing.indices.len();
    if sewing.indptr.len() != v + 1
        || sewing.data.len() != nnz
        || sewing.indptr[v] != nnz
        || sewing.indptr.windows(2).any(|w| w[0] > w[1])
        || sewing.indices.iter().any(|&b| b >= bundles)
    {
        return bad(format!(
            "the sewing rows are not {v} vertices' entries over {bundles} bundles"
        ));
    }
    let per_frame = bundles * q;
    frame_blocks(out, v, BLEND_VERTICES)
        .into_par_iter()
        .enumerate()
        .for_each(|(c, mut parts)| {
            let mut mixed = vec![0.0f64; q];
            blend_block(
                neutral,
                shapes,
                sewing,
                weights,
                per_frame,
                c * BLEND_VERTICES,
                &mut parts,
                &mut mixed,
            );
        });
    Ok(())
}

with_avx2! {
/// One block of [`blend_local_frames`]: vertices `first..` (as many as `parts`' slices hold)
/// of every frame in `parts`, `mixed` a scratch of q values.
#[allow(clippy::too_many_arguments)]
fn blend_block(
    neutral: &[DVec3],
    shapes: &[f32],
    sewing: SewingRows<'_>,
    weights: &[f64],
    per_frame: usize,
    first: usize,
    parts: &mut [&mut [DVec3]],
    mixed: &mut [f64],
) {
    let q = mixed.len();
    let len = parts.first().map_or(0, |p| p.len());
    // Frame by frame over the block: the block's shapes stay in cache across the frames and
    // a frame's weights of the few bundles sewn here in the nearest one.
    for (f, part) in parts.iter_mut().enumerate() {
        let frame = &weights[f * per_frame..(f + 1) * per_frame];
        for k in 0..len {
            let vert = first + k;
            let rows = &shapes[3 * vert * q..3 * (vert + 1) * q];
            mixed.iter_mut().for_each(|m| *m = 0.0);
            for e in sewing.indptr[vert]..sewing.indptr[vert + 1] {
                let (b, s) = (sewing.indices[e], sewing.data[e]);
                for (m, w) in mixed.iter_mut().zip(&frame[b * q..(b + 1) * q]) {
                    *m += s * w;
                }
            }
            // Called directly, not through a closure: a closure is a function of its own,
            // built without AVX2.
            let x = dot8(&rows[..q], mixed);
            let y = dot8(&rows[q..2 * q], mixed);
            let z = dot8(&rows[2 * q..3 * q], mixed);
            part[k] = neutral[vert] + DVec3::new(x, y, z);
        }
    }
}
}

/// A window's fit of one frame: its weights, its dual point where the iteration found it
/// through its dual (else empty), and which of its rows were missing (where the next frame's
/// fit starts).
struct Fitted {
    weights: Vec<f64>,
    dual: Vec<f64>,
    missing: Vec<bool>,
}

impl Window {
    /// One window's fit of one frame, or `None` where it keeps `start` (no marker of the
    /// window present, or neither path finished). It starts at `previous` (the last frame's
    /// fit: a nearby target, a few steps; at its dual point when the same rows are missing),
    /// else at `start`.
    fn fit(
        &self,
        frame: &[f64],
        start: &[f64],
        previous: Option<&Fitted>,
        pieces: &mut PieceFactors,
    ) -> Option<Fitted> {
        let mut target = Vec::with_capacity(3 * self.markers.len());
        for (&m, &g) in self.markers.iter().zip(&self.root_weights) {
            target.extend(frame[3 * m..3 * m + 3].iter().map(|t| t * g));
        }
        let missing: Vec<bool> = target.iter().map(|t| t.is_nan()).collect();
        if missing.iter().all(|&m| m) {
            return None;
        }
        let solver = match &self.fit {
            WindowFit::Ridge(ridge) => {
                let weights = ridge.solve(&target).ok()?;
                return Some(Fitted {
                    weights,
                    dual: Vec::new(),
                    missing,
                });
            }
            WindowFit::Boxed(solver) => solver,
        };
        let from = match previous {
            Some(p) if p.missing == missing => FitStart::Nearby {
                weights: &p.weights,
                dual: &p.dual,
            },
            Some(p) => FitStart::Weights(&p.weights),
            None => FitStart::Weights(start),
        };
        // A warm start that does not finish is solved again from cold inside the solver
        // (`solve_with_derivatives`); the dense path is the last resort (S³/3 flops a step:
        // seconds at 2,000 scans). The window's dense pieces are kept from frame to frame.
        let solution = solver
            .solve_keeping(&target, from, pieces)
            .or_else(|_| {
                let dense = solver.dense_only()?;
                dense.solve_keeping(&target, from, &mut PieceFactors::default())
            })
            .ok()?;
        Some(Fitted {
            weights: solution.weights,
            dual: solution.dual,
            missing,
        })
    }
}

#[cfg(test)]
mod tests;
