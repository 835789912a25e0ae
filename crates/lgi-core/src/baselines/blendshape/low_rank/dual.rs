//! The fit's dual in r dimensions: from 0, a nearby fit's dual point or given weights, its
//! Newton steps move many weights across the box's edges at once, so that the primal
//! iteration starts on the minimum's pieces and ends in one step.

use super::frame::Frame;
use super::kernels::{columns_times, columns_times_single, wt_times};
use crate::error::Result;
use crate::linalg::{cholesky, cholesky_solve, lower_solve, lower_t_solve};

/// `B = I + held WᵀW` (the Newton matrix of the dual with every weight held) as its Cholesky
/// factor L, and every weight's row whitened by it, `z_i = L⁻¹ w_i` (S × r): then
/// `w_iᵀ B⁻¹ w_j = z_iᵀ z_j`, what [`Frame::solve_few_free`] needs. The complete frames' is
/// made once per matrix; a frame with markers missing whitens its rows as they are needed.
#[derive(Debug, Clone)]
pub(super) struct Whitened {
    l: Vec<f64>,
    z: Vec<f64>,
}

impl Whitened {
    /// The form of `w` (S × r row-major, S = `shapes`) with `wtw` = WᵀW.
    pub(super) fn new(w: &[f64], wtw: &[f64], r: usize, shapes: usize, held: f64) -> Result<Self> {
        let l = held_factor(wtw, r, held)?;
        let mut z = vec![0.0; w.len()];
        for i in 0..shapes {
            z[i * r..(i + 1) * r].copy_from_slice(&lower_solve(r, &l, &w[i * r..(i + 1) * r]));
        }
        Ok(Whitened { l, z })
    }
}

/// The Cholesky factor of `I + held WᵀW`.
fn held_factor(wtw: &[f64], r: usize, held: f64) -> Result<Vec<f64>> {
    let mut b: Vec<f64> = wtw.iter().map(|x| x * held).collect();
    for i in 0..r {
        b[i * r + i] += 1.0;
    }
    cholesky(r, b)
}

/// Where [`Frame::dual`] ended: the weights on the minimum's pieces, the steps taken, and the
/// dual point (r values, the frame's coordinates), where a fit of a nearby target of the same
/// frame can start ([`DualStart::Point`]).
pub(in crate::baselines::blendshape) struct DualEnd {
    pub(in crate::baselines::blendshape) weights: Vec<f64>,
    pub(in crate::baselines::blendshape) steps: usize,
    pub(in crate::baselines::blendshape) point: Vec<f64>,
}

/// What [`Frame::solve_few_free`] keeps between a dual's steps of a frame with markers
/// missing: the Cholesky factor of `I + held WᵀW` and the whitened row `L⁻¹ w_i` of each
/// weight that has been in the box (empty until then).
#[derive(Default)]
pub(super) struct SmallFree {
    l: Vec<f64>,
    z: Vec<Vec<f64>>,
}

/// Where [`Frame::dual`] starts.
#[derive(Debug, Clone, Copy)]
pub(in crate::baselines::blendshape) enum DualStart<'a> {
    /// At 0: every weight at 0.
    Zero,
    /// At a dual point of the same frame's fit of a nearby target ([`DualEnd::point`]: the
    /// same markers missing, so the same coordinates); from 0 if it is not r finite values.
    Point(&'a [f64]),
    /// At the dual point nearest these weights (S).
    Weights(&'a [f64]),
}

impl Frame<'_> {
    /// `W' v` (S) for the dual's steps: from the single-precision transpose where W' has one.
    fn dual_pass(&self, v: &[f64]) -> Vec<f64> {
        match &self.wt32 {
            Some(single) => columns_times_single(single, self.shapes, v),
            None => columns_times(&self.wt, self.shapes, v),
        }
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
    /// line search stops at the first change that turns the slope), so it takes fewer steps.
    pub(in crate::baselines::blendshape) fn dual(
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
    pub(super) fn solve_few_free(
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
                    let _ = cell.set(Whitened::new(&self.w, &self.wtw, r, self.shapes, held)?);
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
}
