//! The dataset's global prior for one frame: a box-penalised blendshape fit of all the present
//! markers at once. It is offered to every bundle as one more candidate beside its tets (a real
//! frame has 10–30 shapes active at once, more than a 4-shape tet can hold between markers),
//! and it is what noise-aware solving measures markers against: noise is independent from
//! marker to marker, while what the dataset cannot explain is shared by neighbouring markers.

use crate::baselines::{BlendshapeSolver, FitStart};
use crate::error::{LgiError, Result};
use crate::linalg::{cholesky, cholesky_solve, Lu};
use crate::ridge::RidgeFit;
use crate::take_prior::{TakeFit, TakePrior};
use glam::DVec3;
use std::sync::OnceLock;

/// Ridge weight of the fit, relative to the mean squared column norm of its matrix.
pub const FIT_L2: f64 = 1e-4;
/// Penalty on weights outside [0, 1], relative like [`FIT_L2`].
pub const FIT_PENALTY: f64 = 10.0;
/// Correlation length of what the dataset misses, in median nearest-marker distances: the
/// residual field is smooth over about one marker spacing.
pub const RESIDUAL_LENGTH: f64 = 1.0;
/// Standard errors by which the residuals around a marker must exceed the noise before they
/// count as field there (the usual ~95 % level, the detail weight's too): under noise alone a
/// neighbourhood's mean square scatters about σ², and that scatter is not something to keep.
pub const FIELD_SIGNIFICANCE: f64 = 2.0;
/// Windows over which a marker's field variance may be read, each twice as wide as the one
/// before it from [`RESIDUAL_LENGTH`] (1, 2, 4 and 8 lengths), then the whole face: the widest
/// whose mean square agrees with every narrower one's is used ([`field_deviations`]).
pub const FIELD_WINDOWS: usize = 4;

/// The fit of one frame (one jaw bin's space).
#[derive(Debug, Clone, PartialEq)]
pub struct FrameFit {
    /// Weight of every shape id (index 0, the neutral, is 0).
    pub weights: Vec<f64>,
    /// Every bundle's position under the fitted weights (B).
    pub positions: Vec<DVec3>,
    /// The fit's dual point where its solver found it that way (empty otherwise): where the
    /// fit of a nearby target of the same frame starts ([`FitPrior::fit_from`]).
    pub dual: Vec<f64>,
}

/// What a fit and its residual smoothing need of one set of bundle clouds.
#[derive(Debug, Clone)]
pub struct FitPrior {
    solver: BlendshapeSolver,
    rest: Vec<DVec3>,
    /// Shape displacements at the bundles, `S × B` (`[k * B + n]`, shape id k + 1).
    displacements: Vec<DVec3>,
    /// Weights of the residual field's windows between bundles (B × B, [`FIELD_WINDOWS`] each):
    /// its unit-amplitude correlation, then the Gaussians of 2, 4 and 8 times its length
    /// (each the previous one's fourth root), made once here rather than in every frame.
    windows: Vec<[f64; FIELD_WINDOWS]>,
    /// The displacements' Gram matrix over every bundle (S × S), made on the first
    /// [`active_residuals`](Self::active_residuals) of a frame with every marker present.
    gram: OnceLock<Vec<f64>>,
    /// The fit without the box (ridge alone), made on first use
    /// ([`fit_unbounded`](Self::fit_unbounded)).
    unbounded: OnceLock<std::result::Result<RidgeFit, String>>,
}

impl FitPrior {
    /// From the bundles' positions on every shape, `(S + 1) × B` (shape id 0 the neutral,
    /// index `[k * B + n]`). `None` for a dataset without shapes.
    pub fn new(shape_positions: &[DVec3], num_bundles: usize) -> Result<Option<FitPrior>> {
        let b = num_bundles;
        if b == 0 || shape_positions.len() % b != 0 {
            return Err(LgiError::Input(format!(
                "{} shape positions are not a multiple of {b} bundles",
                shape_positions.len()
            )));
        }
        let s = shape_positions.len() / b - 1;
        if s == 0 {
            return Ok(None);
        }
        let rest = shape_positions[..b].to_vec();
        let displacements: Vec<DVec3> = shape_positions[b..]
            .chunks(b)
            .flat_map(|row| row.iter().zip(&rest).map(|(p, r)| *p - *r))
            .collect();
        let a = fit_matrix(&displacements, b);
        let scale = fit_scale(&a, s);
        let solver = BlendshapeSolver::new(a, 3 * b, s, FIT_L2 * scale, FIT_PENALTY * scale)?;
        let windows = correlation(&rest)
            .into_iter()
            .map(|c| {
                let mut w = [c; FIELD_WINDOWS];
                for n in 1..FIELD_WINDOWS {
                    w[n] = w[n - 1].sqrt().sqrt();
                }
                w
            })
            .collect();
        Ok(Some(FitPrior {
            solver,
            rest,
            displacements,
            windows,
            gram: OnceLock::new(),
            unbounded: OnceLock::new(),
        }))
    }

    /// The rank of the fit's low-rank form when its solver uses it
    /// ([`BlendshapeSolver::low_rank`]).
    pub fn low_rank(&self) -> Option<usize> {
        self.solver.low_rank()
    }

    /// The fit's matrix (row-major `3B × S`, row 3n + d coordinate d of bundle n).
    pub fn matrix(&self) -> Vec<f64> {
        fit_matrix(&self.displacements, self.rest.len())
    }

    /// The bundles' rest positions the fit's targets are offsets from.
    pub fn rest(&self) -> &[DVec3] {
        &self.rest
    }

    /// Number of bundles B.
    pub fn num_bundles(&self) -> usize {
        self.rest.len()
    }

    /// The fit of `targets` (B, NaN rows missing).
    pub fn fit(&self, targets: &[DVec3]) -> Result<FrameFit> {
        self.fit_from(targets, None)
    }

    /// [`fit`](Self::fit) started at `start` (the fit of a nearby target of the same frame,
    /// e.g. the previous step of the jaw refinement's): at its dual point where it has one,
    /// else at its weights; the same minimum in fewer steps.
    pub fn fit_from(&self, targets: &[DVec3], start: Option<&FrameFit>) -> Result<FrameFit> {
        let mut fit = self.weights_from(targets, start)?;
        self.place(&mut fit);
        Ok(fit)
    }

    /// [`fit_from`](Self::fit_from) without the bundles' positions (empty; [`place`](Self::place)
    /// adds them): for fits that only lead to another.
    pub fn weights_from(&self, targets: &[DVec3], start: Option<&FrameFit>) -> Result<FrameFit> {
        let rhs = self.offsets(targets);
        let from = match start.and_then(|f| f.weights.get(1..).map(|w| (w, &f.dual))) {
            Some((weights, dual)) if !dual.is_empty() => FitStart::Nearby { weights, dual },
            Some((w, _)) => FitStart::Weights(w),
            None => FitStart::Cold,
        };
        let (solution, _) = self.solver.solve_with_derivatives(&rhs, &[], from)?;
        let mut weights = Vec::with_capacity(solution.weights.len() + 1);
        weights.push(0.0);
        weights.extend_from_slice(&solution.weights);
        Ok(FrameFit {
            weights,
            positions: Vec::new(),
            dual: solution.dual,
        })
    }

    /// The least-squares fit of `targets` with the ridge alone (no box): the fit a dataset of
    /// scans is solved with, whose weights are no activations.
    pub fn fit_unbounded(&self, targets: &[DVec3]) -> Result<FrameFit> {
        let solver = self
            .unbounded_solver()
            .as_ref()
            .map_err(|e| LgiError::Input(e.clone()))?;
        Ok(self.placed(&solver.solve(&self.offsets(targets))?))
    }

    /// The unbounded fit's solver (made on first use, or by [`FitPrior::derive`]).
    fn unbounded_solver(&self) -> &std::result::Result<RidgeFit, String> {
        self.unbounded.get_or_init(|| {
            let b = self.rest.len();
            let s = self.displacements.len() / b.max(1);
            let a = fit_matrix(&self.displacements, b);
            let scale = fit_scale(&a, s);
            RidgeFit::new(a, 3 * b, s, FIT_L2 * scale).map_err(|e| e.to_string())
        })
    }

    /// Whether [`FitPrior::derive`] has made what it makes (the tests' check).
    #[cfg(test)]
    pub(crate) fn is_derived(&self) -> bool {
        self.gram.get().is_some() && self.unbounded.get().is_some()
    }

    /// What the fit's first uses would make (the boxed solver's whitened form, the unbounded
    /// solver, the displacements' Gram matrix of complete frames' residuals), made now: a
    /// model's build or load does it, not a take's first solve. A failure is left to the
    /// solve that meets it, whose error names the frame.
    pub fn derive(&self) {
        rayon::join(
            || {
                let _ = self.solver.derive();
                let _ = self.unbounded_solver();
            },
            || {
                self.gram.get_or_init(|| self.whole_gram());
            },
        );
    }

    /// A take's prior ([`TakePrior`]) made ready for this fit's matrix.
    pub fn take_fit(&self, prior: &TakePrior) -> Result<TakeFit> {
        prior.fit(&self.matrix(), 3 * self.rest.len())
    }

    /// The fit of `targets` under a take's prior ([`take_fit`](Self::take_fit)): unbounded,
    /// the prior in place of the fit's ridge.
    pub fn fit_with_take(&self, take: &TakeFit, targets: &[DVec3]) -> Result<FrameFit> {
        Ok(self.placed(&take.solve(&self.offsets(targets))?))
    }

    /// The frame fit of shape weights `solution` (S; no dual point): the neutral's weight 0
    /// first, the bundles placed.
    fn placed(&self, solution: &[f64]) -> FrameFit {
        let mut weights = Vec::with_capacity(solution.len() + 1);
        weights.push(0.0);
        weights.extend_from_slice(solution);
        let mut fit = FrameFit {
            weights,
            positions: Vec::new(),
            dual: Vec::new(),
        };
        self.place(&mut fit);
        fit
    }

    /// `targets − rest` as the fit's right-hand side (row 3n + d: coordinate d of bundle n;
    /// NaN rows stay NaN, the fits' missing rows).
    fn offsets(&self, targets: &[DVec3]) -> Vec<f64> {
        let mut rhs = Vec::with_capacity(3 * self.rest.len());
        for (t, r) in targets.iter().zip(&self.rest) {
            rhs.extend_from_slice(&(*t - *r).to_array());
        }
        rhs
    }

    /// Every bundle's position under `fit`'s weights, into `fit.positions`.
    pub fn place(&self, fit: &mut FrameFit) {
        let b = self.rest.len();
        let mut positions = self.rest.clone();
        for (k, &x) in fit.weights.iter().skip(1).enumerate() {
            if x != 0.0 {
                for (p, d) in positions
                    .iter_mut()
                    .zip(&self.displacements[k * b..(k + 1) * b])
                {
                    *p += *d * x;
                }
            }
        }
        fit.positions = positions;
    }

    /// What of `targets` (B, NaN rows missing) the shapes `active` (0-based shape indices)
    /// cannot explain without the fit's ridge and box: the residual of the least-squares
    /// projection of `targets − rest` onto those shapes' displacements over the present rows,
    /// and the same projection's residual of each of `directions` (B points each). Zero for
    /// a dataset shape's own markers when it is active; rows missing from `targets` are zero.
    ///
    /// `cache` keeps the Gram entries summed over a frame's present markers between calls
    /// for the same frame (the same markers missing): each entry is summed once, as it would
    /// be on every call (the same bits).
    pub fn active_residuals(
        &self,
        targets: &[DVec3],
        directions: &[Vec<DVec3>],
        active: &[usize],
        cache: &mut GramCache,
    ) -> Result<(Vec<DVec3>, Vec<Vec<DVec3>>)> {
        let b = self.rest.len();
        let present: Vec<usize> = (0..b).filter(|&i| !targets[i].is_nan()).collect();
        let k = active.len();
        let col = |j: usize, n: usize| self.displacements[active[j] * b + n];
        let mut g = vec![0.0; k * k];
        if present.len() == b {
            // Every marker present: the active shapes' entries of the whole Gram matrix, the
            // same sums (a gather instead of O(B k²) products per call).
            let s = self.displacements.len() / b.max(1);
            let full = self.gram.get_or_init(|| self.whole_gram());
            for i in 0..k {
                for j in 0..k {
                    g[i * k + j] = full[active[i] * s + active[j]];
                }
            }
        } else {
            let s = self.displacements.len() / b.max(1);
            let mut kept = cache.entries(s);
            for i in 0..k {
                for j in 0..=i {
                    let slot = active[i] * s + active[j];
                    let x = match kept.as_deref().map(|e| e[slot]) {
                        Some(x) if !x.is_nan() => x,
                        _ => {
                            let x: f64 = present.iter().map(|&n| col(i, n).dot(col(j, n))).sum();
                            if let Some(e) = kept.as_deref_mut() {
                                e[slot] = x;
                            }
                            x
                        }
                    };
                    g[i * k + j] = x;
                    g[j * k + i] = x;
                }
            }
        }
        // A whisker of ridge keeps collinear shapes (an augmented dataset's) solvable; it is
        // far below the fit's own.
        let trace: f64 = (0..k).map(|i| g[i * k + i]).sum();
        for i in 0..k {
            g[i * k + i] += 1e-12 * trace / k.max(1) as f64 + f64::MIN_POSITIVE;
        }
        let factor = if k > 0 { Some(cholesky(k, g)?) } else { None };
        let project = |v: &[DVec3]| -> Vec<DVec3> {
            let mut out = vec![DVec3::ZERO; b];
            for &n in &present {
                out[n] = v[n];
            }
            if let Some(l) = &factor {
                let c: Vec<f64> = (0..k)
                    .map(|j| present.iter().map(|&n| col(j, n).dot(v[n])).sum())
                    .collect();
                let x = cholesky_solve(k, l, &c);
                for &n in &present {
                    let fitted: DVec3 = (0..k).map(|j| col(j, n) * x[j]).sum();
                    out[n] -= fitted;
                }
            }
            out
        };
        let offset: Vec<DVec3> = targets
            .iter()
            .zip(&self.rest)
            .map(|(t, r)| if t.is_nan() { DVec3::ZERO } else { *t - *r })
            .collect();
        let r = project(&offset);
        let dirs = directions.iter().map(|d| project(d)).collect();
        Ok((r, dirs))
    }

    /// The displacements' Gram matrix over every bundle (S × S), each entry summed over the
    /// bundles in order as [`active_residuals`](Self::active_residuals) sums it.
    fn whole_gram(&self) -> Vec<f64> {
        let b = self.rest.len();
        let s = self.displacements.len() / b.max(1);
        let d = &self.displacements;
        let mut g = vec![0.0; s * s];
        for i in 0..s {
            for j in 0..=i {
                let x: f64 = (0..b).map(|n| d[i * b + n].dot(d[j * b + n])).sum();
                g[i * s + j] = x;
                g[j * s + i] = x;
            }
        }
        g
    }

    /// Noise-aware targets: the fit's positions plus its residuals smoothed across
    /// neighbouring markers, the posterior mean of a residual field with the correlation of
    /// [`RESIDUAL_LENGTH`] under independent marker noise of `sigma` (data units, per
    /// coordinate). The field's variance is local: at each marker, what the residuals around it
    /// (weighted by that same correlation) hold beyond the noise, by more than
    /// [`FIELD_SIGNIFICANCE`] standard errors ([`field_deviations`]). So where the dataset
    /// explains the face the markers move to the fit by about their noise, and a residual that
    /// neighbours share (a shape the dataset lacks, around the brow) is kept there without
    /// letting the noise elsewhere through. Missing rows stay missing.
    pub fn denoise(&self, targets: &[DVec3], fit: &FrameFit, sigma: f64) -> Result<Vec<DVec3>> {
        let b = self.rest.len();
        let present: Vec<usize> = (0..b).filter(|&i| !targets[i].is_nan()).collect();
        let n = present.len();
        if sigma <= 0.0 || n == 0 {
            return Ok(targets.to_vec());
        }
        let residual: Vec<[f64; 3]> = present
            .iter()
            .map(|&i| (targets[i] - fit.positions[i]).to_array())
            .collect();
        let noise = sigma * sigma;
        let deviation = field_deviations(&self.windows, b, &present, &residual, noise);
        let covariance = |r: usize, c: usize| {
            deviation[r] * deviation[c] * self.windows[present[r] * b + present[c]][0]
        };
        let mut system = vec![0.0; n * n];
        for r in 0..n {
            for c in 0..n {
                system[r * n + c] = covariance(r, c);
            }
            system[r * n + r] += noise;
        }
        let solved = Lu::factor(n, system)?.solve3(&residual);
        let mut out = targets.to_vec();
        for (r, &i) in present.iter().enumerate() {
            let mut s = [0.0; 3];
            for (c, x) in solved.iter().enumerate() {
                let k = covariance(r, c);
                for d in 0..3 {
                    s[d] += k * x[d];
                }
            }
            out[i] = fit.positions[i] + DVec3::from_array(s);
        }
        Ok(out)
    }
}

/// The residual field's standard deviation at each present marker (`present`, rows of the B × B
/// window weights `windows`; `residual` their fit residuals), read from the mean square of its
/// neighbours' residuals (not its own: a spike on one marker is not a field its neighbours
/// share) less the noise `noise` (σ²) and [`FIELD_SIGNIFICANCE`] standard errors of that mean under noise alone
/// (σ² √(2/k) for k effective squared coordinates, `3 (Σw)² / Σw²`). Where nothing clears it
/// the field has (almost) no variance there and the markers sit at the fit; the floor keeps
/// the system regular.
///
/// The neighbourhood is chosen per marker, as Lepski's adaptive window: starting from the
/// field's own correlation, the window doubles ([`FIELD_WINDOWS`] times, then the whole face)
/// while its mean square stays within [`FIELD_SIGNIFICANCE`] standard errors of every
/// narrower window's. A residual one region holds (a missing shape) stops the widening at its
/// edge, so the quiet face beside it keeps a narrow window and goes to the fit; a small residual
/// spread over the face (shapes that do not combine linearly) is read over the wide window,
/// whose small standard error no longer hides it.
fn field_deviations(
    windows: &[[f64; FIELD_WINDOWS]],
    b: usize,
    present: &[usize],
    residual: &[[f64; 3]],
    noise: f64,
) -> Vec<f64> {
    let square: Vec<f64> = residual
        .iter()
        .map(|r| (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]) / 3.0)
        .collect();
    const READS: usize = FIELD_WINDOWS + 1;
    present
        .iter()
        .map(|&i| {
            // Per window: Σ w q, Σ w, Σ w²; the last (the whole face) weighs all alike.
            let mut sums = [[0.0f64; 3]; READS];
            for (&j, q) in present.iter().zip(&square) {
                if j == i {
                    continue;
                }
                let pair = &windows[i * b + j];
                for (n, sum) in sums.iter_mut().enumerate() {
                    let w = pair.get(n).copied().unwrap_or(1.0);
                    sum[0] += w * q;
                    sum[1] += w;
                    sum[2] += w * w;
                }
            }
            let mut reads = Vec::with_capacity(READS);
            for [sum, weight, weight_sq] in sums {
                if weight_sq < f64::MIN_POSITIVE {
                    // No present neighbour within reach of this window.
                    continue;
                }
                let error = noise * (2.0 / (3.0 * weight * weight / weight_sq)).sqrt();
                reads.push((sum / weight, error));
            }
            let mut chosen: Option<(f64, f64)> = None;
            for (n, &(mean, error)) in reads.iter().enumerate() {
                let agrees = reads[..n]
                    .iter()
                    .all(|&(narrow, e)| (mean - narrow).abs() <= FIELD_SIGNIFICANCE * e);
                if !agrees {
                    break;
                }
                chosen = Some((mean, error));
            }
            // No window with a present neighbour: nothing shares this residual.
            let variance = chosen.map_or(0.0, |(mean, error)| {
                mean - noise - FIELD_SIGNIFICANCE * error
            });
            variance.max(1e-6 * noise).sqrt()
        })
        .collect()
}

/// Gram entries of one frame's present markers kept between
/// [`FitPrior::active_residuals`] calls for that frame (the jaw refinement's steps), made on
/// first use; none for datasets of more than [`GramCache::MAX_SHAPES`] shapes.
#[derive(Debug, Default)]
pub struct GramCache {
    entries: Vec<f64>,
}

impl GramCache {
    /// Above this many shapes the S × S table is not kept (8 MiB at 1,024).
    pub const MAX_SHAPES: usize = 1024;

    /// The table for `s` shapes, NaN where not yet summed; `None` past the size limit.
    fn entries(&mut self, s: usize) -> Option<&mut [f64]> {
        if s > Self::MAX_SHAPES {
            return None;
        }
        if self.entries.len() != s * s {
            self.entries = vec![f64::NAN; s * s];
        }
        Some(&mut self.entries)
    }
}

/// The fit's matrix from the shapes' displacements at the bundles (`S × B`, `[k * B + n]`):
/// row-major `3B × S`, row 3n + d coordinate d of bundle n.
fn fit_matrix(displacements: &[DVec3], b: usize) -> Vec<f64> {
    let s = displacements.len() / b.max(1);
    let mut a = vec![0.0; 3 * b * s];
    for k in 0..s {
        for n in 0..b {
            for (c, v) in displacements[k * b + n].to_array().iter().enumerate() {
                a[(3 * n + c) * s + k] = *v;
            }
        }
    }
    a
}

/// What [`FIT_L2`] and [`FIT_PENALTY`] are relative to: the mean squared column norm of a fit's
/// matrix (row-major, `cols` columns), at least the smallest positive double.
pub fn fit_scale(a: &[f64], cols: usize) -> f64 {
    (a.iter().map(|x| x * x).sum::<f64>() / cols as f64).max(f64::MIN_POSITIVE)
}

/// Gaussian correlation of the bundles' rest positions with length [`RESIDUAL_LENGTH`] times
/// the median nearest-neighbour distance (B × B, unit diagonal).
pub(crate) fn correlation(rest: &[DVec3]) -> Vec<f64> {
    correlation_over(rest, RESIDUAL_LENGTH)
}

/// Gaussian correlation of the bundles' rest positions with length `lengths` times the median
/// nearest-neighbour distance (B × B, unit diagonal).
pub(crate) fn correlation_over(rest: &[DVec3], lengths: f64) -> Vec<f64> {
    let b = rest.len();
    let mut nearest: Vec<f64> = rest
        .iter()
        .enumerate()
        .map(|(i, p)| {
            rest.iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, q)| p.distance(*q))
                .fold(f64::INFINITY, f64::min)
        })
        .filter(|d| d.is_finite())
        .collect();
    nearest.sort_by(f64::total_cmp);
    let median = nearest.get(nearest.len() / 2).copied().unwrap_or(1.0);
    let length = (lengths * median).max(f64::MIN_POSITIVE);
    let mut out = vec![0.0; b * b];
    for i in 0..b {
        for j in 0..b {
            let d2 = rest[i].distance_squared(rest[j]);
            out[i * b + j] = (-0.5 * d2 / (length * length)).exp();
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three shapes moving 12 bundles on a line in different directions.
    fn positions() -> (Vec<DVec3>, usize) {
        positions_on_line(12)
    }

    /// [`positions`]' three shapes on `b` bundles one unit apart.
    fn positions_on_line(b: usize) -> (Vec<DVec3>, usize) {
        let rest: Vec<DVec3> = (0..b).map(|i| DVec3::new(i as f64, 0.0, 0.0)).collect();
        let mut out = rest.clone();
        for k in 0..3 {
            for (i, r) in rest.iter().enumerate() {
                let x = i as f64 / b as f64;
                let d = match k {
                    0 => DVec3::new(0.0, 1.0, 0.0),
                    1 => DVec3::new(0.0, 0.0, x),
                    _ => DVec3::new(0.3 * x * x, 0.0, 0.0),
                };
                out.push(*r + d);
            }
        }
        (out, b)
    }

    /// The bundles' positions (B) under weights `w` of the three shapes of `sp`.
    fn blended(sp: &[DVec3], b: usize, w: [f64; 3]) -> Vec<DVec3> {
        (0..b)
            .map(|n| {
                sp[n]
                    + (0..3)
                        .map(|k| (sp[(k + 1) * b + n] - sp[n]) * w[k])
                        .sum::<DVec3>()
            })
            .collect()
    }

    #[test]
    fn the_fit_recovers_weights_inside_the_box_and_reproduces_the_markers() {
        let (sp, b) = positions();
        let prior = FitPrior::new(&sp, b).unwrap().unwrap();
        let w = [0.3, 0.7, 0.5];
        let targets = blended(&sp, b, w);
        let fit = prior.fit(&targets).unwrap();
        for (got, want) in fit.weights[1..].iter().zip(w) {
            assert!((got - want).abs() < 5e-3, "{:?}", fit.weights);
        }
        for (p, t) in fit.positions.iter().zip(&targets) {
            assert!(p.distance(*t) < 1e-3);
        }
    }

    #[test]
    fn the_unbounded_fit_is_the_closed_form_ridge_and_leaves_the_box_where_the_fit_cannot() {
        let (sp, b) = positions();
        let prior = FitPrior::new(&sp, b).unwrap().unwrap();
        let w = [-0.8, 1.9, 0.5];
        let mut targets = blended(&sp, b, w);
        targets[4] = DVec3::NAN;
        let free = prior.fit_unbounded(&targets).unwrap();
        // Closed form over the present rows: (AᵀA + l2·scale·I) x = Aᵀ(t − rest), the same
        // scale as the fit's (mean squared column norm over every row).
        let col = |k: usize, n: usize| sp[(k + 1) * b + n] - sp[n];
        let scale = (0..3)
            .map(|k| (0..b).map(|n| col(k, n).length_squared()).sum::<f64>())
            .sum::<f64>()
            / 3.0;
        let present: Vec<usize> = (0..b).filter(|&n| n != 4).collect();
        let mut g = vec![0.0; 9];
        let mut r = vec![0.0; 3];
        for i in 0..3 {
            for j in 0..3 {
                g[i * 3 + j] = present.iter().map(|&n| col(i, n).dot(col(j, n))).sum();
            }
            g[i * 3 + i] += FIT_L2 * scale;
            r[i] = present
                .iter()
                .map(|&n| col(i, n).dot(targets[n] - sp[n]))
                .sum();
        }
        let want = cholesky_solve(3, &cholesky(3, g).unwrap(), &r);
        for (got, want) in free.weights[1..].iter().zip(&want) {
            assert!((got - want).abs() < 1e-12, "{:?} vs {want:?}", free.weights);
        }
        for (got, truth) in free.weights[1..].iter().zip(w) {
            assert!((got - truth).abs() < 5e-3, "{:?}", free.weights);
        }
        // The boxed fit cannot reach -0.8 or 1.9.
        let boxed = prior.fit(&targets).unwrap();
        assert!(
            boxed.weights[1] > -0.2 && boxed.weights[2] < 1.2,
            "{:?}",
            boxed.weights
        );
        // Its positions are the weights' (the missing row placed too).
        let want4 = sp[4]
            + (0..3)
                .map(|k| col(k, 4) * free.weights[k + 1])
                .sum::<DVec3>();
        assert!(free.positions[4].distance(want4) < 1e-12);
    }

    #[test]
    fn denoising_with_zero_noise_returns_the_targets_and_keeps_missing_rows() {
        let (sp, b) = positions();
        let prior = FitPrior::new(&sp, b).unwrap().unwrap();
        let mut targets: Vec<DVec3> = sp[b..2 * b].to_vec();
        targets[3] = DVec3::NAN;
        let fit = prior.fit(&targets).unwrap();
        assert_eq!(prior.denoise(&targets, &fit, 0.0).unwrap()[0], targets[0]);
        let d = prior.denoise(&targets, &fit, 0.1).unwrap();
        assert!(d[3].is_nan() && d.iter().enumerate().all(|(i, p)| i == 3 || p.is_finite()));
    }

    #[test]
    fn denoising_pulls_independent_noise_toward_the_fit_and_keeps_a_shared_residual() {
        let (sp, b) = positions();
        let prior = FitPrior::new(&sp, b).unwrap().unwrap();
        let truth: Vec<DVec3> = sp[b..2 * b].to_vec();
        // Alternating ±0.05 in z: independent-looking noise the dataset does not explain.
        let noisy: Vec<DVec3> = truth
            .iter()
            .enumerate()
            .map(|(i, t)| *t + DVec3::new(0.0, 0.0, if i % 2 == 0 { 0.05 } else { -0.05 }))
            .collect();
        let fit = prior.fit(&noisy).unwrap();
        let d = prior.denoise(&noisy, &fit, 0.05).unwrap();
        let err = |p: &[DVec3]| {
            p.iter()
                .zip(&truth)
                .map(|(a, t)| a.distance(*t))
                .sum::<f64>()
        };
        assert!(
            err(&d) < 0.5 * err(&noisy),
            "{} vs {}",
            err(&d),
            err(&noisy)
        );
        // A smooth offset of all markers in x that no shape makes is kept (most of it).
        let shifted: Vec<DVec3> = truth
            .iter()
            .map(|t| *t + DVec3::new(0.0, 0.0, -2.0))
            .collect();
        let fit = prior.fit(&shifted).unwrap();
        let d = prior.denoise(&shifted, &fit, 0.05).unwrap();
        for (p, s) in d.iter().zip(&shifted) {
            assert!(p.distance(*s) < 0.2, "{p} vs {s}");
        }
    }

    #[test]
    fn a_residual_one_region_shares_is_kept_there_while_noise_elsewhere_is_pulled_to_the_fit() {
        let (sp, b) = positions_on_line(40);
        let prior = FitPrior::new(&sp, b).unwrap().unwrap();
        let sigma = 0.05;
        // A bump of 0.5 in y over the first ten bundles, which no shape makes, on a frame of
        // shape 0 at half weight; then alternating noise of σ in z everywhere.
        let truth: Vec<DVec3> = (0..b)
            .map(|i| {
                let bump = 0.5 * (-0.5 * ((i as f64 - 4.0) / 2.0).powi(2)).exp();
                sp[i] + (sp[b + i] - sp[i]) * 0.5 + DVec3::new(0.0, bump, 0.0)
            })
            .collect();
        let noisy: Vec<DVec3> = truth
            .iter()
            .enumerate()
            .map(|(i, t)| *t + DVec3::new(0.0, 0.0, if i % 2 == 0 { sigma } else { -sigma }))
            .collect();
        let fit = prior.fit(&noisy).unwrap();
        let d = prior.denoise(&noisy, &fit, sigma).unwrap();
        let mean_distance = |to: &[DVec3], range: std::ops::Range<usize>| {
            let n = range.len() as f64;
            range.map(|i| d[i].distance(to[i])).sum::<f64>() / n
        };
        // The bump is kept (it is ten times the noise); far from it the targets sit at the fit
        // (which takes a little of the bump everywhere through shape 0). A variance shared by
        // the whole face (the mean square over every marker) keeps nearly all of the noise
        // there: the bump's energy spread over all markers.
        let near = mean_distance(&truth, 0..9);
        let far = mean_distance(&fit.positions, 20..40);
        assert!(near < sigma, "near the bump {near}");
        assert!(far < 0.3 * sigma, "far from the bump {far}");
    }

    #[test]
    fn a_small_residual_the_whole_face_shares_is_kept_though_no_neighbourhood_alone_shows_it() {
        let (sp, b) = positions_on_line(40);
        let prior = FitPrior::new(&sp, b).unwrap().unwrap();
        let sigma = 0.05;
        // A wave of 2σ in y over the whole line, which no shape makes (shape 0 moves every
        // bundle alike), and noise of σ in every coordinate (signs alternating at three rates).
        // One marker spacing's neighbourhood holds too few markers to tell the wave's mean
        // square (2σ²/3 a coordinate) from noise at 2 standard errors; the whole line can.
        let truth: Vec<DVec3> = (0..b)
            .map(|i| {
                let wave = 2.0 * sigma * (std::f64::consts::TAU * i as f64 / b as f64).cos();
                sp[i] + (sp[b + i] - sp[i]) * 0.5 + DVec3::new(0.0, wave, 0.0)
            })
            .collect();
        let sign = |i: usize, rate: usize| if (i / rate) % 2 == 0 { sigma } else { -sigma };
        let noisy: Vec<DVec3> = truth
            .iter()
            .enumerate()
            .map(|(i, t)| *t + DVec3::new(sign(i, 1), sign(i, 2), sign(i, 4)))
            .collect();
        let fit = prior.fit(&noisy).unwrap();
        let d = prior.denoise(&noisy, &fit, sigma).unwrap();
        let wave_error =
            |got: &[DVec3]| (0..b).map(|i| (got[i].y - truth[i].y).abs()).sum::<f64>() / b as f64;
        let (kept, fitted) = (wave_error(&d), wave_error(&fit.positions));
        // Read over the whole line about half of the wave is kept (0.54 of the fit's error);
        // over one spacing's neighbourhood alone the targets stayed near the fit (0.90).
        assert!(kept < 0.7 * fitted, "targets {kept}, fit {fitted}");
    }
}
