//! A take's own Gaussian prior on the frame's global fit (`lgi.take_prior` estimates it from
//! the take: empirical Bayes). A performance explores a few directions of a dataset's many
//! shapes; with noisy markers, least squares spends the noise over every shape's weight, and a
//! prior the take itself shows (its frames' weights' mean and covariance) keeps the fit to the
//! directions the take moves in. The weights are `w = μ + L v` with `v ~ N(0, I)` and each
//! marker coordinate's noise variance σ², so a frame's fit is the ridge fit of `A L` with ridge
//! σ² to the markers less `A μ` ([`RidgeFit`]: a frame's missing rows taken off one inverse).

use crate::error::{LgiError, Result};
use crate::ridge::RidgeFit;

/// The prior: the weights' mean (S) and a factor of their covariance (`S × q`, row-major,
/// `Σ = L Lᵀ`), and the markers' noise variance (per coordinate, data units²).
#[derive(Debug, Clone, PartialEq)]
pub struct TakePrior {
    mean: Vec<f64>,
    factor: Vec<f64>,
    rank: usize,
    noise_variance: f64,
}

impl TakePrior {
    /// Checked: `factor` holds `mean.len() × rank` finite values, the mean is finite and the
    /// noise variance finite and > 0.
    pub fn new(
        mean: Vec<f64>,
        factor: Vec<f64>,
        rank: usize,
        noise_variance: f64,
    ) -> Result<TakePrior> {
        let s = mean.len();
        if s == 0 || factor.len() != s * rank {
            return Err(LgiError::Input(format!(
                "take prior: a factor of {} values is not {s} shapes by {rank}",
                factor.len()
            )));
        }
        if mean.iter().chain(&factor).any(|x| !x.is_finite()) {
            return Err(LgiError::Input(
                "take prior: the mean and factor must be finite".into(),
            ));
        }
        if !(noise_variance.is_finite() && noise_variance > 0.0) {
            return Err(LgiError::Input(format!(
                "take prior: the markers' noise variance must be finite and > 0, got \
                 {noise_variance}"
            )));
        }
        Ok(TakePrior {
            mean,
            factor,
            rank,
            noise_variance,
        })
    }

    /// Number of shapes S.
    pub fn num_shapes(&self) -> usize {
        self.mean.len()
    }

    /// The prior's fit of one fit matrix `a` (row-major `rows × S`).
    pub fn fit(&self, a: &[f64], rows: usize) -> Result<TakeFit> {
        let (s, q) = (self.mean.len(), self.rank);
        if a.len() != rows * s {
            return Err(LgiError::Input(format!(
                "take prior: made for {s} shapes, the model's fit has {}",
                a.len() / rows.max(1)
            )));
        }
        let row = |r: usize| &a[r * s..(r + 1) * s];
        let a_mean: Vec<f64> = (0..rows)
            .map(|r| row(r).iter().zip(&self.mean).map(|(x, m)| x * m).sum())
            .collect();
        let ridge = if q == 0 {
            None
        } else {
            let mut al = vec![0.0; rows * q];
            for r in 0..rows {
                let out = &mut al[r * q..(r + 1) * q];
                for (x, l) in row(r).iter().zip(self.factor.chunks(q)) {
                    for (o, y) in out.iter_mut().zip(l) {
                        *o += x * y;
                    }
                }
            }
            Some(RidgeFit::new(al, rows, q, self.noise_variance)?)
        };
        Ok(TakeFit {
            prior: self.clone(),
            a_mean,
            ridge,
        })
    }
}

/// [`TakePrior`] made ready for one fit matrix.
#[derive(Debug, Clone)]
pub struct TakeFit {
    prior: TakePrior,
    /// `A μ` (R).
    a_mean: Vec<f64>,
    /// The ridge fit of `A L` with ridge σ²; `None` for a prior of rank 0 (the mean alone).
    ridge: Option<RidgeFit>,
}

impl TakeFit {
    /// The weights (S) of `target` (R values, NaN rows missing): `μ + L v`, `v` the ridge fit
    /// of `A L` to `target − A μ`.
    pub fn solve(&self, target: &[f64]) -> Result<Vec<f64>> {
        let mut w = self.prior.mean.clone();
        let Some(ridge) = &self.ridge else {
            return Ok(w);
        };
        let offset: Vec<f64> = target
            .iter()
            .zip(&self.a_mean)
            .map(|(t, m)| t - m)
            .collect();
        let v = ridge.solve(&offset)?;
        let q = self.prior.rank;
        for (wi, l) in w.iter_mut().zip(self.prior.factor.chunks(q)) {
            *wi += l.iter().zip(&v).map(|(x, y)| x * y).sum::<f64>();
        }
        Ok(w)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::{cholesky, cholesky_solve};
    use crate::test_values::values;

    /// The MAP weights in the covariance form, over the present rows:
    /// μ + Σ Aᵀ (A Σ Aᵀ + σ² I)⁻¹ (t − A μ) with Σ = L Lᵀ (an independent route to the fit's
    /// ridge of `A L`).
    fn map_weights(
        a: &[f64],
        (rows, s): (usize, usize),
        (mean, l, q): (&[f64], &[f64], usize),
        s2: f64,
        t: &[f64],
    ) -> Vec<f64> {
        let sigma =
            |i: usize, j: usize| -> f64 { (0..q).map(|k| l[i * q + k] * l[j * q + k]).sum() };
        let p: Vec<usize> = (0..rows).filter(|&r| !t[r].is_nan()).collect();
        let n = p.len();
        // A_P Σ (n × S)
        let a_sig: Vec<Vec<f64>> = p
            .iter()
            .map(|&r| {
                (0..s)
                    .map(|j| (0..s).map(|i| a[r * s + i] * sigma(i, j)).sum())
                    .collect()
            })
            .collect();
        let mut k = vec![0.0; n * n];
        for x in 0..n {
            for y in 0..n {
                k[x * n + y] = (0..s).map(|j| a_sig[x][j] * a[p[y] * s + j]).sum::<f64>()
                    + if x == y { s2 } else { 0.0 };
            }
        }
        let resid: Vec<f64> = p
            .iter()
            .map(|&r| t[r] - (0..s).map(|j| a[r * s + j] * mean[j]).sum::<f64>())
            .collect();
        let z = cholesky_solve(n, &cholesky(n, k).unwrap(), &resid);
        (0..s)
            .map(|j| mean[j] + (0..n).map(|x| a_sig[x][j] * z[x]).sum::<f64>())
            .collect()
    }

    #[test]
    fn the_take_fit_is_the_map_weights_of_the_gaussian_prior_with_rows_missing() {
        for (rows, s, q) in [(12, 5, 3), (6, 9, 4), (10, 4, 4)] {
            let a = values(rows * s, 3);
            let mean = values(s, 5);
            let l = values(s * q, 7);
            let s2 = 0.3;
            let prior = TakePrior::new(mean.clone(), l.clone(), q, s2).unwrap();
            let fit = prior.fit(&a, rows).unwrap();
            let mut t = values(rows, 11);
            for missing in [vec![], vec![1], vec![0, rows - 1]] {
                for &m in &missing {
                    t[m] = f64::NAN;
                }
                let got = fit.solve(&t).unwrap();
                let want = map_weights(&a, (rows, s), (&mean, &l, q), s2, &t);
                for (g, w) in got.iter().zip(&want) {
                    assert!((g - w).abs() < 1e-10, "{rows}x{s} q {q}: {g} vs {w}");
                }
            }
        }
    }

    #[test]
    fn a_prior_of_rank_zero_gives_its_mean_and_bad_priors_are_refused() {
        let prior = TakePrior::new(vec![0.5, -1.0], vec![], 0, 1.0).unwrap();
        let fit = prior.fit(&values(6, 1), 3).unwrap();
        assert_eq!(fit.solve(&[1.0, f64::NAN, 2.0]).unwrap(), vec![0.5, -1.0]);
        assert!(TakePrior::new(vec![0.5], vec![1.0, 2.0], 1, 1.0).is_err());
        assert!(TakePrior::new(vec![0.5], vec![f64::NAN], 1, 1.0).is_err());
        assert!(TakePrior::new(vec![0.5], vec![1.0], 1, 0.0).is_err());
        assert!(TakePrior::new(vec![], vec![], 0, 1.0).is_err());
        // A model with another number of shapes.
        assert!(prior.fit(&values(9, 1), 3).is_err());
    }
}
