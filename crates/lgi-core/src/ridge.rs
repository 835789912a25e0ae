//! The least-squares fit with a ridge alone, min ‖A w − t‖² + λ‖w‖² over the present rows of
//! `t`: the unbounded global fit ([`FitPrior::fit_unbounded`](crate::prior::FitPrior)). Its
//! equations over every row are inverted once, in the smaller of their two forms, and a
//! frame's missing rows (a take's dropouts) are taken off that inverse rather than factorised
//! again. With fewer shapes than rows, the normal equations `(AᵀA + λI)⁻¹` (S × S), the
//! missing rows a rank-m downdate (Woodbury's identity). With more (K = 2,000 scans on 360
//! marker rows), the dual ones `(A Aᵀ + λI)⁻¹` (R × R), the missing rows dropped by the
//! inverse's Schur complement, and `w = A_Pᵀ (A_P A_Pᵀ + λI)⁻¹ t_P`. A frame costs
//! O(min(R, S)² + R S) instead of a new factorisation.

use crate::baselines::check_target;
use crate::error::{LgiError, Result};
use crate::linalg::{cholesky, cholesky_solve, lower_solve, lower_t_solve};

/// The form the fit's equations are kept in.
#[derive(Debug, Clone)]
enum Form {
    /// `(AᵀA + λI)⁻¹` over every row (S × S, row-major).
    Primal { inverse: Vec<f64> },
    /// `(A Aᵀ + λI)⁻¹` over every row (R × R, row-major).
    Dual { inverse: Vec<f64> },
}

/// A ridge fit of one matrix (see the module's text).
#[derive(Debug, Clone)]
pub struct RidgeFit {
    /// Row-major R × S.
    a: Vec<f64>,
    rows: usize,
    shapes: usize,
    form: Form,
}

impl RidgeFit {
    /// `a` row-major `rows × shapes`; `lambda` > 0 (absolute).
    pub fn new(a: Vec<f64>, rows: usize, shapes: usize, lambda: f64) -> Result<RidgeFit> {
        if a.len() != rows * shapes || shapes == 0 {
            return Err(LgiError::Input(format!(
                "ridge fit: {} values are not {rows} rows of {shapes} shapes",
                a.len()
            )));
        }
        if !(lambda.is_finite() && lambda > 0.0) {
            return Err(LgiError::Input(format!(
                "ridge fit: the ridge must be finite and > 0, got {lambda}"
            )));
        }
        let row = |r: usize| &a[r * shapes..(r + 1) * shapes];
        let form = if shapes <= rows {
            let mut gram = vec![0.0; shapes * shapes];
            for r in 0..rows {
                let x = row(r);
                for i in 0..shapes {
                    for j in 0..=i {
                        gram[i * shapes + j] += x[i] * x[j];
                    }
                }
            }
            for i in 0..shapes {
                for j in 0..i {
                    gram[j * shapes + i] = gram[i * shapes + j];
                }
                gram[i * shapes + i] += lambda;
            }
            Form::Primal {
                inverse: inverse(shapes, gram)?,
            }
        } else {
            let mut k = vec![0.0; rows * rows];
            for i in 0..rows {
                for j in 0..=i {
                    let d: f64 = row(i).iter().zip(row(j)).map(|(x, y)| x * y).sum();
                    k[i * rows + j] = d;
                    k[j * rows + i] = d;
                }
                k[i * rows + i] += lambda;
            }
            Form::Dual {
                inverse: inverse(rows, k)?,
            }
        };
        Ok(RidgeFit {
            a,
            rows,
            shapes,
            form,
        })
    }

    /// The weights (S) fitting `target` (R values; NaN entries are missing rows, dropped).
    pub fn solve(&self, target: &[f64]) -> Result<Vec<f64>> {
        let (r, s) = (self.rows, self.shapes);
        check_target(target, r)?;
        let present: Vec<usize> = (0..r).filter(|&i| !target[i].is_nan()).collect();
        let missing: Vec<usize> = (0..r).filter(|&i| target[i].is_nan()).collect();
        let row = |i: usize| &self.a[i * s..(i + 1) * s];
        match &self.form {
            Form::Primal { inverse } => {
                let inv = |i: usize| &inverse[i * s..(i + 1) * s];
                let mut rhs = vec![0.0; s];
                for &p in &present {
                    for (acc, x) in rhs.iter_mut().zip(row(p)) {
                        *acc += x * target[p];
                    }
                }
                // y = G⁻¹ c over every row's G; the missing rows U (m × S) are then taken off
                // G by Woodbury: (G − UᵀU)⁻¹ = G⁻¹ + V (I − U V)⁻¹ Vᵀ with V = G⁻¹ Uᵀ.
                let apply = |v: &[f64]| -> Vec<f64> {
                    (0..s)
                        .map(|i| inv(i).iter().zip(v).map(|(g, x)| g * x).sum())
                        .collect()
                };
                let mut w = apply(&rhs);
                if !missing.is_empty() {
                    let m = missing.len();
                    let v: Vec<Vec<f64>> = missing.iter().map(|&i| apply(row(i))).collect();
                    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum();
                    let mut block = vec![0.0; m * m];
                    for (a, &i) in missing.iter().enumerate() {
                        for b in 0..m {
                            let uv: f64 = dot(row(i), &v[b]);
                            block[a * m + b] = if a == b { 1.0 - uv } else { -uv };
                        }
                    }
                    let uy: Vec<f64> = missing.iter().map(|&i| dot(row(i), &w)).collect();
                    let z = cholesky_solve(m, &cholesky(m, block)?, &uy);
                    for (vb, zb) in v.iter().zip(&z) {
                        for (wi, vi) in w.iter_mut().zip(vb) {
                            *wi += vi * zb;
                        }
                    }
                }
                Ok(w)
            }
            Form::Dual { inverse } => {
                let inv = |i: usize, j: usize| inverse[i * r + j];
                // x_P = (K_PP)⁻¹ t_P with (K_PP)⁻¹ = Kinv_PP − Kinv_PM (Kinv_MM)⁻¹ Kinv_MP.
                let mut x: Vec<f64> = present
                    .iter()
                    .map(|&i| present.iter().map(|&j| inv(i, j) * target[j]).sum())
                    .collect();
                if !missing.is_empty() {
                    let m = missing.len();
                    let y: Vec<f64> = missing
                        .iter()
                        .map(|&i| present.iter().map(|&j| inv(i, j) * target[j]).sum())
                        .collect();
                    let mut block = vec![0.0; m * m];
                    for (a, &i) in missing.iter().enumerate() {
                        for (b, &j) in missing.iter().enumerate() {
                            block[a * m + b] = inv(i, j);
                        }
                    }
                    let z = cholesky_solve(m, &cholesky(m, block)?, &y);
                    for (xp, &i) in x.iter_mut().zip(&present) {
                        *xp -= missing
                            .iter()
                            .zip(&z)
                            .map(|(&j, zj)| inv(i, j) * zj)
                            .sum::<f64>();
                    }
                }
                let mut w = vec![0.0; s];
                for (&p, xp) in present.iter().zip(&x) {
                    for (acc, a) in w.iter_mut().zip(row(p)) {
                        *acc += a * xp;
                    }
                }
                Ok(w)
            }
        }
    }
}

/// The inverse of the symmetric positive definite `n × n` matrix `g` (row-major): column c is
/// `L⁻ᵀ L⁻¹ e_c`, and by symmetry it is row c too.
fn inverse(n: usize, g: Vec<f64>) -> Result<Vec<f64>> {
    let l = cholesky(n, g)?;
    let mut out = vec![0.0; n * n];
    for c in 0..n {
        let mut e = vec![0.0; n];
        e[c] = 1.0;
        out[c * n..(c + 1) * n].copy_from_slice(&lower_t_solve(n, &l, &lower_solve(n, &l, &e)));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_values::values;

    /// The normal equations over the present rows, solved afresh: the reference.
    fn reference(a: &[f64], rows: usize, s: usize, lambda: f64, t: &[f64]) -> Vec<f64> {
        let present: Vec<usize> = (0..rows).filter(|&i| !t[i].is_nan()).collect();
        let mut g = vec![0.0; s * s];
        let mut rhs = vec![0.0; s];
        for i in 0..s {
            for j in 0..s {
                g[i * s + j] = present.iter().map(|&r| a[r * s + i] * a[r * s + j]).sum();
            }
            g[i * s + i] += lambda;
            rhs[i] = present.iter().map(|&r| a[r * s + i] * t[r]).sum();
        }
        cholesky_solve(s, &cholesky(s, g).unwrap(), &rhs)
    }

    #[test]
    fn both_forms_equal_the_normal_equations_over_the_present_rows() {
        // Fewer shapes than rows (the primal form) and more (the dual form).
        for (rows, s) in [(30, 7), (12, 40)] {
            let a = values(rows * s, 3 + s as u64);
            let fit = RidgeFit::new(a.clone(), rows, s, 1e-3).unwrap();
            let mut t = values(rows, 11);
            for missing in [vec![], vec![4], vec![0, 5, 6, 11]] {
                for &m in &missing {
                    t[m] = f64::NAN;
                }
                let got = fit.solve(&t).unwrap();
                let want = reference(&a, rows, s, 1e-3, &t);
                for (g, w) in got.iter().zip(&want) {
                    assert!(
                        (g - w).abs() < 1e-9 * (1.0 + w.abs()),
                        "{rows}x{s}: {g} vs {w}"
                    );
                }
            }
        }
    }

    #[test]
    fn bad_shapes_ridges_and_targets_are_input_errors() {
        assert!(RidgeFit::new(vec![0.0; 5], 2, 3, 1.0).is_err());
        assert!(RidgeFit::new(vec![0.0; 6], 2, 3, 0.0).is_err());
        let fit = RidgeFit::new(values(6, 1), 2, 3, 1.0).unwrap();
        assert!(fit.solve(&[1.0]).is_err());
        assert!(fit.solve(&[1.0, f64::INFINITY]).is_err());
    }
}
