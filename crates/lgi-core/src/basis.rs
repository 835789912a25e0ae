//! A basis of a dataset's shapes made of some of the shapes themselves, with every other shape
//! as a combination of them: an augmented dataset's in-betweens and pair sums are exact
//! combinations of its scanned shapes (ICT-300: 300 shapes, 57 independent). The global fit
//! spreads its weights over all of them; re-expressed over the basis, sewing the fit reads 57
//! shapes at a vertex instead of 300, with the same mesh to f32 round-off.

use rayon::prelude::*;

/// A shape whose squared residual against the basis is at most this fraction of its own
/// squared norm (relative rms 1e-6) counts as a combination of the basis.
const COMBINATION_TOLERANCE: f64 = 1e-12;

/// Coordinates summed per parallel task of the Gram matrix.
const BLOCK: usize = 4096;

/// The basis and every shape's coefficients over it.
#[derive(Debug, Clone)]
pub struct ShapeBasis {
    /// 0-based indices of the basis shapes.
    pub shapes: Vec<usize>,
    /// `S × q`: shape k is `Σ_j coefficients[k q + j] · shapes[j]` (a basis shape: its unit).
    coefficients: Vec<f64>,
}

impl ShapeBasis {
    /// The basis of `displacements` (`S × V × 3`, shape-major), or `None` when no shape is a
    /// combination of the others.
    pub fn find(displacements: &[f32], num_shapes: usize) -> Option<ShapeBasis> {
        let s = num_shapes;
        if s < 2 || displacements.len() % s != 0 {
            return None;
        }
        let n = displacements.len() / s;
        let gram = (0..n.div_ceil(BLOCK))
            .into_par_iter()
            .map(|c| {
                let (lo, hi) = (c * BLOCK, ((c + 1) * BLOCK).min(n));
                let rows: Vec<&[f32]> = (0..s)
                    .map(|k| &displacements[k * n + lo..k * n + hi])
                    .collect();
                let mut g = vec![0.0f64; s * s];
                for i in 0..s {
                    for j in 0..=i {
                        g[i * s + j] = rows[i]
                            .iter()
                            .zip(rows[j])
                            .map(|(a, b)| *a as f64 * *b as f64)
                            .sum();
                    }
                }
                g
            })
            .reduce(
                || vec![0.0; s * s],
                |mut a, b| {
                    a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                    a
                },
            );
        let at = |i: usize, j: usize| {
            if j <= i {
                gram[i * s + j]
            } else {
                gram[j * s + i]
            }
        };
        // Pivoted Cholesky, the pivot the shape least explained (relative to its own norm) by
        // the pivots so far; it stops when every shape is explained.
        let norm: Vec<f64> = (0..s).map(|k| at(k, k)).collect();
        let mut left = norm.clone();
        let mut factor: Vec<Vec<f64>> = Vec::new(); // columns of L, S each
        let mut pivots = Vec::new();
        loop {
            let (p, worst) = (0..s)
                .filter(|k| !pivots.contains(k))
                .map(|k| {
                    (
                        k,
                        if norm[k] > 0.0 {
                            left[k] / norm[k]
                        } else {
                            0.0
                        },
                    )
                })
                .fold((usize::MAX, 0.0f64), |b, x| if x.1 > b.1 { x } else { b });
            if p == usize::MAX || worst.is_nan() || worst <= COMBINATION_TOLERANCE {
                break;
            }
            let root = left[p].sqrt();
            let col: Vec<f64> = (0..s)
                .map(|i| (at(i, p) - factor.iter().map(|c| c[i] * c[p]).sum::<f64>()) / root)
                .collect();
            for (l, c) in left.iter_mut().zip(&col) {
                *l -= c * c;
            }
            left[p] = 0.0;
            factor.push(col);
            pivots.push(p);
        }
        let q = pivots.len();
        if q == s {
            return None;
        }
        // Shape k's coefficients solve L_PPᵀ c = L_k (L_PP: the pivots' rows of the factor,
        // lower triangular in pivot order).
        let mut coefficients = vec![0.0; s * q];
        for k in 0..s {
            let out = &mut coefficients[k * q..(k + 1) * q];
            if let Some(j) = pivots.iter().position(|&p| p == k) {
                out[j] = 1.0;
                continue;
            }
            for j in (0..q).rev() {
                let mut x = factor[j][k];
                for (m, o) in out.iter().enumerate().skip(j + 1) {
                    x -= factor[j][pivots[m]] * o;
                }
                out[j] = x / factor[j][pivots[j]];
            }
        }
        Some(ShapeBasis {
            shapes: pivots,
            coefficients,
        })
    }

    /// Weights over every shape (S) as weights over the basis shapes (S, zero elsewhere): the
    /// same combination of displacements.
    pub fn map(&self, weights: &[f64]) -> Vec<f64> {
        let q = self.shapes.len();
        let mut out = vec![0.0; weights.len()];
        for (k, &w) in weights.iter().enumerate() {
            if w != 0.0 {
                for (j, &c) in self.coefficients[k * q..(k + 1) * q].iter().enumerate() {
                    out[self.shapes[j]] += w * c;
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn combinations_are_found_and_mapped_weights_give_the_same_displacement() {
        // 3 independent shapes over 40 values, then an in-between and two pair sums.
        let n = 40;
        let base: Vec<Vec<f32>> = (0..3)
            .map(|k| {
                (0..n)
                    .map(|i| ((i * (k + 2)) as f32 * 0.37).sin())
                    .collect()
            })
            .collect();
        let mut shapes = base.clone();
        shapes.push(base[1].iter().map(|x| 0.5 * x).collect());
        shapes.push(base[0].iter().zip(&base[2]).map(|(a, b)| a + b).collect());
        shapes.push(base[1].iter().zip(&base[2]).map(|(a, b)| a + b).collect());
        let flat: Vec<f32> = shapes.iter().flatten().copied().collect();
        let basis = ShapeBasis::find(&flat, shapes.len()).unwrap();
        assert_eq!(basis.shapes.len(), 3);
        let w = [0.2, 0.0, 0.7, 0.4, 0.3, 0.9];
        let mapped = basis.map(&w);
        for (k, &m) in mapped.iter().enumerate() {
            assert!(m == 0.0 || basis.shapes.contains(&k));
        }
        let sum = |w: &[f64]| -> Vec<f64> {
            (0..n)
                .map(|i| w.iter().zip(&shapes).map(|(a, s)| a * s[i] as f64).sum())
                .collect()
        };
        for (a, b) in sum(&w).iter().zip(sum(&mapped)) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
        // Independent shapes have no basis smaller than themselves.
        let flat: Vec<f32> = base.iter().flatten().copied().collect();
        assert!(ShapeBasis::find(&flat, 3).is_none());
    }
}
