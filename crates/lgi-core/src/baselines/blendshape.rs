//! Global blendshape fit, the standard production baseline: per frame the shape weights that
//! best explain the markers, min ‖A w − r‖² + l2‖w‖² + penalty·Σ(min(w,0)² + max(w−1,0)²).
//! The objective is a convex, C¹, piecewise quadratic, so an active-set (semi-smooth Newton)
//! iteration solves it exactly in a few steps.

use crate::error::{LgiError, Result};
use rayon::prelude::*;

/// Result of one frame's fit.
#[derive(Debug, Clone, PartialEq)]
pub struct BlendshapeSolution {
    /// Shape weights (S).
    pub weights: Vec<f64>,
    /// Newton iterations used (1 when no weight left [0, 1]).
    pub iterations: usize,
    /// Objective value at `weights`.
    pub objective: f64,
}

/// Solver for a fixed R×S matrix `A` (rows: marker coordinates, columns: shapes' displacements
/// at the markers).
#[derive(Debug, Clone)]
pub struct BlendshapeSolver {
    a: Vec<f64>,
    rows: usize,
    shapes: usize,
    l2: f64,
    penalty: f64,
    // AᵀA + l2 I over all rows (every complete frame's Hessian before the box terms) and its
    // Cholesky factor (the first step of every complete frame).
    full_gram: Vec<f64>,
    full: Vec<f64>,
}

const MAX_ITERATIONS: usize = 100;

/// Lower Cholesky factor of the row-major `n × n` symmetric matrix `g`.
fn cholesky(n: usize, mut g: Vec<f64>) -> Result<Vec<f64>> {
    for j in 0..n {
        let d = g[j * n + j] - (0..j).map(|k| g[j * n + k] * g[j * n + k]).sum::<f64>();
        if d.is_nan() || d <= 0.0 {
            return Err(LgiError::Input(format!(
                "blendshape normal matrix is not positive definite at shape {j} \
                 (shapes linearly dependent at the markers? use l2 > 0)"
            )));
        }
        let d = d.sqrt();
        g[j * n + j] = d;
        for i in (j + 1)..n {
            let s = g[i * n + j] - (0..j).map(|k| g[i * n + k] * g[j * n + k]).sum::<f64>();
            g[i * n + j] = s / d;
        }
    }
    Ok(g)
}

fn cholesky_solve(n: usize, l: &[f64], b: &[f64]) -> Vec<f64> {
    let mut y = b.to_vec();
    for i in 0..n {
        let s: f64 = (0..i).map(|k| l[i * n + k] * y[k]).sum();
        y[i] = (y[i] - s) / l[i * n + i];
    }
    for i in (0..n).rev() {
        let s: f64 = ((i + 1)..n).map(|k| l[k * n + i] * y[k]).sum();
        y[i] = (y[i] - s) / l[i * n + i];
    }
    y
}

impl BlendshapeSolver {
    /// `a` is row-major `rows × shapes`; `l2` and `penalty` are absolute, non-negative.
    pub fn new(a: Vec<f64>, rows: usize, shapes: usize, l2: f64, penalty: f64) -> Result<Self> {
        if a.len() != rows * shapes || shapes == 0 {
            return Err(LgiError::Input(format!(
                "blendshape matrix of {} values is not {rows}×{shapes} with shapes > 0",
                a.len()
            )));
        }
        if !(l2.is_finite() && l2 >= 0.0 && penalty.is_finite() && penalty >= 0.0) {
            return Err(LgiError::Input(format!(
                "l2 ({l2}) and penalty ({penalty}) must be finite and non-negative"
            )));
        }
        if a.iter().any(|x| !x.is_finite()) {
            return Err(LgiError::Input(
                "blendshape matrix has non-finite entries".into(),
            ));
        }
        let mut me = BlendshapeSolver {
            a,
            rows,
            shapes,
            l2,
            penalty,
            full_gram: Vec::new(),
            full: Vec::new(),
        };
        me.full_gram = me.gram(&vec![true; rows]);
        me.full = cholesky(shapes, me.full_gram.clone())?;
        Ok(me)
    }

    /// Number of shapes S.
    pub fn num_shapes(&self) -> usize {
        self.shapes
    }

    /// Number of rows R.
    pub fn num_rows(&self) -> usize {
        self.rows
    }

    fn gram(&self, present: &[bool]) -> Vec<f64> {
        let s = self.shapes;
        let mut g = vec![0.0; s * s];
        for (r, _) in present.iter().enumerate().filter(|(_, &p)| p) {
            let row = &self.a[r * s..(r + 1) * s];
            for i in 0..s {
                for j in 0..=i {
                    g[i * s + j] += row[i] * row[j];
                }
            }
        }
        for i in 0..s {
            g[i * s + i] += self.l2;
            for j in 0..i {
                g[j * s + i] = g[i * s + j];
            }
        }
        g
    }

    /// The objective at `w` for `target` (NaN entries are dropped rows).
    pub fn objective(&self, w: &[f64], target: &[f64]) -> f64 {
        let s = self.shapes;
        let mut f = 0.0;
        for (r, t) in target.iter().enumerate().filter(|(_, t)| !t.is_nan()) {
            let row = &self.a[r * s..(r + 1) * s];
            let aw: f64 = row.iter().zip(w).map(|(a, b)| a * b).sum();
            f += (aw - t) * (aw - t);
        }
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
        let (s, rows) = (self.shapes, self.rows);
        if target.len() != rows {
            return Err(LgiError::Input(format!(
                "expected {rows} target values, got {}",
                target.len()
            )));
        }
        if target.iter().any(|t| t.is_infinite()) {
            return Err(LgiError::Input("target has an infinite value".into()));
        }
        let present: Vec<bool> = target.iter().map(|t| !t.is_nan()).collect();
        let complete = present.iter().all(|&p| p);
        let partial;
        let gram = if complete {
            &self.full_gram
        } else {
            partial = self.gram(&present);
            &partial
        };
        let mut atr = vec![0.0; s];
        for (r, &t) in target.iter().enumerate().filter(|(_, t)| !t.is_nan()) {
            for (o, a) in atr.iter_mut().zip(&self.a[r * s..(r + 1) * s]) {
                *o += a * t;
            }
        }
        let step = |w: &[f64], first: bool| -> Result<Vec<f64>> {
            let active: Vec<(bool, bool)> = w.iter().map(|&x| (x < 0.0, x > 1.0)).collect();
            let none = active.iter().all(|&(l, u)| !l && !u);
            let mut rhs = atr.clone();
            for (r, &(_, u)) in rhs.iter_mut().zip(&active) {
                if u {
                    *r += self.penalty;
                }
            }
            if none && complete && first {
                return Ok(cholesky_solve(s, &self.full, &rhs));
            }
            let mut h = gram.clone();
            for (i, &(l, u)) in active.iter().enumerate() {
                if l || u {
                    h[i * s + i] += self.penalty;
                }
            }
            Ok(cholesky_solve(s, &cholesky(s, h)?, &rhs))
        };
        // Start inside the box so the first step is the plain (unconstrained) normal equations.
        let mut w = vec![0.5; s];
        let mut f = self.objective(&w, target);
        for it in 1..=MAX_ITERATIONS {
            let sides = |v: &[f64]| -> Vec<(bool, bool)> {
                v.iter().map(|&x| (x < 0.0, x > 1.0)).collect()
            };
            let cand = step(&w, it == 1)?;
            // The candidate minimises the quadratic piece of w's active set; if it lies in
            // that same piece the (C¹ convex) gradient vanishes there: the global minimum.
            if sides(&cand) == sides(&w) {
                let objective = self.objective(&cand, target);
                return Ok(BlendshapeSolution {
                    weights: cand,
                    iterations: it,
                    objective,
                });
            }
            // Otherwise an exact line search: along w + αd the objective is a convex piecewise
            // quadratic in α, so its derivative is piecewise linear between the breakpoints
            // where a weight crosses 0 or 1; a damped step keeps the iteration from cycling.
            let d: Vec<f64> = cand.iter().zip(&w).map(|(c, x)| c - x).collect();
            // The slope d·∇f(w + αd): the data term's part is linear in α, from A d and
            // A w − t once per iteration; the ridge and box terms are per weight.
            let (mut ad_r, mut ad_ad) = (0.0, 0.0);
            for (r, &t) in target.iter().enumerate().filter(|(_, t)| !t.is_nan()) {
                let row = &self.a[r * s..(r + 1) * s];
                let ad: f64 = row.iter().zip(&d).map(|(a, b)| a * b).sum();
                let res: f64 = row.iter().zip(&w).map(|(a, b)| a * b).sum::<f64>() - t;
                ad_r += ad * res;
                ad_ad += ad * ad;
            }
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
            w = w.iter().zip(&d).map(|(x, dx)| x + alpha * dx).collect();
            let fw = self.objective(&w, target);
            if fw >= f && alpha == 0.0 {
                return Err(LgiError::Input(
                    "blendshape fit stalled (no descent)".into(),
                ));
            }
            f = fw;
        }
        Err(LgiError::Input(format!(
            "blendshape fit did not converge in {MAX_ITERATIONS} iterations"
        )))
    }
}

impl BlendshapeSolver {
    /// [`BlendshapeSolver::solve`] for many frames, in parallel; the first error wins.
    pub fn solve_many(&self, targets: &[Vec<f64>]) -> Result<Vec<BlendshapeSolution>> {
        targets.par_iter().map(|t| self.solve(t)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rnd(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }

    // Brute force reference: projected gradient descent with a tiny fixed step, many steps.
    fn gradient_descent(sol: &BlendshapeSolver, t: &[f64]) -> Vec<f64> {
        let s = sol.num_shapes();
        let mut w = vec![0.0; s];
        for _ in 0..200_000 {
            let mut g = vec![0.0; s];
            for (r, &tr) in t.iter().enumerate() {
                let row = &sol.a[r * s..(r + 1) * s];
                let res: f64 = row.iter().zip(&w).map(|(a, b)| a * b).sum::<f64>() - tr;
                for (gi, a) in g.iter_mut().zip(row) {
                    *gi += 2.0 * res * a;
                }
            }
            for i in 0..s {
                let out = w[i].min(0.0) + (w[i] - 1.0).max(0.0);
                g[i] += 2.0 * (sol.l2 * w[i] + sol.penalty * out);
                w[i] -= 2e-3 * g[i];
            }
        }
        w
    }

    #[test]
    fn active_set_solution_matches_slow_gradient_descent() {
        for seed in 0..5u64 {
            let mut s = seed;
            let (rows, shapes) = (12, 4);
            let a: Vec<f64> = (0..rows * shapes).map(|_| rnd(&mut s)).collect();
            let t: Vec<f64> = (0..rows).map(|_| 3.0 * rnd(&mut s)).collect();
            let sol = BlendshapeSolver::new(a, rows, shapes, 1e-3, 5.0).unwrap();
            let got = sol.solve(&t).unwrap();
            let want = gradient_descent(&sol, &t);
            for (g, w) in got.weights.iter().zip(&want) {
                assert!(
                    (g - w).abs() < 1e-6,
                    "seed {seed}: {:?} vs {want:?}",
                    got.weights
                );
            }
            assert!(got.objective <= sol.objective(&want, &t) + 1e-12);
        }
    }

    #[test]
    fn weights_inside_the_box_are_the_plain_least_squares_solution() {
        let a = vec![1.0, 0.0, 0.0, 1.0, 1.0, 1.0];
        let sol = BlendshapeSolver::new(a, 3, 2, 0.0, 10.0).unwrap();
        let got = sol.solve(&[0.3, 0.6, 0.9]).unwrap();
        assert!((got.weights[0] - 0.3).abs() < 1e-12 && (got.weights[1] - 0.6).abs() < 1e-12);
        assert_eq!(got.iterations, 1);
    }

    #[test]
    fn missing_rows_are_dropped_and_bad_inputs_are_errors() {
        let a = vec![1.0, 0.0, 0.0, 1.0, 1.0, 1.0];
        let sol = BlendshapeSolver::new(a, 3, 2, 0.0, 0.0).unwrap();
        let got = sol.solve(&[0.2, f64::NAN, 0.7]).unwrap();
        assert!((got.weights[0] - 0.2).abs() < 1e-12 && (got.weights[1] - 0.5).abs() < 1e-12);
        assert!(sol.solve(&[0.0, 1.0]).is_err());
        assert!(sol.solve(&[0.0, f64::INFINITY, 1.0]).is_err());
        assert!(BlendshapeSolver::new(vec![1.0, 1.0], 1, 2, 0.0, 0.0).is_err());
        assert!(BlendshapeSolver::new(vec![1.0, 1.0], 1, 2, -1.0, 0.0).is_err());
    }
}
