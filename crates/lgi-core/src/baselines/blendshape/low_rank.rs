//! The blendshape fit's normal equations in the span of the matrix's rows. A dataset whose
//! shapes are combinations of fewer ones (in-betweens and pair sums of an augmented dataset:
//! ICT-300's 300 shapes span 55 directions at 120 markers) has `AᵀA` of low rank r, so every
//! Newton step's `(AᵀA + D) w = b`, D diagonal (the ridge plus the box penalty), is solved by
//! the Woodbury identity in r dimensions instead of S: O(S r + r³) per step, not O(S³).
//!
//! With `Aᵀ = W X` (W: S × r, X: r × R with orthonormal rows), a frame whose rows `m` are
//! missing has `A_pᵀ A_p = W K Wᵀ`, `K = I − X_m X_mᵀ`, and `(D + W K Wᵀ) w = b` is
//! `w = D⁻¹ (b − W y)` with `(I + K Wᵀ D⁻¹ W) y = K Wᵀ D⁻¹ b`.
//!
//! Here the factorisation (`LowRank`) and a frame's system made from it; the frame's primal
//! steps are in `frame`, its dual in `dual`, the kernels both use in `kernels`.

use crate::error::Result;
use crate::linalg::{cholesky, cholesky_solve, lower_solve};
use std::borrow::Cow;
use std::sync::OnceLock;

mod dual;
mod frame;
mod kernels;
#[cfg(test)]
mod tests;

pub(super) use dual::DualStart;
use dual::Whitened;
use frame::Frame;
use kernels::{
    add_outer_products, columns_times, gram_of, lower_t_times, mirror_upper, single, times_lower,
    transposed, wt_times,
};

/// A rank below this fraction of the shape count takes the low-rank path (the dense path is
/// cheaper near full rank).
const MAX_RANK_FRACTION: f64 = 0.5;

/// Directions of `AᵀA` whose energy is below this fraction of the ridge (summed over the shapes)
/// are dropped: against the ridge they change the normal equations by at most that fraction.
const DROP_FRACTION: f64 = 1e-6;

/// A W whose transpose in double precision takes more bytes than this is also kept in single
/// precision for the dual's passes: half a core's L2 cache (2 MiB on the machines measured),
/// above which a pass waits on memory (2,000 scans at rank 135: 2.2 MB, 1.1 MB in single).
/// The dual's steps only choose where the fit ends; the weights returned are solved in double
/// precision on the pieces it found.
const SINGLE_PASSES_ABOVE: usize = 1 << 20;

/// The factors of one matrix.
#[derive(Debug, Clone)]
pub(super) struct LowRank {
    shapes: usize,
    rank: usize,
    /// W, `S × r` row-major.
    w: Vec<f64>,
    /// Wᵀ, `r × S` row-major: what [`columns_times`] reads.
    wt: Vec<f64>,
    /// Wᵀ in single precision when it is larger than [`SINGLE_PASSES_ABOVE`]: the dual's
    /// steps' passes ([`Frame::dual`]).
    wt32: Option<Vec<f32>>,
    /// Xᵀ, `R × r` row-major: row ρ of it is what row ρ of A contributes.
    xt: Vec<f64>,
    /// WᵀW, `r × r`.
    wtw: Vec<f64>,
    /// The complete frames' [`Whitened`] form, made on first use.
    whitened: OnceLock<Whitened>,
}

impl LowRank {
    /// The complete frames' [`Whitened`] form for a fit with `held` = 1 / (l2 + penalty), made
    /// now (a model's build or load) rather than by its first complete frame.
    pub(super) fn whiten(&self, held: f64) -> crate::error::Result<()> {
        if self.whitened.get().is_none() {
            let made = Whitened::new(&self.w, &self.wtw, self.rank, self.shapes, held)?;
            let _ = self.whitened.set(made);
        }
        Ok(())
    }

    /// The factors of `A` (R × S row-major) when its numerical rank is low enough to pay,
    /// else `None`. The Gram matrix AᵀA (without the ridge) is given by its diagonal (S) and
    /// `column(p)` (its column p, S): only the pivots' columns are asked for (r of S; the
    /// whole matrix is R S² / 2 multiply-adds, seconds for a local fit's window of 2,000
    /// scans).
    pub(super) fn new(
        a: &[f64],
        rows: usize,
        shapes: usize,
        gram_diagonal: &[f64],
        column: impl Fn(usize) -> Vec<f64>,
        l2: f64,
    ) -> Result<Option<LowRank>> {
        let s = shapes;
        if l2 <= 0.0 || s < 4 {
            return Ok(None);
        }
        // Pivoted Cholesky of AᵀA, stopped where what is left is negligible.
        let tolerance = DROP_FRACTION * l2 / s as f64;
        let max_rank = (MAX_RANK_FRACTION * s as f64) as usize;
        let mut diag: Vec<f64> = gram_diagonal.to_vec();
        let mut cols: Vec<Vec<f64>> = Vec::new();
        loop {
            let (p, dp) = diag
                .iter()
                .copied()
                .enumerate()
                .fold((0, f64::NEG_INFINITY), |b, x| if x.1 > b.1 { x } else { b });
            if dp.is_nan() || dp <= tolerance {
                break;
            }
            if cols.len() == max_rank {
                return Ok(None);
            }
            let root = dp.sqrt();
            let at_p = column(p);
            let col: Vec<f64> = (0..s)
                .map(|i| {
                    let done: f64 = cols.iter().map(|c| c[i] * c[p]).sum();
                    (at_p[i] - done) / root
                })
                .collect();
            for (d, c) in diag.iter_mut().zip(&col) {
                *d -= c * c;
            }
            diag[p] = 0.0;
            cols.push(col);
        }
        let r = cols.len();
        if r == 0 {
            return Ok(None);
        }
        let mut w = vec![0.0; s * r];
        for (j, c) in cols.iter().enumerate() {
            for i in 0..s {
                w[i * r + j] = c[i];
            }
        }
        // X = (WᵀW)⁻¹ Wᵀ Aᵀ, then its rows made orthonormal: X X ᵀ = L Lᵀ, X ← L⁻¹X, W ← W L.
        let wtw = gram_of(&w, s, r);
        let wtw_l = cholesky(r, wtw)?;
        let mut xt = vec![0.0; rows * r];
        for rho in 0..rows {
            let row = &a[rho * s..(rho + 1) * s];
            let aw: Vec<f64> = (0..r)
                .map(|j| (0..s).map(|i| row[i] * w[i * r + j]).sum())
                .collect();
            xt[rho * r..(rho + 1) * r].copy_from_slice(&cholesky_solve(r, &wtw_l, &aw));
        }
        let xxt = gram_of(&xt, rows, r);
        let l = cholesky(r, xxt)?;
        // Xᵀ ← Xᵀ L⁻ᵀ (each row solved against L), W ← W L.
        for rho in 0..rows {
            let row = &mut xt[rho * r..(rho + 1) * r];
            for i in 0..r {
                let s: f64 = (0..i).map(|k| l[i * r + k] * row[k]).sum();
                row[i] = (row[i] - s) / l[i * r + i];
            }
        }
        let mut wl = vec![0.0; s * r];
        for i in 0..s {
            for j in 0..r {
                wl[i * r + j] = (j..r).map(|k| w[i * r + k] * l[k * r + j]).sum();
            }
        }
        let wtw = gram_of(&wl, s, r);
        let wt = transposed(&wl, r);
        Ok(Some(LowRank {
            shapes: s,
            rank: r,
            wt32: (8 * wt.len() > SINGLE_PASSES_ABOVE).then(|| single(&wt)),
            wt,
            w: wl,
            xt,
            wtw,
            whitened: OnceLock::new(),
        }))
    }

    /// The same factors with the dual's passes in single precision whatever W's size.
    #[cfg(test)]
    fn with_single_passes(mut self) -> LowRank {
        self.wt32 = Some(single(&self.wt));
        self
    }

    /// The rank r.
    pub(super) fn rank(&self) -> usize {
        self.rank
    }

    /// One frame's system for `target` (R values, NaN rows missing): its `Aᵀt` too.
    pub(super) fn frame(&self, target: &[f64]) -> (Frame<'_>, Vec<f64>) {
        let r = self.rank;
        let mut c = vec![0.0; r];
        let mut missing = Vec::new();
        let mut tt = 0.0;
        for (rho, &t) in target.iter().enumerate() {
            let x = &self.xt[rho * r..(rho + 1) * r];
            if t.is_nan() {
                missing.push(rho);
            } else {
                tt += t * t;
                for (ci, xi) in c.iter_mut().zip(x) {
                    *ci += xi * t;
                }
            }
        }
        // K = I − X_m X_mᵀ, or None for I.
        let k = (!missing.is_empty()).then(|| {
            let mut k = vec![0.0; r * r];
            for i in 0..r {
                k[i * r + i] = 1.0;
            }
            let terms: Vec<(f64, &[f64])> = missing
                .iter()
                .map(|&rho| (-1.0, &self.xt[rho * r..(rho + 1) * r]))
                .collect();
            add_outer_products(&mut k, r, &terms);
            mirror_upper(&mut k, r);
            k
        });
        let atr = self.w_times(&c);
        // With markers missing, K = V Vᵀ (Cholesky) turns the frame's `W K Wᵀ` into the
        // complete frame's form `W' W'ᵀ` with W' = W V: every Newton step then solves a
        // symmetric system by Cholesky (r³/6) instead of forming `K M` and factoring it by LU
        // (4r³/3), for O(S r²) once per fit. A K that is not positive definite (a direction
        // seen only by missing rows) keeps the general form.
        // The last two: the data term's τ where the frame has a dual form (‖W'ᵀ w − τ‖² +
        // const, [`Frame::dual`]), and the matrix's whitened rows for a complete frame.
        let (w, wt, wt32, wtw, k, tau, whitened) = match k.as_ref().map(|k| cholesky(r, k.clone()))
        {
            None => (
                Cow::Borrowed(&self.w[..]),
                Cow::Borrowed(&self.wt[..]),
                self.wt32.as_deref().map(Cow::Borrowed),
                Cow::Borrowed(&self.wtw[..]),
                None,
                Some(c),
                Some(&self.whitened),
            ),
            Some(Ok(v)) => {
                let wv = times_lower(&self.w, r, &v);
                // (W V)ᵀ(W V) = Vᵀ (WᵀW) V: O(r³) rather than O(S r²).
                let t = times_lower(&self.wtw, r, &v);
                let wtw = lower_t_times(&v, r, &t);
                // Aᵀt = W c = (W V)(V⁻¹ c): the data term is ‖(W V)ᵀ w − V⁻¹ c‖² + const.
                let tau = lower_solve(r, &v, &c);
                let wvt = transposed(&wv, r);
                let wvt32 = self.wt32.as_ref().map(|_| Cow::Owned(single(&wvt)));
                (
                    Cow::Owned(wv),
                    Cow::Owned(wvt),
                    wvt32,
                    Cow::Owned(wtw),
                    None,
                    Some(tau),
                    None,
                )
            }
            Some(Err(_)) => (
                Cow::Borrowed(&self.w[..]),
                Cow::Borrowed(&self.wt[..]),
                self.wt32.as_deref().map(Cow::Borrowed),
                Cow::Borrowed(&self.wtw[..]),
                k,
                None,
                None,
            ),
        };
        // Wᵀ Aᵀt once per fit: each step's right-hand side differs from Aᵀt only where a
        // weight is above the box (the penalty's pull), so its product with Wᵀ is this plus
        // those few rows.
        let wt_atr = wt_times(&w, r, &atr);
        let sum_free = wtw.to_vec();
        let frame = Frame {
            rank: r,
            shapes: self.shapes,
            tau,
            whitened,
            w,
            wt,
            wt32,
            wtw,
            k,
            tt,
            atr: atr.clone(),
            wt_atr,
            known: Vec::new(),
            clamped: vec![false; self.shapes],
            sum_free,
            factor: None,
        };
        (frame, atr)
    }

    /// W y (S).
    fn w_times(&self, y: &[f64]) -> Vec<f64> {
        columns_times(&self.wt, self.shapes, y)
    }
}
