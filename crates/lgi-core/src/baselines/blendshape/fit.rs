//! The fit itself: [`BlendshapeSolver::solve`] and its variants check the target and the
//! start, then run the Newton iteration on the dense normal equations, or on their low-rank
//! form from where the fit's dual ends.

use super::low_rank::{DualStart, LowRank};
use super::newton::{Steps, MAX_ITERATIONS};
use super::pieces::PieceFactors;
use super::{check_target, BlendshapeSolution, BlendshapeSolver, FitStart};
use crate::error::{LgiError, Result};
use crate::linalg::{cholesky_solve, dot_rows};
use rayon::prelude::*;

impl BlendshapeSolver {
    /// The objective at `w` for `target` (NaN entries are dropped rows).
    pub fn objective(&self, w: &[f64], target: &[f64]) -> f64 {
        let mut f = 0.0;
        self.each_present_row(target, [w], |t, [aw]| f += (aw - t) * (aw - t));
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
        self.solve_with_pieces(target, directions, start, &mut PieceFactors::default())
    }

    /// A fit of a window's frame in turn (`crate::LocalFits`): [`solve`](Self::solve) from
    /// `start`, the dense path's piece factors kept in `pieces` for the next frame's fit (the
    /// same bits as without them).
    pub(crate) fn solve_keeping(
        &self,
        target: &[f64],
        start: FitStart<'_>,
        pieces: &mut PieceFactors,
    ) -> Result<BlendshapeSolution> {
        Ok(self.solve_with_pieces(target, &[], start, pieces)?.0)
    }

    /// [`solve_with_derivatives`](Self::solve_with_derivatives), the dense path's piece
    /// factors from and into `pieces`.
    fn solve_with_pieces(
        &self,
        target: &[f64],
        directions: &[Vec<f64>],
        start: FitStart<'_>,
        pieces: &mut PieceFactors,
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
            return self.solve_dense(target, &along, start_weights, pieces);
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

    /// [`solve`](Self::solve) on the dense S × S normal equations, each piece's factor from
    /// `pieces` where kept there (and kept there when made).
    fn solve_dense(
        &self,
        target: &[f64],
        along: &[Vec<f64>],
        start: Option<&[f64]>,
        pieces: &mut PieceFactors,
    ) -> Result<(BlendshapeSolution, Vec<Vec<f64>>)> {
        let s = self.shapes;
        let present: Vec<bool> = target.iter().map(|t| !t.is_nan()).collect();
        let complete = present.iter().all(|&p| p);
        // A frame with rows missing makes its Gram matrix only if a piece is not kept.
        let partial = std::cell::OnceCell::new();
        let gram = || -> &Vec<f64> {
            if complete {
                &self.full_gram
            } else {
                partial.get_or_init(|| self.gram(&present))
            }
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
            let factor = pieces.factor(s, &present, clamped, || {
                let mut h = gram().clone();
                for (i, &c) in clamped.iter().enumerate() {
                    if c {
                        h[i * s + i] += self.penalty;
                    }
                }
                Ok(h)
            })?;
            Ok(cholesky_solve(s, factor, rhs))
        };
        // The data term's slope parts, (A d)·(A w − t) + d·Aᵀt and (A d)·(A d), from A's rows.
        let products = |_: &[f64], w: &[f64], d: &[f64]| -> (f64, f64) {
            let (mut ad_aw, mut ad_ad) = (0.0, 0.0);
            self.each_present_row(target, [d, w], |_, [ad, aw]| {
                ad_aw += ad * aw;
                ad_ad += ad * ad;
            });
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

    /// `each(t, [row · x for x in xs])` for every row of A whose target `t` is present, in
    /// row order: each product one sum in order (the bits of `Iterator::sum`), eight rows'
    /// sums side by side ([`dot_rows`]) instead of one dependent chain at a time.
    fn each_present_row<const N: usize>(
        &self,
        target: &[f64],
        xs: [&[f64]; N],
        mut each: impl FnMut(f64, [f64; N]),
    ) {
        const ROWS: usize = 8;
        let s = self.shapes;
        let row = |r: usize| &self.a[r * s..(r + 1) * s];
        let mut groups = target.chunks_exact(ROWS);
        for (g, ts) in (&mut groups).enumerate() {
            let rows: [&[f64]; ROWS] = std::array::from_fn(|l| row(g * ROWS + l));
            let sums = xs.map(|x| dot_rows(rows, x));
            for (l, &t) in ts.iter().enumerate() {
                if !t.is_nan() {
                    each(t, std::array::from_fn(|i| sums[i][l]));
                }
            }
        }
        let first = target.len() - groups.remainder().len();
        for (r, &t) in target.iter().enumerate().skip(first) {
            if !t.is_nan() {
                each(
                    t,
                    xs.map(|x| row(r).iter().zip(x).map(|(a, b)| a * b).sum()),
                );
            }
        }
    }

    /// [`BlendshapeSolver::solve`] for many frames, in parallel; the first error wins.
    pub fn solve_many(&self, targets: &[Vec<f64>]) -> Result<Vec<BlendshapeSolution>> {
        targets.par_iter().map(|t| self.solve(t)).collect()
    }
}
