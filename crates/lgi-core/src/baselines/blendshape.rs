//! Global blendshape fit, the standard production baseline: per frame the shape weights that
//! best explain the markers, min ‖A w − r‖² + l2‖w‖² + penalty·Σ(min(w,0)² + max(w−1,0)²).
//! The objective is a convex, C¹, piecewise quadratic, so an active-set (semi-smooth Newton)
//! iteration solves it exactly in a few steps.

use crate::error::{LgiError, Result};
use crate::linalg::{cholesky, cholesky_solve};
use rayon::prelude::*;

mod low_rank;
use low_rank::{DualStart, LowRank};

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

const MAX_ITERATIONS: usize = 100;

/// The objective's resolution relative to its value at 0 (‖t‖²): a step that changes it by
/// less has made no progress a double can show (the low-rank path sums it from terms of that
/// size, so its round-off is a few thousand ulps of them at most).
const ROUND_OFF: f64 = 1e-12;

/// Steps in a row without progress beyond [`ROUND_OFF`] after which the Newton iteration
/// takes the better of its candidate and iterate as the minimum.
const STAGNANT_STEPS: usize = 2;

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

/// What the Newton iteration asks of a frame's normal equations (dense or low-rank): the
/// minimiser of a quadratic piece, the line search's products, the objective, and word of
/// each damped step (`BlendshapeSolver::newton`).
struct Steps<Pc, Pr, Ob, St> {
    piece: Pc,
    products: Pr,
    objective: Ob,
    stepped: St,
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

impl BlendshapeSolver {
    /// `a` is row-major `rows × shapes`; `l2` and `penalty` are absolute, non-negative.
    pub fn new(a: Vec<f64>, rows: usize, shapes: usize, l2: f64, penalty: f64) -> Result<Self> {
        if a.len() != rows * shapes || shapes == 0 {
            return Err(LgiError::Input(format!(
                "blendshape matrix of {} values is not {rows}×{shapes} with shapes > 0",
                a.len()
            )));
        }
        if !(l2.is_finite() && l2 >= 0.0 && penalty.is_finite() && penalty >= 0.0) {
            return Err(LgiError::Input(format!(
                "l2 ({l2}) and penalty ({penalty}) must be finite and non-negative"
            )));
        }
        if a.iter().any(|x| !x.is_finite()) {
            return Err(LgiError::Input(
                "blendshape matrix has non-finite entries".into(),
            ));
        }
        let mut me = BlendshapeSolver {
            a,
            rows,
            shapes,
            l2,
            penalty,
            full_gram: Vec::new(),
            full: Vec::new(),
            low_rank: None,
        };
        me.low_rank = LowRank::new(
            &me.a,
            rows,
            shapes,
            &me.plain_gram_diagonal(),
            |p| me.plain_gram_column(p),
            l2,
        )?;
        // The whole Gram matrix and its factor serve only the dense path (S² doubles, 32 MB,
        // and S³/3 flops at 2,000 shapes; the local fits keep one solver per bundle).
        if me.low_rank.is_none() {
            let gram = me.gram(&vec![true; rows]);
            me.keep_dense(gram)?;
        }
        Ok(me)
    }

    /// The diagonal of AᵀA (all rows), each entry the bits `gram`'s diagonal less the ridge
    /// had: (Σ + l2) − l2.
    fn plain_gram_diagonal(&self) -> Vec<f64> {
        let s = self.shapes;
        let mut d = vec![0.0; s];
        for row in self.a.chunks_exact(s) {
            for (x, a) in d.iter_mut().zip(row) {
                *x += a * a;
            }
        }
        d.iter().map(|x| (x + self.l2) - self.l2).collect()
    }

    /// Column p of AᵀA (all rows), each entry the bits of `gram`'s (the rows summed in the
    /// same order; a product commutes exactly), its diagonal entry as
    /// [`plain_gram_diagonal`](Self::plain_gram_diagonal)'s.
    fn plain_gram_column(&self, p: usize) -> Vec<f64> {
        let s = self.shapes;
        let mut c = vec![0.0; s];
        for row in self.a.chunks_exact(s) {
            let ap = row[p];
            for (x, a) in c.iter_mut().zip(row) {
                *x += a * ap;
            }
        }
        let mut own = 0.0;
        for row in self.a.chunks_exact(s) {
            own += row[p] * row[p];
        }
        c[p] = (own + self.l2) - self.l2;
        c
    }

    /// Keeps `gram` (AᵀA + l2 I over all rows) and its Cholesky factor for the dense path.
    fn keep_dense(&mut self, gram: Vec<f64>) -> Result<()> {
        self.full = cholesky(self.shapes, gram.clone())?;
        self.full_gram = gram;
        Ok(())
    }

    /// Number of shapes S.
    pub fn num_shapes(&self) -> usize {
        self.shapes
    }

    /// Number of rows R.
    pub fn num_rows(&self) -> usize {
        self.rows
    }

    /// The rank of the normal equations' low-rank form, when the solver uses it (a matrix of
    /// rank at most half its shapes, e.g. an augmented dataset's).
    pub fn low_rank(&self) -> Option<usize> {
        self.low_rank.as_ref().map(LowRank::rank)
    }

    fn gram(&self, present: &[bool]) -> Vec<f64> {
        let s = self.shapes;
        let mut g = vec![0.0; s * s];
        for (r, _) in present.iter().enumerate().filter(|(_, &p)| p) {
            let row = &self.a[r * s..(r + 1) * s];
            for i in 0..s {
                for j in 0..=i {
                    g[i * s + j] += row[i] * row[j];
                }
            }
        }
        for i in 0..s {
            g[i * s + i] += self.l2;
            for j in 0..i {
                g[j * s + i] = g[i * s + j];
            }
        }
        g
    }

    /// The objective at `w` for `target` (NaN entries are dropped rows).
    pub fn objective(&self, w: &[f64], target: &[f64]) -> f64 {
        let s = self.shapes;
        let mut f = 0.0;
        for (r, t) in target.iter().enumerate().filter(|(_, t)| !t.is_nan()) {
            let row = &self.a[r * s..(r + 1) * s];
            let aw: f64 = row.iter().zip(w).map(|(a, b)| a * b).sum();
            f += (aw - t) * (aw - t);
        }
        for &x in w {
            let out = x.min(0.0) + (x - 1.0).max(0.0);
            f += self.l2 * x * x + self.penalty * out * out;
        }
        f
    }

    /// Minimises the objective for `target` (R values; NaN entries are missing rows, dropped).
    /// Errors: wrong length or infinite targets, a singular system, or no convergence within
    /// 100 iterations ([`LgiError::Input`]).
    pub fn solve(&self, target: &[f64]) -> Result<BlendshapeSolution> {
        Ok(self.solve_with_derivatives(target, &[], FitStart::Cold)?.0)
    }

    /// [`solve`](Self::solve), and for each of `directions` (R values each, a change of the
    /// target; rows missing from `target` are ignored) the change of the weights per unit of
    /// it, on the solution's piece (its clamped set held): the fit's derivative with respect
    /// to its target, for callers that optimise something of which the fit is a part.
    /// `start` says where the iteration starts ([`FitStart`]): the same minimum, in fewer
    /// steps from a nearby one.
    pub fn solve_with_derivatives(
        &self,
        target: &[f64],
        directions: &[Vec<f64>],
        start: FitStart<'_>,
    ) -> Result<(BlendshapeSolution, Vec<Vec<f64>>)> {
        let rows = self.rows;
        check_target(target, rows)?;
        let start_weights = match start {
            FitStart::Cold => None,
            FitStart::Weights(w) | FitStart::Nearby { weights: w, .. } => Some(w),
        };
        if start_weights.is_some_and(|w| w.len() != self.shapes || w.iter().any(|x| !x.is_finite()))
        {
            return Err(LgiError::Input(format!(
                "a start must be {} finite weights",
                self.shapes
            )));
        }
        if directions.iter().any(|d| d.len() != rows) {
            return Err(LgiError::Input(format!(
                "every direction must have {rows} values"
            )));
        }
        // Aᵀδ of each direction over the present rows.
        let s = self.shapes;
        let along: Vec<Vec<f64>> = directions
            .iter()
            .map(|d| {
                let mut out = vec![0.0; s];
                for (r, (&t, &x)) in target.iter().zip(d).enumerate() {
                    if !t.is_nan() && x != 0.0 {
                        for (o, a) in out.iter_mut().zip(&self.a[r * s..(r + 1) * s]) {
                            *o += a * x;
                        }
                    }
                }
                out
            })
            .collect();
        let Some(lr) = &self.low_rank else {
            return self.solve_dense(target, &along, start_weights);
        };
        let at = match start {
            FitStart::Cold => DualStart::Zero,
            FitStart::Nearby { dual, .. } => DualStart::Point(dual),
            FitStart::Weights(w) => DualStart::Weights(w),
        };
        // A warm start that does not finish is solved again from the dual's 0: a net kept
        // from before the Newton iteration's end was made robust to round-off at the box's
        // edge, which was why 15 warm fits in the test suite circled (none needs it now).
        match self.low_rank_fit(lr, target, &along, at, start_weights) {
            Err(_) if !matches!(start, FitStart::Cold) => {
                self.low_rank_fit(lr, target, &along, DualStart::Zero, None)
            }
            done => done,
        }
    }

    /// The low-rank path of [`solve_with_derivatives`](Self::solve_with_derivatives): the dual
    /// iteration from `at`, then the Newton iteration from its end (or from `start_weights`
    /// where the fit has no dual form).
    fn low_rank_fit(
        &self,
        lr: &LowRank,
        target: &[f64],
        along: &[Vec<f64>],
        at: DualStart<'_>,
        start_weights: Option<&[f64]>,
    ) -> Result<(BlendshapeSolution, Vec<Vec<f64>>)> {
        let (mut frame, atr) = lr.frame(target);
        let dual = frame.dual(at, self.l2, self.penalty, MAX_ITERATIONS)?;
        let (from, dual_steps) = match &dual {
            Some(end) => (Some(end.weights.as_slice()), end.steps),
            None => (start_weights, 0),
        };
        let frame = std::cell::RefCell::new(frame);
        let (mut solution, derivatives) = self.newton(
            &atr,
            along,
            from,
            Steps {
                piece: |clamped: &[bool], rhs: &[f64], _| {
                    frame
                        .borrow_mut()
                        .piece(clamped, rhs, self.l2, self.penalty)
                },
                products: |cand: &[f64], w: &[f64], d: &[f64]| {
                    frame.borrow_mut().products(cand, w, d)
                },
                objective: |w: &[f64]| frame.borrow_mut().data_term(w, &atr) + self.box_terms(w),
                stepped: |from: &[f64], cand: &[f64], alpha, to: &[f64]| {
                    frame.borrow_mut().stepped(from, cand, alpha, to)
                },
            },
        )?;
        solution.iterations += dual_steps;
        if let Some(end) = dual {
            solution.dual = end.point;
        }
        Ok((solution, derivatives))
    }

    /// The ridge and box terms of the objective at `w`.
    fn box_terms(&self, w: &[f64]) -> f64 {
        w.iter()
            .map(|&x| {
                let out = x.min(0.0) + (x - 1.0).max(0.0);
                self.l2 * x * x + self.penalty * out * out
            })
            .sum()
    }

    /// [`solve`](Self::solve) on the dense S × S normal equations.
    fn solve_dense(
        &self,
        target: &[f64],
        along: &[Vec<f64>],
        start: Option<&[f64]>,
    ) -> Result<(BlendshapeSolution, Vec<Vec<f64>>)> {
        let s = self.shapes;
        let present: Vec<bool> = target.iter().map(|t| !t.is_nan()).collect();
        let complete = present.iter().all(|&p| p);
        let partial;
        let gram = if complete {
            &self.full_gram
        } else {
            partial = self.gram(&present);
            &partial
        };
        let mut atr = vec![0.0; s];
        for (r, &t) in target.iter().enumerate().filter(|(_, t)| !t.is_nan()) {
            for (o, a) in atr.iter_mut().zip(&self.a[r * s..(r + 1) * s]) {
                *o += a * t;
            }
        }
        let piece = |clamped: &[bool], rhs: &[f64], first: bool| -> Result<Vec<f64>> {
            if first && complete && clamped.iter().all(|&c| !c) {
                return Ok(cholesky_solve(s, &self.full, rhs));
            }
            let mut h = gram.clone();
            for (i, &c) in clamped.iter().enumerate() {
                if c {
                    h[i * s + i] += self.penalty;
                }
            }
            Ok(cholesky_solve(s, &cholesky(s, h)?, rhs))
        };
        // The data term's slope parts, (A d)·(A w − t) + d·Aᵀt and (A d)·(A d), from A's rows.
        let products = |_: &[f64], w: &[f64], d: &[f64]| -> (f64, f64) {
            let (mut ad_aw, mut ad_ad) = (0.0, 0.0);
            for (r, _) in target.iter().enumerate().filter(|(_, t)| !t.is_nan()) {
                let row = &self.a[r * s..(r + 1) * s];
                let ad: f64 = row.iter().zip(d).map(|(a, b)| a * b).sum();
                let aw: f64 = row.iter().zip(w).map(|(a, b)| a * b).sum::<f64>();
                ad_aw += ad * aw;
                ad_ad += ad * ad;
            }
            (ad_aw, ad_ad)
        };
        self.newton(
            &atr,
            along,
            start,
            Steps {
                piece,
                products,
                objective: |w: &[f64]| self.objective(w, target),
                stepped: |_: &[f64], _: &[f64], _, _: &[f64]| {},
            },
        )
    }

    /// The active-set Newton iteration on the frame's normal equations ([`Steps`]): `piece(clamped, rhs,
    /// first)` minimises the quadratic piece where `clamped` weights are out of the box,
    /// `products(cand, w, d)` gives `(dᵀ G w, dᵀ G d)` for `d = cand − w` with G the data
    /// term's Hessian / 2, `objective(w)` the whole objective, and `stepped(w, cand, α, to)`
    /// hears of each damped step `to = w + α (cand − w)`; `atr` is Aᵀt. The solution's piece also solves
    /// for the right-hand sides `along` (the derivatives of [`solve_with_derivatives`]).
    ///
    /// [`solve_with_derivatives`]: Self::solve_with_derivatives
    fn newton(
        &self,
        atr: &[f64],
        along: &[Vec<f64>],
        start: Option<&[f64]>,
        steps: Steps<
            impl FnMut(&[bool], &[f64], bool) -> Result<Vec<f64>>,
            impl Fn(&[f64], &[f64], &[f64]) -> (f64, f64),
            impl Fn(&[f64]) -> f64,
            impl Fn(&[f64], &[f64], f64, &[f64]),
        >,
    ) -> Result<(BlendshapeSolution, Vec<Vec<f64>>)> {
        let Steps {
            mut piece,
            products,
            objective,
            stepped,
        } = steps;
        let s = self.shapes;
        let sides =
            |v: &[f64]| -> Vec<(bool, bool)> { v.iter().map(|&x| (x < 0.0, x > 1.0)).collect() };
        // The piece of w's active set: the clamped weights (out of the box), and the
        // penalty's pull toward 1 on the right-hand side of those above it.
        let clamped_and_rhs = |w: &[f64]| -> (Vec<bool>, Vec<f64>) {
            let mut rhs = atr.to_vec();
            for (r, &x) in rhs.iter_mut().zip(w) {
                if x > 1.0 {
                    *r += self.penalty;
                }
            }
            (w.iter().map(|&x| !(0.0..=1.0).contains(&x)).collect(), rhs)
        };
        // Start inside the box so the first step is the plain (unconstrained) normal equations
        // (or where the caller says).
        let mut w = start.map_or_else(|| vec![0.5; s], <[f64]>::to_vec);
        let mut f = objective(&w);
        // Steps in a row whose objective changed by less than its round-off (`resolution`).
        let mut stagnant = 0;
        let mut scale = None;
        let mut resolution = |f: f64| -> f64 {
            ROUND_OFF * *scale.get_or_insert_with(|| objective(&vec![0.0; s]).max(f))
        };
        for it in 1..=MAX_ITERATIONS {
            let (clamped, rhs) = clamped_and_rhs(&w);
            let cand = piece(&clamped, &rhs, it == 1)?;
            // The candidate minimises the quadratic piece of w's active set; if it lies in
            // that same piece the (C¹ convex) gradient vanishes there: the global minimum.
            // Near the minimum, round-off (the low-rank path's, with a small ridge: its
            // objective cancels ‖t‖² down to the fit's residual) can leave weights that the
            // box's soft penalty holds at an edge on either side of it from step to step
            // (1e-15 to 1e-9 seen on ICT and the sample), so the sides never agree while the
            // objective no longer moves. An exact line search that cannot lower the objective
            // along the piece's Newton direction means that direction is ~0 (the piece's
            // Hessian is at least the ridge): after `STAGNANT_STEPS` such steps the better of
            // the candidate and the iterate is the minimum to the objective's resolution.
            let agree = sides(&cand) == sides(&w);
            let undecided = !agree && stagnant >= STAGNANT_STEPS;
            if agree || undecided {
                let at_cand = objective(&cand);
                let (weights, objective) = if agree || at_cand <= f {
                    (cand, at_cand)
                } else {
                    (w, f)
                };
                let derivatives = along
                    .iter()
                    .map(|b| piece(&clamped, b, false))
                    .collect::<Result<_>>()?;
                let solution = BlendshapeSolution {
                    weights,
                    iterations: it,
                    objective,
                    dual: Vec::new(),
                };
                return Ok((solution, derivatives));
            }
            // Otherwise an exact line search: along w + αd the objective is a convex piecewise
            // quadratic in α, so its derivative is piecewise linear between the breakpoints
            // where a weight crosses 0 or 1; a damped step keeps the iteration descending.
            // The full step first, when it lowers the objective: each such step lands on a
            // piece's minimiser with a lower objective than the last, so none repeats and the
            // iteration ends, in fewer steps than the damped one takes (ICT-300's fit from
            // inside the box: 13.8 steps a frame damped, 8.9 so; the same minimum).
            let full = objective(&cand);
            if full < f {
                stagnant = if f - full <= resolution(f) {
                    stagnant + 1
                } else {
                    0
                };
                w = cand;
                f = full;
                continue;
            }
            let d: Vec<f64> = cand.iter().zip(&w).map(|(c, x)| c - x).collect();
            // The slope d·∇f(w + αd): the data term's part is linear in α, from (A d)·(A w − t)
            // and (A d)·(A d) once per iteration; the ridge and box terms are per weight.
            let (d_gw, ad_ad) = products(&cand, &w, &d);
            let ad_r = d_gw - d.iter().zip(atr).map(|(a, b)| a * b).sum::<f64>();
            let slope = |alpha: f64| -> f64 {
                let box_terms: f64 = w
                    .iter()
                    .zip(&d)
                    .map(|(&x, &di)| {
                        let x = x + alpha * di;
                        let out = x.min(0.0) + (x - 1.0).max(0.0);
                        2.0 * (self.l2 * x + self.penalty * out) * di
                    })
                    .sum();
                2.0 * (ad_r + alpha * ad_ad) + box_terms
            };
            let mut breaks: Vec<f64> = w
                .iter()
                .zip(&d)
                .filter(|(_, &di)| di != 0.0)
                .flat_map(|(&x, &di)| [-x / di, (1.0 - x) / di])
                .filter(|&a| a > 0.0 && a < 1.0)
                .collect();
            breaks.sort_by(f64::total_cmp);
            breaks.push(1.0);
            let (mut lo, mut slo) = (0.0, slope(0.0));
            let mut alpha = 1.0;
            for &hi in &breaks {
                let shi = slope(hi);
                if shi >= 0.0 {
                    alpha = if shi > slo {
                        lo + (hi - lo) * (-slo) / (shi - slo)
                    } else {
                        hi
                    };
                    break;
                }
                (lo, slo) = (hi, shi);
            }
            let moved: Vec<f64> = w.iter().zip(&d).map(|(x, dx)| x + alpha * dx).collect();
            stepped(&w, &cand, alpha, &moved);
            let fw = objective(&moved);
            if f - fw <= resolution(f) {
                // No descent a double can show (round-off in the slopes near the minimum):
                // the iterate stays, and the step counts as one without progress.
                stagnant += 1;
                continue;
            }
            stagnant = 0;
            w = moved;
            f = fw;
        }
        Err(LgiError::Input(format!(
            "blendshape fit did not converge in {MAX_ITERATIONS} iterations"
        )))
    }
}

impl BlendshapeSolver {
    /// The same solver on the dense path (its Gram matrix and factor made, the low-rank form
    /// dropped): the reference the tests compare the low-rank path with, and where a fit the
    /// low-rank path does not finish is solved again ([`crate::LocalFits`]).
    pub(crate) fn dense_only(&self) -> Result<Self> {
        let mut dense = self.clone();
        dense.low_rank = None;
        dense.keep_dense(dense.gram(&vec![true; dense.rows]))?;
        Ok(dense)
    }

    /// [`BlendshapeSolver::solve`] for many frames, in parallel; the first error wins.
    pub fn solve_many(&self, targets: &[Vec<f64>]) -> Result<Vec<BlendshapeSolution>> {
        targets.par_iter().map(|t| self.solve(t)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(super) fn rnd(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }

    // Brute force reference: projected gradient descent with a tiny fixed step, many steps.
    fn gradient_descent(sol: &BlendshapeSolver, t: &[f64]) -> Vec<f64> {
        let s = sol.num_shapes();
        let mut w = vec![0.0; s];
        for _ in 0..200_000 {
            let mut g = vec![0.0; s];
            for (r, &tr) in t.iter().enumerate() {
                let row = &sol.a[r * s..(r + 1) * s];
                let res: f64 = row.iter().zip(&w).map(|(a, b)| a * b).sum::<f64>() - tr;
                for (gi, a) in g.iter_mut().zip(row) {
                    *gi += 2.0 * res * a;
                }
            }
            for i in 0..s {
                let out = w[i].min(0.0) + (w[i] - 1.0).max(0.0);
                g[i] += 2.0 * (sol.l2 * w[i] + sol.penalty * out);
                w[i] -= 2e-3 * g[i];
            }
        }
        w
    }

    #[test]
    fn active_set_solution_matches_slow_gradient_descent() {
        for seed in 0..5u64 {
            let mut s = seed;
            let (rows, shapes) = (12, 4);
            let a: Vec<f64> = (0..rows * shapes).map(|_| rnd(&mut s)).collect();
            let t: Vec<f64> = (0..rows).map(|_| 3.0 * rnd(&mut s)).collect();
            let sol = BlendshapeSolver::new(a, rows, shapes, 1e-3, 5.0).unwrap();
            let got = sol.solve(&t).unwrap();
            let want = gradient_descent(&sol, &t);
            for (g, w) in got.weights.iter().zip(&want) {
                assert!(
                    (g - w).abs() < 1e-6,
                    "seed {seed}: {:?} vs {want:?}",
                    got.weights
                );
            }
            assert!(got.objective <= sol.objective(&want, &t) + 1e-12);
        }
    }

    /// 12 shapes that are combinations of 3 (an augmented dataset's in-betweens and sums)
    /// over 30 rows: rank 3, so the solver takes the low-rank path.
    fn augmented(seed: u64) -> (Vec<f64>, usize, usize) {
        let (rows, base, shapes) = (30, 3, 12);
        let mut s = seed;
        let b: Vec<f64> = (0..rows * base).map(|_| rnd(&mut s)).collect();
        let mix: Vec<f64> = (0..shapes * base)
            .map(|i| {
                if i % base == (i / base) % base {
                    1.0
                } else {
                    0.6 * rnd(&mut s)
                }
            })
            .collect();
        let a = (0..rows * shapes)
            .map(|i| {
                let (r, k) = (i / shapes, i % shapes);
                (0..base).map(|j| b[r * base + j] * mix[k * base + j]).sum()
            })
            .collect();
        (a, rows, shapes)
    }

    #[test]
    fn the_low_rank_path_equals_the_dense_path_and_gradient_descent() {
        for seed in 0..4u64 {
            let (a, rows, shapes) = augmented(seed);
            let sol = BlendshapeSolver::new(a, rows, shapes, 1e-2, 5.0).unwrap();
            assert_eq!(sol.low_rank(), Some(3), "seed {seed}");
            let dense = sol.dense_only().unwrap();
            let mut s = seed + 100;
            let mut t: Vec<f64> = (0..rows).map(|_| 2.0 * rnd(&mut s)).collect();
            for missing in [vec![], vec![4, 5, 6], vec![0, 1, 2, 27, 28, 29]] {
                for &m in &missing {
                    t[m] = f64::NAN;
                }
                let got = sol.solve(&t).unwrap();
                let want = dense.solve(&t).unwrap();
                let slow = gradient_descent(
                    &sol,
                    &t.iter()
                        .map(|x| if x.is_nan() { 0.0 } else { *x })
                        .collect::<Vec<_>>(),
                );
                for ((g, w), d) in got.weights.iter().zip(&want.weights).zip(&slow) {
                    assert!((g - w).abs() < 1e-9, "seed {seed} {missing:?}: {g} vs {w}");
                    if missing.is_empty() {
                        assert!((g - d).abs() < 1e-6, "seed {seed}: {g} vs descent {d}");
                    }
                }
                assert!((got.objective - want.objective).abs() < 1e-9 * (1.0 + want.objective));
            }
        }
    }

    /// The Newton iteration's end where the box's soft penalty holds a weight within
    /// round-off of an edge: a shape that no row sees keeps weight 0, and a piece solved with
    /// round-off (the low-rank path with a small ridge: 1e-12 seen on ICT) puts it on either
    /// side of 0 from step to step, so the candidate's sides never agree with the iterate's
    /// (before: "did not converge in 100 iterations"). It must end at the minimum once the
    /// objective stops moving.
    #[test]
    fn a_weight_crossing_the_box_edge_by_round_off_still_ends_at_the_minimum() {
        let (rows, shapes) = (6, 4);
        let mut s = 3;
        let mut a: Vec<f64> = (0..rows * shapes).map(|_| rnd(&mut s)).collect();
        for r in 0..rows {
            a[r * shapes + 3] = 0.0;
        }
        let t: Vec<f64> = (0..rows).map(|_| 2.0 * rnd(&mut s)).collect();
        let sol = BlendshapeSolver::new(a, rows, shapes, 1e-3, 5.0).unwrap();
        let want = sol.solve(&t).unwrap();
        assert_eq!(want.weights[3], 0.0);
        let mut atr = vec![0.0; shapes];
        for (r, &x) in t.iter().enumerate() {
            for (o, v) in atr.iter_mut().zip(&sol.a[r * shapes..(r + 1) * shapes]) {
                *o += v * x;
            }
        }
        let gram = sol.gram(&[true; 6]);
        let piece = |clamped: &[bool], rhs: &[f64], _| -> Result<Vec<f64>> {
            let mut h = gram.clone();
            for (i, &c) in clamped.iter().enumerate() {
                if c {
                    h[i * shapes + i] += sol.penalty;
                }
            }
            let mut cand = cholesky_solve(shapes, &cholesky(shapes, h)?, rhs);
            // Always on the other side of the edge from the iterate.
            cand[3] = if clamped[3] { 1e-13 } else { -1e-13 };
            Ok(cand)
        };
        let products = |_: &[f64], w: &[f64], d: &[f64]| -> (f64, f64) {
            let (mut ad_aw, mut ad_ad) = (0.0, 0.0);
            for r in 0..rows {
                let row = &sol.a[r * shapes..(r + 1) * shapes];
                let ad: f64 = row.iter().zip(d).map(|(a, b)| a * b).sum();
                let aw: f64 = row.iter().zip(w).map(|(a, b)| a * b).sum();
                ad_aw += ad * aw;
                ad_ad += ad * ad;
            }
            (ad_aw, ad_ad)
        };
        let (got, _) = sol
            .newton(
                &atr,
                &[],
                None,
                Steps {
                    piece,
                    products,
                    objective: |w: &[f64]| sol.objective(w, &t),
                    stepped: |_: &[f64], _: &[f64], _, _: &[f64]| {},
                },
            )
            .unwrap();
        assert!(got.iterations < 10, "{} steps", got.iterations);
        for (g, w) in got.weights.iter().zip(&want.weights) {
            assert!(
                (g - w).abs() < 1e-12,
                "{:?} vs {:?}",
                got.weights,
                want.weights
            );
        }
    }

    /// 240 shapes over 30 rows, every one a random positive mix of 6 (like scans of one face): most weights end
    /// clamped by the box (a fit of many scans), and the first steps clamp and free many at
    /// once, so the low-rank path sums its free weights' products afresh as well as updating
    /// them one by one; it must still land on the dense path's minimum.
    #[test]
    fn a_fit_that_clamps_most_of_many_shapes_equals_the_dense_path() {
        let (rows, shapes) = (30, 240);
        for seed in 0..3u64 {
            let (sol, mut t) = scans(seed);
            assert_eq!(sol.low_rank(), Some(6), "seed {seed}");
            let dense = sol.dense_only().unwrap();
            let mut s = seed + 90;
            let dirs: Vec<Vec<f64>> = vec![(0..rows).map(|_| rnd(&mut s)).collect()];
            for missing in [vec![], vec![2, 9, 17]] {
                for &m in &missing {
                    t[m] = f64::NAN;
                }
                let (got, gd) = sol
                    .solve_with_derivatives(&t, &dirs, FitStart::Cold)
                    .unwrap();
                let (want, wd) = dense
                    .solve_with_derivatives(&t, &dirs, FitStart::Cold)
                    .unwrap();
                let clamped = want
                    .weights
                    .iter()
                    .filter(|w| !(0.0..=1.0).contains(*w))
                    .count();
                assert!(2 * clamped > shapes, "seed {seed}: only {clamped} clamped");
                assert!(
                    got.iterations > 2,
                    "seed {seed}: {} iterations",
                    got.iterations
                );
                for (g, w) in got.weights.iter().zip(&want.weights) {
                    assert!((g - w).abs() < 1e-9, "seed {seed} {missing:?}: {g} vs {w}");
                }
                for (g, w) in gd[0].iter().zip(&wd[0]) {
                    assert!((g - w).abs() < 1e-7, "seed {seed} {missing:?}: {g} vs {w}");
                }
                let rel = (got.objective - want.objective).abs() / (1.0 + want.objective);
                assert!(
                    rel < 1e-9,
                    "seed {seed}: {} vs {}",
                    got.objective,
                    want.objective
                );
            }
        }
    }

    /// A `rows × shapes` matrix (row-major) whose columns mix `base` random columns, the
    /// mixing weights drawn (by [`rnd`] from `seed`) plus `offset` (0.5: positive mixes, like
    /// scans of one face).
    pub(super) fn mixes(
        rows: usize,
        base: usize,
        shapes: usize,
        offset: f64,
        seed: &mut u64,
    ) -> Vec<f64> {
        let b: Vec<f64> = (0..rows * base).map(|_| rnd(seed)).collect();
        let mix: Vec<f64> = (0..shapes * base).map(|_| rnd(seed) + offset).collect();
        (0..rows * shapes)
            .map(|i| {
                let (r, k) = (i / shapes, i % shapes);
                (0..base).map(|j| b[r * base + j] * mix[k * base + j]).sum()
            })
            .collect()
    }

    #[test]
    fn the_low_rank_forms_gram_columns_are_the_whole_gram_matrixs_bits_less_the_ridge() {
        let (rows, shapes) = (17, 40);
        let mut seed = 11u64;
        let a = mixes(rows, 5, shapes, 0.3, &mut seed);
        let l2 = 1e-3 * 0.37;
        let sol = BlendshapeSolver::new(a, rows, shapes, l2, 10.0).unwrap();
        assert!(
            sol.low_rank().is_some(),
            "a rank-5 matrix takes the low-rank form"
        );
        let gram = sol.gram(&vec![true; rows]);
        let diag = sol.plain_gram_diagonal();
        for p in 0..shapes {
            let col = sol.plain_gram_column(p);
            for i in 0..shapes {
                let want = if i == p {
                    gram[i * shapes + p] - l2
                } else {
                    gram[i * shapes + p]
                };
                assert_eq!(col[i].to_bits(), want.to_bits(), "column {p}, row {i}");
            }
            assert_eq!(diag[p].to_bits(), (gram[p * shapes + p] - l2).to_bits());
        }
    }

    /// 240 positive mixes of 6 shapes over 30 rows (scans of one face: most weights end
    /// clamped) and a target.
    fn scans(seed: u64) -> (BlendshapeSolver, Vec<f64>) {
        let (rows, base, shapes) = (30, 6, 240);
        let mut s = seed + 40;
        let a = mixes(rows, base, shapes, 0.5, &mut s);
        let t = (0..rows).map(|_| 3.0 * rnd(&mut s)).collect();
        (
            BlendshapeSolver::new(a, rows, shapes, 1e-3, 10.0).unwrap(),
            t,
        )
    }

    #[test]
    fn the_dual_from_a_nearby_fits_dual_point_lands_on_the_dense_minimum() {
        for seed in 0..3u64 {
            let (sol, t) = scans(seed);
            let dense = sol.dense_only().unwrap();
            let mut s = seed + 7;
            for missing in [vec![], vec![3, 11, 25]] {
                let mut t = t.clone();
                for &m in &missing {
                    t[m] = f64::NAN;
                }
                // A nearby fit of the same frame: the target moved by 5 % of its scale.
                let near: Vec<f64> = t.iter().map(|x| x + 0.15 * rnd(&mut s)).collect();
                let nearby = sol.solve(&near).unwrap();
                assert_eq!(nearby.dual.len(), 6, "seed {seed} {missing:?}");
                let from = |dual: &[f64]| {
                    sol.solve_with_derivatives(
                        &t,
                        &[],
                        FitStart::Nearby {
                            weights: &nearby.weights,
                            dual,
                        },
                    )
                    .unwrap()
                    .0
                };
                let got = from(&nearby.dual);
                let want = dense.solve(&t).unwrap();
                let cold = sol.solve(&t).unwrap();
                // A dual point of another length is not the frame's: the dual starts at 0.
                let other = from(&nearby.dual[1..]);
                for (((g, c), o), w) in got
                    .weights
                    .iter()
                    .zip(&cold.weights)
                    .zip(&other.weights)
                    .zip(&want.weights)
                {
                    for (x, what) in [(g, "nearby"), (c, "cold"), (o, "other")] {
                        assert!(
                            (x - w).abs() < 1e-9,
                            "seed {seed} {missing:?} {what}: {x} vs {w}"
                        );
                    }
                }
                assert_eq!(other.iterations, cold.iterations);
                // Started nearby it takes fewer steps than from 0.
                assert!(
                    got.iterations <= cold.iterations,
                    "seed {seed} {missing:?}: {} vs {} from 0",
                    got.iterations,
                    cold.iterations
                );
            }
        }
    }

    #[test]
    fn derivatives_equal_finite_differences_of_the_solution_on_both_paths() {
        for (a, rows, shapes) in [augmented(7), {
            let mut s = 11u64;
            (((0..30 * 5).map(|_| rnd(&mut s)).collect()), 30, 5)
        }] {
            let sol = BlendshapeSolver::new(a, rows, shapes, 1e-2, 5.0).unwrap();
            let mut s = 3u64;
            let mut t: Vec<f64> = (0..rows).map(|_| 2.0 * rnd(&mut s)).collect();
            t[4] = f64::NAN;
            let dirs: Vec<Vec<f64>> = (0..2)
                .map(|_| (0..rows).map(|_| rnd(&mut s)).collect())
                .collect();
            let (base, dw) = sol
                .solve_with_derivatives(&t, &dirs, FitStart::Cold)
                .unwrap();
            // Started at the solution, the iteration ends at once, on the same weights: one
            // primal step (the low-rank path first takes one dual step from the solution's
            // dual point, which the primal step confirms).
            let (again, _) = sol
                .solve_with_derivatives(&t, &[], FitStart::Weights(&base.weights))
                .unwrap();
            let steps = if sol.low_rank().is_some() { 2 } else { 1 };
            assert_eq!(again.iterations, steps);
            for (a, b) in again.weights.iter().zip(&base.weights) {
                assert!((a - b).abs() < 1e-12);
            }
            for (d, dwd) in dirs.iter().zip(&dw) {
                let h = 1e-7;
                let moved: Vec<f64> = t.iter().zip(d).map(|(a, b)| a + h * b).collect();
                let w = sol.solve(&moved).unwrap().weights;
                for ((x1, x0), g) in w.iter().zip(&base.weights).zip(dwd) {
                    assert!(((x1 - x0) / h - g).abs() < 1e-5, "{} vs {g}", (x1 - x0) / h);
                }
            }
        }
    }

    #[test]
    fn weights_inside_the_box_are_the_plain_least_squares_solution() {
        let a = vec![1.0, 0.0, 0.0, 1.0, 1.0, 1.0];
        let sol = BlendshapeSolver::new(a, 3, 2, 0.0, 10.0).unwrap();
        let got = sol.solve(&[0.3, 0.6, 0.9]).unwrap();
        assert!((got.weights[0] - 0.3).abs() < 1e-12 && (got.weights[1] - 0.6).abs() < 1e-12);
        assert_eq!(got.iterations, 1);
    }

    #[test]
    fn missing_rows_are_dropped_and_bad_inputs_are_errors() {
        let a = vec![1.0, 0.0, 0.0, 1.0, 1.0, 1.0];
        let sol = BlendshapeSolver::new(a, 3, 2, 0.0, 0.0).unwrap();
        let got = sol.solve(&[0.2, f64::NAN, 0.7]).unwrap();
        assert!((got.weights[0] - 0.2).abs() < 1e-12 && (got.weights[1] - 0.5).abs() < 1e-12);
        assert!(sol.solve(&[0.0, 1.0]).is_err());
        assert!(sol.solve(&[0.0, f64::INFINITY, 1.0]).is_err());
        assert!(BlendshapeSolver::new(vec![1.0, 1.0], 1, 2, 0.0, 0.0).is_err());
        assert!(BlendshapeSolver::new(vec![1.0, 1.0], 1, 2, -1.0, 0.0).is_err());
    }
}
