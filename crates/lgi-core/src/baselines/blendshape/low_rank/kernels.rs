//! The small dense kernels of the low-rank path: W's passes over the S shapes (AVX2 builds
//! with the baseline builds' bits), transposes, triangular and Gram products, and rank-one
//! updates of a symmetric matrix made on one triangle and mirrored.

use crate::simd::with_avx2;

with_avx2! {
/// `M y` (n) of a matrix given as its transpose `mt` (row-major, `y.len() × n`): each entry
/// one sum in order from −0.0 over y (the bits of an inner product per row of M, as
/// `Iterator::sum` adds it), taken a column of M at a time: a contiguous pass per value of y
/// that vectorises, faster than the rows' inner products where W stays in cache (a W too
/// large for it waits on memory either way: [`columns_times_single`]).
pub(super) fn columns_times(mt: &[f64], n: usize, y: &[f64]) -> Vec<f64> {
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
pub(super) fn columns_times_single(mt: &[f32], n: usize, y: &[f64]) -> Vec<f64> {
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
pub(super) fn single(m: &[f64]) -> Vec<f32> {
    m.iter().map(|&x| x as f32).collect()
}

/// The transpose (`r × n`) of a row-major `n × r` matrix.
pub(super) fn transposed(m: &[f64], r: usize) -> Vec<f64> {
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
pub(super) fn wt_times(w: &[f64], r: usize, v: &[f64]) -> Vec<f64> {
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
pub(super) fn lower_t_times(v: &[f64], r: usize, t: &[f64]) -> Vec<f64> {
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
pub(super) fn times_lower(w: &[f64], r: usize, v: &[f64]) -> Vec<f64> {
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
pub(super) fn add_outer_products(m: &mut [f64], r: usize, terms: &[(f64, &[f64])]) {
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
pub(super) fn mirror_upper(m: &mut [f64], r: usize) {
    for a in 0..r {
        for b in a + 1..r {
            m[b * r + a] = m[a * r + b];
        }
    }
}

/// `MᵀM` of a row-major `n × r` matrix.
pub(super) fn gram_of(m: &[f64], n: usize, r: usize) -> Vec<f64> {
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
