//! The blendshape fit's normal equations in the span of the matrix's rows. A dataset whose
//! shapes are combinations of fewer ones (in-betweens and pair sums of an augmented dataset:
//! ICT-300's 300 shapes span 55 directions at 120 markers) has `AᵀA` of low rank r, so every
//! Newton step's `(AᵀA + D) w = b`, D diagonal (the ridge plus the box penalty), is solved by
//! the Woodbury identity in r dimensions instead of S: O(S r + r³) per step, not O(S³).
//!
//! With `Aᵀ = W X` (W: S × r, X: r × R with orthonormal rows), a frame whose rows `m` are
//! missing has `A_pᵀ A_p = W K Wᵀ`, `K = I − X_m X_mᵀ`, and `(D + W K Wᵀ) w = b` is
//! `w = D⁻¹ (b − W y)` with `(I + K Wᵀ D⁻¹ W) y = K Wᵀ D⁻¹ b`.

use crate::error::Result;
use crate::linalg::{cholesky, cholesky_solve, lower_solve, lower_t_solve, Lu};
use crate::simd::with_avx2;
use std::borrow::Cow;
use std::sync::OnceLock;

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

/// `B = I + held WᵀW` (the Newton matrix of the dual with every weight held) as its Cholesky
/// factor L, and every weight's row whitened by it, `z_i = L⁻¹ w_i` (S × r): then
/// `w_iᵀ B⁻¹ w_j = z_iᵀ z_j`, what [`Frame::solve_few_free`] needs. The complete frames' is
/// made once per matrix; a frame with markers missing whitens its rows as they are needed.
#[derive(Debug, Clone)]
struct Whitened {
    l: Vec<f64>,
    z: Vec<f64>,
}

/// The Cholesky factor of `I + held WᵀW`.
fn held_factor(wtw: &[f64], r: usize, held: f64) -> Result<Vec<f64>> {
    let mut b: Vec<f64> = wtw.iter().map(|x| x * held).collect();
    for i in 0..r {
        b[i * r + i] += 1.0;
    }
    cholesky(r, b)
}

impl LowRank {
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

with_avx2! {
/// `M y` (n) of a matrix given as its transpose `mt` (row-major, `y.len() × n`): each entry
/// one sum in order from −0.0 over y (the bits of an inner product per row of M, as
/// `Iterator::sum` adds it), taken a column of M at a time: a contiguous pass per value of y
/// that vectorises: twice as fast as the rows' inner products where W stays in cache (2,000
/// scans at rank 135, alone: 56 µs against 115 µs); in a solve a W that large waits on memory
/// either way ([`columns_times_single`]).
fn columns_times(mt: &[f64], n: usize, y: &[f64]) -> Vec<f64> {
    let mut out = vec![-0.0; n];
    for (column, &yj) in mt.chunks_exact(n.max(1)).zip(y) {
        for (o, a) in out.iter_mut().zip(column) {
            *o += a * yj;
        }
    }
    out
}
}

with_avx2! {
/// [`columns_times`] of a transpose kept in single precision: half the bytes of a pass that
/// is bound by memory (2,000 scans at rank 135: 2.2 MB in double precision, more than a
/// core's 2 MiB L2), each product widened to double and summed as there.
fn columns_times_single(mt: &[f32], n: usize, y: &[f64]) -> Vec<f64> {
    let mut out = vec![-0.0; n];
    for (column, &yj) in mt.chunks_exact(n.max(1)).zip(y) {
        for (o, a) in out.iter_mut().zip(column) {
            *o += f64::from(*a) * yj;
        }
    }
    out
}
}

/// `m` rounded to single precision.
fn single(m: &[f64]) -> Vec<f32> {
    m.iter().map(|&x| x as f32).collect()
}

/// The transpose (`r × n`) of a row-major `n × r` matrix.
fn transposed(m: &[f64], r: usize) -> Vec<f64> {
    let n = m.len() / r.max(1);
    let mut t = vec![0.0; m.len()];
    for (i, row) in m.chunks_exact(r.max(1)).enumerate() {
        for (j, &x) in row.iter().enumerate() {
            t[j * n + i] = x;
        }
    }
    t
}

/// `Wᵀ v` (r) of a row-major `S × r` matrix `w`.
fn wt_times(w: &[f64], r: usize, v: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; r];
    for (row, &x) in w.chunks(r).zip(v) {
        if x != 0.0 {
            for (o, a) in out.iter_mut().zip(row) {
                *o += a * x;
            }
        }
    }
    out
}

/// `Vᵀ T` of a lower-triangular `r × r` matrix `v` and a row-major `r × r` matrix `t`.
fn lower_t_times(v: &[f64], r: usize, t: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; r * r];
    // Row j of Vᵀ T is Σ_{l ≥ j} v[l][j] · row l of T.
    for l in 0..r {
        let t_row = &t[l * r..(l + 1) * r];
        for j in 0..=l {
            let x = v[l * r + j];
            if x != 0.0 {
                for (o, &y) in out[j * r..(j + 1) * r].iter_mut().zip(t_row) {
                    *o += x * y;
                }
            }
        }
    }
    out
}

/// `W V` of a row-major `S × r` matrix `w` and a lower-triangular `r × r` matrix `v`.
fn times_lower(w: &[f64], r: usize, v: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; w.len()];
    for (row, o) in w.chunks(r).zip(out.chunks_mut(r)) {
        for (l, &x) in row.iter().enumerate() {
            if x != 0.0 {
                for (oj, vj) in o[..=l].iter_mut().zip(&v[l * r..l * r + l + 1]) {
                    *oj += x * vj;
                }
            }
        }
    }
    out
}

with_avx2! {
/// `m += Σ_k sign_k x_k x_kᵀ` on and above the diagonal of the row-major `r × r` matrix `m`
/// (`terms`: each `(sign_k, x_k)`, sign ±1), each entry updated by the terms in order as
/// `+= (sign_k x_k[a]) x_k[b]`: the bits of one rank-one update after another. The entry
/// below, `(sign x_b) x_a`, has the same bits (± and the product commute exactly), so
/// [`mirror_upper`] completes the full update at half the cost; entries below the diagonal
/// in the diagonal's tiles are changed too and must be mirrored over.
///
/// Taken a 4 × 4 tile of `m` at a time over 32 terms, the tile held in registers: one rank-one
/// update at a time reads and writes the whole matrix per term (a fit of 2,000 scans makes
/// hundreds of them at rank 135 a frame), bound by the cache, not the arithmetic.
fn add_outer_products(m: &mut [f64], r: usize, terms: &[(f64, &[f64])]) {
    const TILE: usize = 4;
    const CHUNK: usize = 32;
    for chunk in terms.chunks(CHUNK) {
        for a0 in (0..r).step_by(TILE) {
            let a1 = (a0 + TILE).min(r);
            for b0 in (a0..r).step_by(TILE) {
                let b1 = (b0 + TILE).min(r);
                if a1 - a0 < TILE || b1 - b0 < TILE {
                    for a in a0..a1 {
                        for b in b0.max(a)..b1 {
                            // Summed in a local: the terms' rows could alias `m` as far as
                            // the compiler knows, which would store the entry every term.
                            let mut e = m[a * r + b];
                            for &(sign, x) in chunk {
                                e += (sign * x[a]) * x[b];
                            }
                            m[a * r + b] = e;
                        }
                    }
                    continue;
                }
                // Fixed-size arrays: the tile's loops unroll and it stays in registers.
                let tile_of = |v: &[f64]| -> [f64; TILE] { std::array::from_fn(|q| v[q]) };
                let mut acc: [[f64; TILE]; TILE] =
                    std::array::from_fn(|p| tile_of(&m[(a0 + p) * r + b0..]));
                for &(sign, x) in chunk {
                    let (xa, xb) = (tile_of(&x[a0..]), tile_of(&x[b0..]));
                    for p in 0..TILE {
                        let t = sign * xa[p];
                        for q in 0..TILE {
                            acc[p][q] += t * xb[q];
                        }
                    }
                }
                for (p, row) in acc.iter().enumerate() {
                    m[(a0 + p) * r + b0..(a0 + p) * r + b1].copy_from_slice(row);
                }
            }
        }
    }
}
}

/// Copies the entries above the diagonal of the row-major `r × r` matrix `m` below it.
fn mirror_upper(m: &mut [f64], r: usize) {
    for a in 0..r {
        for b in a + 1..r {
            m[b * r + a] = m[a * r + b];
        }
    }
}

/// `MᵀM` of a row-major `n × r` matrix.
fn gram_of(m: &[f64], n: usize, r: usize) -> Vec<f64> {
    let mut g = vec![0.0; r * r];
    for row in m.chunks(r).take(n) {
        for i in 0..r {
            for j in 0..=i {
                g[i * r + j] += row[i] * row[j];
            }
        }
    }
    for i in 0..r {
        for j in 0..i {
            g[j * r + i] = g[i * r + j];
        }
    }
    g
}

/// Where [`Frame::dual`] ended: the weights on the minimum's pieces, the steps taken, and the
/// dual point (r values, the frame's coordinates), where a fit of a nearby target of the same
/// frame can start ([`DualStart::Point`]).
pub(super) struct DualEnd {
    pub(super) weights: Vec<f64>,
    pub(super) steps: usize,
    pub(super) point: Vec<f64>,
}

/// What [`Frame::solve_few_free`] keeps between a dual's steps of a frame with markers
/// missing: the Cholesky factor of `I + held WᵀW` and the whitened row `L⁻¹ w_i` of each
/// weight that has been in the box (empty until then).
#[derive(Default)]
struct SmallFree {
    l: Vec<f64>,
    z: Vec<Vec<f64>>,
}

/// Where [`Frame::dual`] starts.
#[derive(Debug, Clone, Copy)]
pub(super) enum DualStart<'a> {
    /// At 0: every weight at 0.
    Zero,
    /// At a dual point of the same frame's fit of a nearby target ([`DualEnd::point`]: the
    /// same markers missing, so the same coordinates); from 0 if it is not r finite values.
    Point(&'a [f64]),
    /// At the dual point nearest these weights (S).
    Weights(&'a [f64]),
}

/// One frame's normal equations `W K Wᵀ` with the weights clamped by the box so far. The
/// free weights' `Σ w_i w_iᵀ` is kept as the active set changes: by a rank-one update per
/// change, or summed afresh over the free weights when there are fewer of them than changes
/// (a fit of 2,000 scans ends with ~15 free, after a first step that clamps ~1,000).
pub(super) struct Frame<'f> {
    rank: usize,
    shapes: usize,
    /// τ of the frame's data term as `‖W'ᵀ w − τ‖²` plus a constant (W' = W, or W V with
    /// markers missing), when its `W K Wᵀ` is `W' W'ᵀ`: what [`Frame::dual`] maximises over.
    tau: Option<Vec<f64>>,
    /// The matrix's [`Whitened`] rows, for a complete frame.
    whitened: Option<&'f OnceLock<Whitened>>,
    /// The frame's W (the matrix's, or W V with markers missing), its transpose and `WᵀW`.
    w: Cow<'f, [f64]>,
    wt: Cow<'f, [f64]>,
    /// Its transpose in single precision, for a large W (the dual's passes).
    wt32: Option<Cow<'f, [f32]>>,
    wtw: Cow<'f, [f64]>,
    /// K when it is kept in the general form (not positive definite), else None for I.
    k: Option<Vec<f64>>,
    /// ‖t_p‖².
    tt: f64,
    /// `Aᵀt` and the frame's `Wᵀ Aᵀt`.
    atr: Vec<f64>,
    wt_atr: Vec<f64>,
    /// `Wᵀ w` of the last two candidates or iterates (the objective and the line search read
    /// them: an O(S r) pass each, otherwise).
    known: Vec<(Vec<f64>, Vec<f64>)>,
    clamped: Vec<bool>,
    /// The weights not clamped's `Σ w_i w_iᵀ` (r × r, full).
    sum_free: Vec<f64>,
    /// [`Frame::factor`]'s, while the clamped set stands.
    factor: Option<Vec<f64>>,
}

impl Frame<'_> {
    /// `W' v` (S) for the dual's steps: from the single-precision transpose where W' has one.
    fn dual_pass(&self, v: &[f64]) -> Vec<f64> {
        match &self.wt32 {
            Some(single) => columns_times_single(single, self.shapes, v),
            None => columns_times(&self.wt, self.shapes, v),
        }
    }

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
    pub(super) fn piece(
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
    fn set_clamped(&mut self, clamped: &[bool]) {
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
    fn factor(&mut self, free: f64, held: f64) -> Result<&[f64]> {
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

    /// Where the dual of the fit is maximised, from `start` ([`DualStart`]): the
    /// weights there (the start at which the primal iteration ends in one step), the steps
    /// taken and the dual point. `None` when the frame has no dual form, or the dual stalls or
    /// runs past `max_steps` (the primal iteration then starts as it would without it).
    ///
    /// The dual of `min ‖W'ᵀw − τ‖² + Σ g(w_i)` (g the ridge and box penalty) is the concave,
    /// C¹, piecewise quadratic `D(η) = −‖η‖²/4 − ηᵀτ − Σ g*(−(W'η)_i)` over r values, and each
    /// weight is a piecewise linear function of `u = W'η`: `w_i = (−u_i)/(2 l2)` in the box,
    /// `(−u_i)/(2 (l2 + penalty))` below it and that plus `penalty/(l2 + penalty)` above. Its
    /// Newton step is the primal step's r × r system; a damped step moves every weight along
    /// its own piecewise linear path (many weights change piece in one step, where the primal
    /// line search stops at the first change that turns the slope): a cold fit of 2,000 scans
    /// in ~20 steps instead of ~47.
    pub(super) fn dual(
        &mut self,
        start: DualStart<'_>,
        l2: f64,
        penalty: f64,
        max_steps: usize,
    ) -> Result<Option<DualEnd>> {
        let Some(tau) = self.tau.clone() else {
            return Ok(None);
        };
        let (r, s) = (self.rank, self.shapes);
        let (free, held) = (1.0 / l2, 1.0 / (l2 + penalty));
        let kappa = penalty / (l2 + penalty);
        let top = 2.0 * l2;
        // A weight's piece (0 below the box, 1 in it, 2 above) at `v = −u_i` moving by `dv`.
        let side = |v: f64, dv: f64| -> u8 {
            if v < 0.0 || (v == 0.0 && dv < 0.0) {
                0
            } else if v > top || (v == top && dv > 0.0) {
                2
            } else {
                1
            }
        };
        // The weight on piece p is `slope(p) (−u) + offset(p)`.
        let slope = |p: u8| if p == 1 { 0.5 * free } else { 0.5 * held };
        let offset = |p: u8| if p == 2 { kappa } else { 0.0 };
        // From 0 (every weight free at 0) the first step's end is the unconstrained fit's
        // dual point, taken whole: a step fewer than searching the line to it.
        let cold = matches!(start, DualStart::Zero);
        let mut eta = match start {
            DualStart::Zero => vec![0.0; r],
            DualStart::Point(p) if p.len() == r && p.iter().all(|x| x.is_finite()) => p.to_vec(),
            DualStart::Point(_) => vec![0.0; r],
            DualStart::Weights(w) => self.dual_point_of_weights(w, l2, penalty)?,
        };
        // At 0, `W'η` is 0 without a pass over the shapes.
        let mut u = if cold {
            vec![0.0; s]
        } else {
            self.dual_pass(&eta)
        };
        let mut pieces: Vec<u8> = u.iter().map(|&x| side(-x, 0.0)).collect();
        // With few weights in the box the Newton matrix is `B + (free − held) F Fᵀ`, B =
        // I + held WᵀW the same for every step and F the free weights' rows: solved through
        // B's factor and the free weights' own small system (Woodbury) instead of factoring
        // r × r on every step. `B⁻¹ w_i` of each weight is made when it is first free.
        let mut small = SmallFree::default();
        for step in 1..=max_steps {
            // The piece's maximiser: (I + Wᵀ D⁻¹ W) η / 2 = κ Σ_above w_i − τ.
            let mut rhs: Vec<f64> = tau.iter().map(|t| -t).collect();
            for i in (0..s).filter(|&i| pieces[i] == 2) {
                for (o, a) in rhs.iter_mut().zip(&self.w[i * r..(i + 1) * r]) {
                    *o += kappa * a;
                }
            }
            let in_box: Vec<usize> = (0..s).filter(|&i| pieces[i] == 1).collect();
            // Woodbury costs ~n² r / 2 + n³ / 6 for n free against r³ / 6 (and the free sum's
            // updates): it pays below n ≈ r / √3.
            let solved = if 3 * in_box.len() * in_box.len() < r * r {
                self.solve_few_free(&in_box, &rhs, held, free - held, &mut small)?
            } else {
                let clamped: Vec<bool> = pieces.iter().map(|&p| p != 1).collect();
                self.set_clamped(&clamped);
                cholesky_solve(r, self.factor(free, held)?, &rhs)
            };
            let target: Vec<f64> = solved.iter().map(|x| 2.0 * x).collect();
            let d: Vec<f64> = target.iter().zip(&eta).map(|(a, b)| a - b).collect();
            let du = self.dual_pass(&d);
            if (0..s).all(|i| side(-(u[i] + du[i]), 0.0) == pieces[i]) {
                let w = (0..s)
                    .map(|i| {
                        let p = pieces[i];
                        slope(p) * -(u[i] + du[i]) + offset(p)
                    })
                    .collect();
                return Ok(Some(DualEnd {
                    weights: w,
                    steps: step,
                    point: target,
                }));
            }
            // Exact line search: the slope of D along d is piecewise linear and decreasing,
            // c0 + s0 − α (‖d‖²/2 + s1), with s0 and s1 summed over the weights' pieces and
            // changing where a weight crosses 0 or 1.
            let dd: f64 = d.iter().map(|x| x * x).sum();
            let c0: f64 = (0..r).map(|j| d[j] * (-0.5 * eta[j] - tau[j])).sum();
            let (mut s0, mut s1) = (0.0, 0.0);
            let mut breaks: Vec<(f64, u32)> = Vec::new();
            let mut along = vec![0u8; s];
            for i in 0..s {
                let (v, dv) = (-u[i], -du[i]);
                let p = side(v, dv);
                along[i] = p;
                s0 += du[i] * (-slope(p) * u[i] + offset(p));
                s1 += slope(p) * du[i] * du[i];
                if dv != 0.0 {
                    for edge in [0.0, top] {
                        let a = (edge - v) / dv;
                        if a > 0.0 && a < 1.0 {
                            breaks.push((a, i as u32));
                        }
                    }
                }
            }
            breaks.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
            let mut alpha = 1.0;
            let mut found = false;
            for &(at, i) in &breaks {
                if c0 + s0 - at * (0.5 * dd + s1) <= 0.0 {
                    found = true;
                    break;
                }
                let i = i as usize;
                let old = along[i];
                let new = if du[i] < 0.0 { old + 1 } else { old - 1 };
                s0 += du[i] * (-(slope(new) - slope(old)) * u[i] + offset(new) - offset(old));
                s1 += (slope(new) - slope(old)) * du[i] * du[i];
                along[i] = new;
            }
            if (found || c0 + s0 - (0.5 * dd + s1) <= 0.0) && !(cold && step == 1) {
                alpha = ((c0 + s0) / (0.5 * dd + s1)).min(1.0);
            }
            if alpha.is_nan() || alpha <= 0.0 {
                return Ok(None);
            }
            for (e, x) in eta.iter_mut().zip(&d) {
                *e += alpha * x;
            }
            for (ui, x) in u.iter_mut().zip(&du) {
                *ui += alpha * x;
            }
            for (p, &x) in pieces.iter_mut().zip(&u) {
                *p = side(-x, 0.0);
            }
        }
        Ok(None)
    }

    /// `(B + c Σ_{i ∈ in_box} w_i w_iᵀ)⁻¹ rhs` with `B = I + held WᵀW`, by the Woodbury
    /// identity over the weights `in_box` in B's whitened coordinates ([`Whitened`]):
    /// `(I/c + Zᵀ Z) y = Zᵀ L⁻¹ rhs`, then `x = L⁻ᵀ (L⁻¹ rhs − Z y)` ([`Frame::dual`]).
    fn solve_few_free(
        &self,
        in_box: &[usize],
        rhs: &[f64],
        held: f64,
        c: f64,
        small: &mut SmallFree,
    ) -> Result<Vec<f64>> {
        let r = self.rank;
        let row = |i: usize| &self.w[i * r..(i + 1) * r];
        let whole = match self.whitened {
            Some(cell) => {
                if cell.get().is_none() {
                    let l = held_factor(&self.wtw, r, held)?;
                    let mut z = vec![0.0; self.w.len()];
                    for i in 0..self.shapes {
                        z[i * r..(i + 1) * r].copy_from_slice(&lower_solve(r, &l, row(i)));
                    }
                    let _ = cell.set(Whitened { l, z });
                }
                cell.get()
            }
            None => None,
        };
        if whole.is_none() && small.l.is_empty() {
            small.l = held_factor(&self.wtw, r, held)?;
            small.z = vec![Vec::new(); self.shapes];
        }
        let l = whole.map_or(small.l.as_slice(), |w| w.l.as_slice());
        if whole.is_none() {
            for &i in in_box {
                if small.z[i].is_empty() {
                    small.z[i] = lower_solve(r, l, row(i));
                }
            }
        }
        let z = |i: usize| -> &[f64] {
            match whole {
                Some(w) => &w.z[i * r..(i + 1) * r],
                None => &small.z[i],
            }
        };
        let mut x = lower_solve(r, l, rhs);
        let n = in_box.len();
        if n > 0 {
            let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(p, q)| p * q).sum::<f64>();
            let mut m = vec![0.0; n * n];
            for (a, &i) in in_box.iter().enumerate() {
                for (b, &j) in in_box.iter().enumerate().skip(a) {
                    let v = dot(z(i), z(j));
                    m[a * n + b] = v;
                    m[b * n + a] = v;
                }
                m[a * n + a] += 1.0 / c;
            }
            let g: Vec<f64> = in_box.iter().map(|&i| dot(z(i), &x)).collect();
            let y = cholesky_solve(n, &cholesky(n, m)?, &g);
            for (&i, yi) in in_box.iter().zip(&y) {
                for (o, p) in x.iter_mut().zip(z(i)) {
                    *o -= yi * p;
                }
            }
        }
        Ok(lower_t_solve(r, l, &x))
    }

    /// The frame's dual point nearest to weights `w` (S): each weight's `u_i` on its piece
    /// (`w_i = −u_i/(2 l2)` in the box, `−u_i/(2 (l2 + penalty))` below it, that plus
    /// `penalty/(l2 + penalty)` above), and η the least-squares fit of `W'η = u`, ridged by
    /// `l2`. At a fit's own minimum it is that fit's dual point.
    fn dual_point_of_weights(&self, w: &[f64], l2: f64, penalty: f64) -> Result<Vec<f64>> {
        let r = self.rank;
        let u: Vec<f64> = w
            .iter()
            .map(|&x| {
                if x < 0.0 {
                    -2.0 * (l2 + penalty) * x
                } else if x <= 1.0 {
                    -2.0 * l2 * x
                } else {
                    2.0 * penalty - 2.0 * (l2 + penalty) * x
                }
            })
            .collect();
        let mut g = self.wtw.to_vec();
        for i in 0..r {
            g[i * r + i] += l2;
        }
        Ok(cholesky_solve(
            r,
            &cholesky(r, g)?,
            &wt_times(&self.w, r, &u),
        ))
    }

    /// A damped step `to = from + α (cand − from)`: `Wᵀ to` from the two remembered ends
    /// (no pass over the S shapes).
    pub(super) fn stepped(&mut self, from: &[f64], cand: &[f64], alpha: f64, to: &[f64]) {
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
    pub(super) fn products(&mut self, cand: &[f64], w: &[f64], _d: &[f64]) -> (f64, f64) {
        let v = self.project(w);
        let vc = self.project(cand);
        let u: Vec<f64> = vc.iter().zip(&v).map(|(a, b)| a - b).collect();
        let ku = self.k_times(&u);
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        (dot(&ku, &v), dot(&ku, &u))
    }

    /// ‖A_p w − t_p‖² given `atr` = A_pᵀ t_p.
    pub(super) fn data_term(&mut self, w: &[f64], atr: &[f64]) -> f64 {
        let v = self.project(w);
        let kv = self.k_times(&v);
        let vkv: f64 = v.iter().zip(&kv).map(|(a, b)| a * b).sum();
        let wa: f64 = w.iter().zip(atr).map(|(a, b)| a * b).sum();
        (vkv - 2.0 * wa + self.tt).max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{mixes, rnd};
    use super::*;
    use proptest::prelude::*;

    /// [`LowRank::new`] from a whole Gram matrix (S × S).
    fn from_gram(
        a: &[f64],
        rows: usize,
        shapes: usize,
        gram: &[f64],
        l2: f64,
    ) -> Result<Option<LowRank>> {
        let diag: Vec<f64> = (0..shapes).map(|i| gram[i * shapes + i]).collect();
        let column = |p: usize| (0..shapes).map(|i| gram[i * shapes + p]).collect();
        LowRank::new(a, rows, shapes, &diag, column, l2)
    }

    /// The Woodbury solve over a few free weights equals the r × r system it stands for,
    /// `(I + held WᵀW + c Σ_free w_i w_iᵀ) x = rhs`, on a complete frame (rows whitened once
    /// for the matrix) and on one with rows missing (whitened as needed), twice each (the
    /// second time from what the first kept).
    #[test]
    fn the_few_free_solve_equals_the_whole_system() {
        let (rows, shapes) = (40, 60);
        let mut seed = 9u64;
        // 60 shapes mixing 12: rank 12 < 30, the low-rank form.
        let a = mixes(rows, 12, shapes, 0.0, &mut seed);
        let mut rnd = || rnd(&mut seed);
        let lr = from_gram(&a, rows, shapes, &gram_of(&a, rows, shapes), 1e-3)
            .unwrap()
            .unwrap();
        let r = lr.rank();
        assert_eq!(r, 12);
        let (held, c) = (0.05, 900.0);
        let mut t: Vec<f64> = (0..rows).map(|_| rnd()).collect();
        for missing in [vec![], vec![0, 13, 27]] {
            for &m in &missing {
                t[m] = f64::NAN;
            }
            let (frame, _) = lr.frame(&t);
            let mut small = SmallFree::default();
            for in_box in [vec![3usize, 17, 40, 41], vec![3, 8, 17, 59]] {
                let rhs: Vec<f64> = (0..r).map(|_| rnd()).collect();
                let got = frame
                    .solve_few_free(&in_box, &rhs, held, c, &mut small)
                    .unwrap();
                let mut n: Vec<f64> = frame.wtw.iter().map(|x| x * held).collect();
                for i in 0..r {
                    n[i * r + i] += 1.0;
                }
                for &k in &in_box {
                    let w = &frame.w[k * r..(k + 1) * r];
                    for i in 0..r {
                        for j in 0..r {
                            n[i * r + j] += c * w[i] * w[j];
                        }
                    }
                }
                let want = cholesky_solve(r, &cholesky(r, n).unwrap(), &rhs);
                for (g, w) in got.iter().zip(&want) {
                    assert!(
                        (g - w).abs() < 1e-9 * (1.0 + w.abs()),
                        "{missing:?}: {g} vs {w}"
                    );
                }
            }
        }
    }

    /// The dual's end, for a matrix of 200 positive mixes of 5 shapes over 24 rows, complete
    /// and with rows missing: weights on the pieces of the minimum, so the primal step on
    /// their piece lands on them (the one step the solver then takes), within 1e-9 of the
    /// dense normal equations' solution on that piece (1e-5 with the dual's passes in single
    /// precision, as a large W takes them), and that step's weights within 1e-9 either way.
    #[test]
    fn the_dual_ends_on_the_minimums_pieces_with_passes_in_double_or_single_precision() {
        let (rows, base, shapes) = (24, 5, 200);
        let mut seed = 5u64;
        let a = mixes(rows, base, shapes, 0.5, &mut seed);
        let mut rnd = || rnd(&mut seed);
        let gram = gram_of(&a, rows, shapes);
        let (l2, penalty) = (1e-3, 10.0);
        let double = from_gram(&a, rows, shapes, &gram, l2).unwrap().unwrap();
        assert!(
            double.wt32.is_none(),
            "a small W keeps its passes in double precision"
        );
        let single = double.clone().with_single_passes();
        let t: Vec<f64> = (0..rows).map(|_| 3.0 * rnd()).collect();
        let cases = [vec![], vec![1, 2, 20]]
            .into_iter()
            .flat_map(|m| [(m.clone(), &double), (m, &single)]);
        for (missing, lr) in cases {
            // The dual's own weights carry its passes' rounding; the piece's solve does not.
            let dual_tolerance = if lr.wt32.is_some() { 1e-5 } else { 1e-9 };
            let mut t = t.clone();
            for &m in &missing {
                t[m] = f64::NAN;
            }
            let (mut frame, atr) = lr.frame(&t);
            let end = frame
                .dual(DualStart::Zero, l2, penalty, 100)
                .unwrap()
                .unwrap();
            let (w, steps) = (end.weights, end.steps);
            assert!(steps >= 2, "{missing:?}: {steps} steps");
            let clamped: Vec<bool> = w.iter().map(|x| !(0.0..=1.0).contains(x)).collect();
            assert!(clamped.iter().filter(|&&c| c).count() > shapes / 2);
            let mut rhs = atr.clone();
            for (r, x) in rhs.iter_mut().zip(&w) {
                if *x > 1.0 {
                    *r += penalty;
                }
            }
            let cand = frame.piece(&clamped, &rhs, l2, penalty).unwrap();
            // The dense normal equations on that piece over the present rows.
            let mut m = vec![0.0; shapes * shapes];
            for r in (0..rows).filter(|&r| !t[r].is_nan()) {
                let row = &a[r * shapes..(r + 1) * shapes];
                for i in 0..shapes {
                    for j in 0..shapes {
                        m[i * shapes + j] += row[i] * row[j];
                    }
                }
            }
            for i in 0..shapes {
                m[i * shapes + i] += l2 + if clamped[i] { penalty } else { 0.0 };
            }
            let dense = cholesky_solve(shapes, &cholesky(shapes, m).unwrap(), &rhs);
            for ((x, c), d) in w.iter().zip(&cand).zip(&dense) {
                assert_eq!(!(0.0..=1.0).contains(c), !(0.0..=1.0).contains(x));
                assert!(
                    (x - d).abs() < dual_tolerance && (c - d).abs() < 1e-9,
                    "{x} {c} {d}"
                );
            }
        }
    }

    /// The fit's kernels give the same bits from their AVX2 builds as from the baseline ones
    /// (no multiply-add fusion either way), on sizes with and without a vector remainder.
    #[test]
    fn the_fits_kernels_take_the_same_bits_with_or_without_avx2() {
        let mut seed = 11u64;
        for (n, r) in [(2000, 135), (301, 55), (7, 3)] {
            let m: Vec<f64> = (0..n * r).map(|_| rnd(&mut seed)).collect();
            let y: Vec<f64> = (0..r).map(|_| rnd(&mut seed)).collect();
            let single_m = single(&m);
            let bits = |v: Vec<f64>| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            let (fast, baseline) = crate::simd::both_builds(|| bits(columns_times(&m, n, &y)));
            assert_eq!(fast, baseline);
            let (fast, baseline) =
                crate::simd::both_builds(|| bits(columns_times_single(&single_m, n, &y)));
            assert_eq!(fast, baseline);
            let terms: Vec<(f64, &[f64])> = m
                .chunks_exact(r)
                .take(70)
                .enumerate()
                .map(|(i, x)| (if i % 3 == 0 { -1.0 } else { 1.0 }, x))
                .collect();
            let (fast, baseline) = crate::simd::both_builds(|| {
                let mut sum = vec![0.5; r * r];
                add_outer_products(&mut sum, r, &terms);
                bits(sum)
            });
            assert_eq!(fast, baseline);
        }
    }

    proptest! {
        /// Rank-one updates made on and above the diagonal and then mirrored equal the same
        /// updates made on every entry, bit for bit (what the frame's K and clamped sum rely on).
        #[test]
        fn upper_updates_mirrored_equal_full_updates_bit_for_bit(
            r in 1usize..40,
            updates in proptest::collection::vec((proptest::bool::ANY, proptest::collection::vec(-3.0f64..3.0, 40)), 1..80),
        ) {
            let mut full = vec![0.0f64; r * r];
            for i in 0..r {
                full[i * r + i] = 1.0;
            }
            let mut upper = full.clone();
            for (plus, x) in &updates {
                let sign = if *plus { 1.0 } else { -1.0 };
                let x = &x[..r];
                for a in 0..r {
                    for b in 0..r {
                        full[a * r + b] += sign * x[a] * x[b];
                    }
                }
            }
            let terms: Vec<(f64, &[f64])> = updates
                .iter()
                .map(|(plus, x)| (if *plus { 1.0 } else { -1.0 }, &x[..r]))
                .collect();
            add_outer_products(&mut upper, r, &terms);
            let bits = |m: &[f64]| m.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            mirror_upper(&mut upper, r);
            prop_assert_eq!(bits(&upper), bits(&full));
        }
    }
}
