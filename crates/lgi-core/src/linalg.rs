//! Dense LU factorisation with partial pivoting for the small B×B systems of the residual pass
//! (B = number of bundles, ~100–300), and the Cholesky factorisation of the blendshape fit's
//! normal equations. glam has no general solver and nalgebra would be a heavy dependency for
//! two routines.

use crate::error::{LgiError, Result};
use crate::simd::with_avx2;

/// LU factors of a square row-major matrix, `P A = L U`.
#[derive(Debug, Clone)]
pub struct Lu {
    n: usize,
    lu: Vec<f64>,
    perm: Vec<usize>,
}

with_avx2! {
/// One step of [`Lu::factor`]'s elimination: every row below row `k` of the `n × n` row-major
/// `a` less its multiple `f = a[r][k] / a[k][k]` of row `k` (columns after `k`), `f` kept in
/// its place; each entry the one product and difference it always was, on either build.
fn eliminate_below(a: &mut [f64], n: usize, k: usize) {
    let (top, below) = a.split_at_mut((k + 1) * n);
    let pivot = &top[k * n..(k + 1) * n];
    for row in below.chunks_exact_mut(n) {
        let f = row[k] / pivot[k];
        row[k] = f;
        if f != 0.0 {
            for (x, p) in row[k + 1..].iter_mut().zip(&pivot[k + 1..]) {
                *x -= f * p;
            }
        }
    }
}
}

impl Lu {
    /// Factorises the `n × n` row-major matrix `a`. A pivot below `1e-12 ×` the largest entry
    /// makes the matrix singular for our purposes and returns `LgiError::Input` naming the row.
    pub fn factor(n: usize, mut a: Vec<f64>) -> Result<Lu> {
        if a.len() != n * n {
            return Err(LgiError::Input(format!(
                "matrix of {} values is not {n}×{n}",
                a.len()
            )));
        }
        let scale = a
            .iter()
            .fold(0.0f64, |m, x| m.max(x.abs()))
            .max(f64::MIN_POSITIVE);
        let mut perm: Vec<usize> = (0..n).collect();
        for k in 0..n {
            let (p, pv) = (k..n)
                .map(|r| (r, a[r * n + k].abs()))
                .fold((k, -1.0), |best, x| if x.1 > best.1 { x } else { best });
            if pv <= 1e-12 * scale {
                return Err(LgiError::Input(format!(
                    "singular system at row {k} (bundles too close together or coincident?)"
                )));
            }
            if p != k {
                for c in 0..n {
                    a.swap(k * n + c, p * n + c);
                }
                perm.swap(k, p);
            }
            eliminate_below(&mut a, n, k);
        }
        Ok(Lu { n, lu: a, perm })
    }

    /// Solves `A x = b` for `b` given as `n` columns of 3-vectors stored as `[f64; 3]` rows.
    pub fn solve3(&self, b: &[[f64; 3]]) -> Vec<[f64; 3]> {
        let n = self.n;
        let mut x: Vec<[f64; 3]> = self.perm.iter().map(|&p| b[p]).collect();
        for r in 0..n {
            let (done, rest) = x.split_at_mut(r);
            let row = &self.lu[r * n..r * n + r];
            for (f, xc) in row.iter().zip(done.iter()) {
                for d in 0..3 {
                    rest[0][d] -= f * xc[d];
                }
            }
        }
        for r in (0..n).rev() {
            let (head, tail) = x.split_at_mut(r + 1);
            let row = &self.lu[r * n + r + 1..(r + 1) * n];
            let acc = &mut head[r];
            for (f, xc) in row.iter().zip(tail.iter()) {
                for d in 0..3 {
                    acc[d] -= f * xc[d];
                }
            }
            let piv = self.lu[r * n + r];
            *acc = [acc[0] / piv, acc[1] / piv, acc[2] / piv];
        }
        x
    }
}

/// Lower Cholesky factor of the row-major `n × n` symmetric matrix `g`; a pivot that is not
/// positive is an [`LgiError::Input`] (shapes linearly dependent at the markers).
pub fn cholesky(n: usize, g: Vec<f64>) -> Result<Vec<f64>> {
    cholesky_from(n, g, 0)
}

/// [`cholesky`] from column `start` on: `g`'s columns before `start` (on and below the
/// diagonal) already hold the factor's, the rest the matrix's. A factor's column depends only
/// on the matrix's columns up to it, so two matrices that agree on their first `start`
/// columns share those of their factors, and the rest made here are the bits a whole
/// factorisation makes.
pub(crate) fn cholesky_from(n: usize, mut g: Vec<f64>, start: usize) -> Result<Vec<f64>> {
    const ROWS: usize = 8;
    // Row slices rather than indices: no bounds checks in the inner products, which are
    // summed in the same order (k ascending) as ever.
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    for j in start..n {
        let d = g[j * n + j] - dot(&g[j * n..j * n + j], &g[j * n..j * n + j]);
        if d.is_nan() || d <= 0.0 {
            return Err(LgiError::Input(format!(
                "blendshape normal matrix is not positive definite at shape {j} \
                 (shapes linearly dependent at the markers? use l2 > 0)"
            )));
        }
        let d = d.sqrt();
        g[j * n + j] = d;
        let (above, below) = g.split_at_mut((j + 1) * n);
        let row_j = &above[j * n..j * n + j];
        // Eight rows at a time: each entry's inner product is still one sum in k order (the
        // same bits), but eight independent sums run side by side instead of one chain of
        // dependent additions waiting on each other.
        let mut groups = below.chunks_exact_mut(ROWS * n);
        for group in &mut groups {
            let sums = {
                let rows: [&[f64]; ROWS] = std::array::from_fn(|l| &group[l * n..l * n + j]);
                dot_rows(rows, row_j)
            };
            for (l, s) in sums.into_iter().enumerate() {
                let e = &mut group[l * n + j];
                *e = (*e - s) / d;
            }
        }
        for row_i in groups.into_remainder().chunks_exact_mut(n) {
            let s = row_i[j] - dot(&row_i[..j], row_j);
            row_i[j] = s / d;
        }
    }
    Ok(g)
}

/// `Σ a_i b_i` in f64 with eight independent partial sums (a single running sum is one
/// dependent chain of additions, ~4× slower); `a`'s values widened to f64 (exact for f32).
/// Inlined, so a caller built for AVX2 builds it so too.
#[inline(always)]
pub(crate) fn dot8<A: Copy + Into<f64>>(a: &[A], b: &[f64]) -> f64 {
    let mut acc = [0.0f64; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(&x, y)| x.into() * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            acc[l] += x[l].into() * y[l];
        }
    }
    ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7])) + tail
}

/// The inner products of `N` rows with `x`, each summed in order from −0.0 (as
/// `Iterator::sum` sums: the same bits as `N` separate sums), side by side.
#[inline]
pub(crate) fn dot_rows<const N: usize>(rows: [&[f64]; N], x: &[f64]) -> [f64; N] {
    let rows = rows.map(|r| &r[..x.len()]);
    let mut s = [-0.0f64; N];
    for (k, &xk) in x.iter().enumerate() {
        for (sl, row) in s.iter_mut().zip(&rows) {
            *sl += row[k] * xk;
        }
    }
    s
}

/// Solves `L Lᵀ x = b` with `l` from [`cholesky`].
pub fn cholesky_solve(n: usize, l: &[f64], b: &[f64]) -> Vec<f64> {
    lower_t_solve(n, l, &lower_solve(n, l, b))
}

/// `L⁻¹ b` of a lower-triangular row-major `n × n` matrix `l` (forward substitution, each
/// inner product one sum in order).
pub(crate) fn lower_solve(n: usize, l: &[f64], b: &[f64]) -> Vec<f64> {
    let mut y = b.to_vec();
    for i in 0..n {
        let s: f64 = l[i * n..i * n + i]
            .iter()
            .zip(&y[..i])
            .map(|(a, b)| a * b)
            .sum();
        y[i] = (y[i] - s) / l[i * n + i];
    }
    y
}

/// `L⁻ᵀ b` of a lower-triangular row-major `n × n` matrix `l` (back substitution).
pub(crate) fn lower_t_solve(n: usize, l: &[f64], b: &[f64]) -> Vec<f64> {
    let mut y = b.to_vec();
    for i in (0..n).rev() {
        let s: f64 = ((i + 1)..n).map(|k| l[k * n + i] * y[k]).sum();
        y[i] = (y[i] - s) / l[i * n + i];
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn lu_solution_satisfies_the_system(n in 1usize..12, seed in 0u64..1000) {
            // Diagonally dominant random matrix: always well conditioned.
            let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let mut rnd = || { s = s.wrapping_mul(6364136223846793005).wrapping_add(1); ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5 };
            let mut a = vec![0.0; n * n];
            for r in 0..n { for c in 0..n { a[r*n+c] = rnd(); } a[r*n+r] += n as f64; }
            let b: Vec<[f64;3]> = (0..n).map(|_| [rnd(), rnd(), rnd()]).collect();
            let lu = Lu::factor(n, a.clone()).unwrap();
            let x = lu.solve3(&b);
            for r in 0..n { for d in 0..3 {
                let ax: f64 = (0..n).map(|c| a[r*n+c] * x[c][d]).sum();
                prop_assert!((ax - b[r][d]).abs() < 1e-10);
            }}
        }

        /// The factor made eight rows at a time has the bits of the textbook one-row-at-a-time
        /// Cholesky (every inner product summed alone, in k order), and `L Lᵀ` is the matrix.
        #[test]
        fn cholesky_equals_the_one_row_at_a_time_factor_bit_for_bit(n in 1usize..23, seed in 0u64..1000) {
            let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let mut rnd = || { s = s.wrapping_mul(6364136223846793005).wrapping_add(1); ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5 };
            let m: Vec<f64> = (0..n * n).map(|_| rnd()).collect();
            let mut g = vec![0.0; n * n];
            for i in 0..n { for j in 0..n {
                g[i * n + j] = (0..n).map(|k| m[i * n + k] * m[j * n + k]).sum::<f64>();
            } g[i * n + i] += 0.1; }
            let got = cholesky(n, g.clone()).unwrap();
            let mut want = g.clone();
            for j in 0..n {
                let d: f64 = want[j * n + j] - (0..j).map(|k| want[j * n + k] * want[j * n + k]).sum::<f64>();
                want[j * n + j] = d.sqrt();
                for i in j + 1..n {
                    let x: f64 = want[i * n + j] - (0..j).map(|k| want[i * n + k] * want[j * n + k]).sum::<f64>();
                    want[i * n + j] = x / want[j * n + j];
                }
            }
            let lower = |a: &[f64]| (0..n).flat_map(|i| (0..=i).map(move |j| (i, j))).map(|(i, j)| a[i * n + j].to_bits()).collect::<Vec<_>>();
            prop_assert_eq!(lower(&got), lower(&want));
            for i in 0..n { for j in 0..=i {
                let llt: f64 = (0..=j).map(|k| got[i * n + k] * got[j * n + k]).sum();
                prop_assert!((llt - g[i * n + j]).abs() < 1e-10);
            }}
        }
    }

    #[test]
    fn lu_factors_are_the_textbook_eliminations_bits_on_both_builds() {
        // 37 x 37 (a tail past any vector width), pivoting needed on some rows.
        let n = 37usize;
        let a = crate::test_values::values(n * n, 11);
        let (fast, baseline) = crate::simd::both_builds(|| {
            Lu::factor(n, a.clone()).map(|lu| (lu.lu, lu.perm)).unwrap()
        });
        assert_eq!(fast.1, baseline.1);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&fast.0), bits(&baseline.0));
        // The same elimination written out with indices, partial pivoting by the largest.
        let mut m = a.clone();
        let mut perm: Vec<usize> = (0..n).collect();
        for k in 0..n {
            let p = (k..n).fold(k, |b, r| {
                if m[r * n + k].abs() > m[b * n + k].abs() {
                    r
                } else {
                    b
                }
            });
            for c in 0..n {
                m.swap(k * n + c, p * n + c);
            }
            perm.swap(k, p);
            for r in k + 1..n {
                let f = m[r * n + k] / m[k * n + k];
                m[r * n + k] = f;
                if f != 0.0 {
                    for c in k + 1..n {
                        m[r * n + c] -= f * m[k * n + c];
                    }
                }
            }
        }
        assert_eq!(fast.1, perm);
        assert_eq!(bits(&fast.0), bits(&m));
    }

    #[test]
    fn singular_matrix_is_an_error_naming_the_row() {
        let err = Lu::factor(2, vec![1.0, 2.0, 2.0, 4.0]).unwrap_err();
        assert!(err.to_string().contains("row 1"), "{err}");
    }

    #[test]
    fn permutation_matrix_needs_pivoting_and_solves_exactly() {
        let lu = Lu::factor(2, vec![0.0, 1.0, 1.0, 0.0]).unwrap();
        let x = lu.solve3(&[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        assert_eq!(x, vec![[4.0, 5.0, 6.0], [1.0, 2.0, 3.0]]);
    }
}
