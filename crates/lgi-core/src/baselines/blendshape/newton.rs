//! The active-set (semi-smooth Newton) iteration that both paths of the fit share: it asks a
//! frame's normal equations, dense or low-rank, only for the quadratic pieces' minimisers and
//! the line search's products ([`Steps`]), so one iteration serves both.

use super::{BlendshapeSolution, BlendshapeSolver};
use crate::error::{LgiError, Result};

/// The most steps a fit's iteration takes (the Newton iteration, and the low-rank path's dual).
pub(super) const MAX_ITERATIONS: usize = 100;

/// The objective's resolution relative to its value at 0 (‖t‖²): a step that changes it by
/// less has made no progress a double can show (the low-rank path sums it from terms of that
/// size, so its round-off is a few thousand ulps of them at most).
const ROUND_OFF: f64 = 1e-12;

/// Steps in a row without progress beyond [`ROUND_OFF`] after which the Newton iteration
/// takes the better of its candidate and iterate as the minimum.
const STAGNANT_STEPS: usize = 2;

/// What the Newton iteration asks of a frame's normal equations (dense or low-rank): the
/// minimiser of a quadratic piece, the line search's products, the objective, and word of
/// each damped step (`BlendshapeSolver::newton`).
pub(super) struct Steps<Pc, Pr, Ob, St> {
    pub(super) piece: Pc,
    pub(super) products: Pr,
    pub(super) objective: Ob,
    pub(super) stepped: St,
}

impl BlendshapeSolver {
    /// The active-set Newton iteration on the frame's normal equations ([`Steps`]):
    /// `piece(clamped, rhs, first)` minimises the quadratic piece where `clamped` weights are
    /// out of the box, `products(cand, w, d)` gives `(dᵀ G w, dᵀ G d)` for `d = cand − w` with
    /// G the data term's Hessian / 2, `objective(w)` the whole objective, and
    /// `stepped(w, cand, α, to)` hears of each damped step `to = w + α (cand − w)`; `atr` is
    /// Aᵀt. The solution's piece also solves for the right-hand sides `along` (the derivatives
    /// of [`solve_with_derivatives`]).
    ///
    /// [`solve_with_derivatives`]: Self::solve_with_derivatives
    pub(super) fn newton(
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
