//! One frame's normal equations in the low-rank form (`W K Wᵀ`, its missing rows folded in):
//! the primal Newton iteration's piece minimisers and line-search products, with `Wᵀ w` of
//! recent iterates remembered so that a step makes no extra pass over the S shapes.

use super::dual::Whitened;
use super::kernels::{add_outer_products, columns_times, mirror_upper, wt_times};
use crate::error::Result;
use crate::linalg::{cholesky, cholesky_solve, Lu};
use std::borrow::Cow;
use std::sync::OnceLock;

/// One frame's normal equations `W K Wᵀ` with the weights clamped by the box so far. The
/// free weights' `Σ w_i w_iᵀ` is kept as the active set changes: by a rank-one update per
/// change, or summed afresh over the free weights when there are fewer of them than changes
/// (a fit of many scans ends with few free, after a first step that clamps many).
pub(in crate::baselines::blendshape) struct Frame<'f> {
    pub(super) rank: usize,
    pub(super) shapes: usize,
    /// τ of the frame's data term as `‖W'ᵀ w − τ‖²` plus a constant (W' = W, or W V with
    /// markers missing), when its `W K Wᵀ` is `W' W'ᵀ`: what [`Frame::dual`] maximises over.
    pub(super) tau: Option<Vec<f64>>,
    /// The matrix's [`Whitened`] rows, for a complete frame.
    pub(super) whitened: Option<&'f OnceLock<Whitened>>,
    /// The frame's W (the matrix's, or W V with markers missing), its transpose and `WᵀW`.
    pub(super) w: Cow<'f, [f64]>,
    pub(super) wt: Cow<'f, [f64]>,
    /// Its transpose in single precision, for a large W (the dual's passes).
    pub(super) wt32: Option<Cow<'f, [f32]>>,
    pub(super) wtw: Cow<'f, [f64]>,
    /// K when it is kept in the general form (not positive definite), else None for I.
    pub(super) k: Option<Vec<f64>>,
    /// ‖t_p‖².
    pub(super) tt: f64,
    /// `Aᵀt` and the frame's `Wᵀ Aᵀt`.
    pub(super) atr: Vec<f64>,
    pub(super) wt_atr: Vec<f64>,
    /// `Wᵀ w` of the last two candidates or iterates (the objective and the line search read
    /// them: an O(S r) pass each, otherwise).
    pub(super) known: Vec<(Vec<f64>, Vec<f64>)>,
    pub(super) clamped: Vec<bool>,
    /// The weights not clamped's `Σ w_i w_iᵀ` (r × r, full).
    pub(super) sum_free: Vec<f64>,
    /// [`Frame::factor`]'s, while the clamped set stands.
    pub(super) factor: Option<Vec<f64>>,
}

impl Frame<'_> {
    /// K v.
    fn k_times(&self, v: &[f64]) -> Vec<f64> {
        let r = self.rank;
        match &self.k {
            None => v.to_vec(),
            Some(k) => k
                .chunks(r)
                .map(|row| row.iter().zip(v).map(|(a, b)| a * b).sum())
                .collect(),
        }
    }

    /// The minimiser of the quadratic piece where `clamped[i]` (ridge `l2`, plus `penalty`
    /// where clamped) for the right-hand side `rhs`.
    pub(in crate::baselines::blendshape) fn piece(
        &mut self,
        clamped: &[bool],
        rhs: &[f64],
        l2: f64,
        penalty: f64,
    ) -> Result<Vec<f64>> {
        let r = self.rank;
        self.set_clamped(clamped);
        let (free, held) = (1.0 / l2, 1.0 / (l2 + penalty));
        let m = match self.k {
            None => Vec::new(),
            Some(_) => self.weighted_gram(free, held),
        };
        // g = Wᵀ D⁻¹ rhs = held Wᵀrhs + (free − held) Σ_free w_i rhs_i, with Wᵀrhs from the
        // fit's Wᵀ Aᵀt and the rows where rhs differs from Aᵀt (those above the box), or
        // summed whole for another right-hand side (a derivative's).
        let differ: Vec<usize> = (0..self.shapes)
            .filter(|&i| rhs[i].to_bits() != self.atr[i].to_bits())
            .collect();
        let wt_rhs = if 4 * differ.len() < self.shapes {
            let mut v = self.wt_atr.clone();
            for &i in &differ {
                let x = rhs[i] - self.atr[i];
                for (o, a) in v.iter_mut().zip(&self.w[i * r..(i + 1) * r]) {
                    *o += a * x;
                }
            }
            v
        } else {
            wt_times(&self.w, r, rhs)
        };
        let mut g: Vec<f64> = wt_rhs.iter().map(|x| x * held).collect();
        for i in (0..self.shapes).filter(|&i| !self.clamped[i]) {
            let x = (free - held) * rhs[i];
            for (o, a) in g.iter_mut().zip(&self.w[i * r..(i + 1) * r]) {
                *o += a * x;
            }
        }
        let y = match &self.k {
            None => cholesky_solve(r, self.factor(free, held)?, &g),
            Some(k) => {
                let mut n = vec![0.0; r * r];
                for i in 0..r {
                    for (l, &kil) in k[i * r..(i + 1) * r].iter().enumerate() {
                        if kil != 0.0 {
                            for j in 0..r {
                                n[i * r + j] += kil * m[l * r + j];
                            }
                        }
                    }
                    n[i * r + i] += 1.0;
                }
                let kg = self.k_times(&g);
                let cols: Vec<[f64; 3]> = kg.iter().map(|&x| [x, 0.0, 0.0]).collect();
                Lu::factor(r, n)?
                    .solve3(&cols)
                    .iter()
                    .map(|c| c[0])
                    .collect()
            }
        };
        let dinv = |i: usize| if self.clamped[i] { held } else { free };
        let wy = columns_times(&self.wt, self.shapes, &y);
        let cand: Vec<f64> = (0..self.shapes)
            .map(|i| dinv(i) * (rhs[i] - wy[i]))
            .collect();
        // Wᵀ cand without another pass over the S shapes: with e = rhs − W y,
        // Wᵀ cand = held (Wᵀrhs − WᵀW y) + (free − held) Σ_free w_i e_i, and free e_i is the
        // free weight itself: held (Wᵀrhs − WᵀW y − l2 Σ_free w_i cand_i) + Σ_free w_i cand_i.
        let mut sum = vec![0.0; r];
        for i in (0..self.shapes).filter(|&i| !self.clamped[i]) {
            for (o, a) in sum.iter_mut().zip(&self.w[i * r..(i + 1) * r]) {
                *o += a * cand[i];
            }
        }
        // Row by row: a frame's `Vᵀ (WᵀW) V` need not be symmetric to the last bit.
        let wtw_y: Vec<f64> = self
            .wtw
            .chunks_exact(r)
            .map(|row| row.iter().zip(&y).map(|(a, b)| a * b).sum())
            .collect();
        let v = (0..r)
            .map(|j| sum[j] + held * (wt_rhs[j] - wtw_y[j] - l2 * sum[j]))
            .collect();
        self.remember(cand.clone(), v);
        Ok(cand)
    }

    /// Makes `clamped` the frame's clamped set, keeping the free weights' `Σ w_i w_iᵀ`.
    pub(super) fn set_clamped(&mut self, clamped: &[bool]) {
        let r = self.rank;
        let changes: Vec<usize> = (0..self.shapes)
            .filter(|&i| clamped[i] != self.clamped[i])
            .collect();
        for &i in &changes {
            self.clamped[i] = clamped[i];
        }
        let now_free = self.clamped.iter().filter(|&&c| !c).count();
        if !changes.is_empty() {
            let row = |i: usize| &self.w[i * r..(i + 1) * r];
            let terms: Vec<(f64, &[f64])> = if now_free <= changes.len() {
                self.sum_free.fill(0.0);
                (0..self.shapes)
                    .filter(|&i| !self.clamped[i])
                    .map(|i| (1.0, row(i)))
                    .collect()
            } else {
                changes
                    .iter()
                    .map(|&i| (if self.clamped[i] { -1.0 } else { 1.0 }, row(i)))
                    .collect()
            };
            add_outer_products(&mut self.sum_free, r, &terms);
            mirror_upper(&mut self.sum_free, r);
            self.factor = None;
        }
    }

    /// The Cholesky factor of `I + Wᵀ D⁻¹ W` for the current clamped set (complete frames and
    /// `W V` frames), made once per set: the dual's last step and the primal step that
    /// confirms it share one.
    pub(super) fn factor(&mut self, free: f64, held: f64) -> Result<&[f64]> {
        if self.factor.is_none() {
            let r = self.rank;
            let mut n = self.weighted_gram(free, held);
            for i in 0..r {
                n[i * r + i] += 1.0;
            }
            self.factor = Some(cholesky(r, n)?);
        }
        Ok(self.factor.as_deref().unwrap_or_default())
    }

    /// `Wᵀ D⁻¹ W = held WᵀW + (free − held) Σ_free w_i w_iᵀ` of the clamped set.
    fn weighted_gram(&self, free: f64, held: f64) -> Vec<f64> {
        self.wtw
            .iter()
            .zip(&self.sum_free)
            .map(|(a, f)| a * held + f * (free - held))
            .collect()
    }

    /// A damped step `to = from + α (cand − from)`: `Wᵀ to` from the two remembered ends
    /// (no pass over the S shapes).
    pub(in crate::baselines::blendshape) fn stepped(
        &mut self,
        from: &[f64],
        cand: &[f64],
        alpha: f64,
        to: &[f64],
    ) {
        let (v, vc) = (self.project(from), self.project(cand));
        let vt = v
            .iter()
            .zip(&vc)
            .map(|(a, c)| a + alpha * (c - a))
            .collect();
        self.remember(to.to_vec(), vt);
    }

    /// Keeps `Wᵀ w` of a recent `w` (the last two).
    fn remember(&mut self, w: Vec<f64>, v: Vec<f64>) {
        self.known.insert(0, (w, v));
        self.known.truncate(2);
    }

    /// `Wᵀ w`, from what was remembered when `w` is a recent candidate or iterate.
    fn project(&mut self, w: &[f64]) -> Vec<f64> {
        if let Some((_, v)) = self.known.iter().find(|(x, _)| x.as_slice() == w) {
            return v.clone();
        }
        let v = wt_times(&self.w, self.rank, w);
        self.remember(w.to_vec(), v.clone());
        v
    }

    /// `(dᵀ G w, dᵀ G d)` for `d = cand − w` with G the frame's `A_pᵀ A_p` (`Wᵀ d` from the
    /// remembered `Wᵀ cand − Wᵀ w`).
    pub(in crate::baselines::blendshape) fn products(
        &mut self,
        cand: &[f64],
        w: &[f64],
        _d: &[f64],
    ) -> (f64, f64) {
        let v = self.project(w);
        let vc = self.project(cand);
        let u: Vec<f64> = vc.iter().zip(&v).map(|(a, b)| a - b).collect();
        let ku = self.k_times(&u);
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        (dot(&ku, &v), dot(&ku, &u))
    }

    /// ‖A_p w − t_p‖² given `atr` = A_pᵀ t_p.
    pub(in crate::baselines::blendshape) fn data_term(&mut self, w: &[f64], atr: &[f64]) -> f64 {
        let v = self.project(w);
        let kv = self.k_times(&v);
        let vkv: f64 = v.iter().zip(&kv).map(|(a, b)| a * b).sum();
        let wa: f64 = w.iter().zip(atr).map(|(a, b)| a * b).sum();
        (vkv - 2.0 * wa + self.tt).max(0.0)
    }
}
