//! The jaw pose fit: the θ whose skinning carries points onto their targets, by Gauss–Newton
//! with the analytic Jacobian of `F R_y(lateral) R_x(open) Fᵀ` in the rig's frame (robust with
//! Huber weights on request). The one implementation: the solve's tracked pose
//! ([`JawPose::Track`](crate::JawPose)) and Python's rig estimation (`lgi.jaw.estimate_rig`,
//! through `_lgi.JawRig.fit_pose`) both call it.

use glam::{DMat3, DVec3};

use super::{JawParams, JawRig};
use crate::error::{LgiError, Result};

/// Scales the Huber threshold's robust σ: 1.4826 × the median absolute residual is the
/// standard deviation of normally distributed residuals.
const MAD_TO_SIGMA: f64 = 1.4826;
/// Ridge on the normal equations, relative to their trace (a direction no point constrains
/// takes no step instead of a singular system).
const RIDGE: f64 = 1e-12;
/// A step this small relative to the points' extent from the pivot ends the fit.
const STEP_TOLERANCE: f64 = 1e-13;

impl JawRig {
    /// The pose θ minimising `Σᵢ ρ(‖skin(pᵢ, θ, wᵢ) − yᵢ‖)` over `points` (pᵢ) and their
    /// `targets` (yᵢ), by Gauss–Newton from `start`: `weights` are the points' jaw weights
    /// (`None`: 1 each, a rigid fit); `huber` (in units of the residuals' robust scale, e.g.
    /// 1.345) reweighs each iteration's points with Huber's weights (IRLS), `None` is plain
    /// least squares. At most `iterations` steps (at least one); the angles are kept within
    /// ±90° after each step, and a step that moves no point by more than 1e-13 of the points'
    /// extent ends the fit, as does a singular system (the pose reached so far is returned).
    pub fn fit_pose(
        &self,
        points: &[DVec3],
        targets: &[DVec3],
        weights: Option<&[f64]>,
        start: JawParams,
        huber: Option<f64>,
        iterations: usize,
    ) -> Result<JawParams> {
        if targets.len() != points.len() {
            return Err(LgiError::Input(format!(
                "targets: {} points for {} points to fit",
                targets.len(),
                points.len()
            )));
        }
        if let Some(w) = weights.filter(|w| w.len() != points.len()) {
            return Err(LgiError::Input(format!(
                "weights: {} weights for {} points",
                w.len(),
                points.len()
            )));
        }
        start.validate()?;
        let weight = |i: usize| weights.map_or(1.0, |w| w[i]);
        let f = self.frame;
        let local: Vec<DVec3> = points
            .iter()
            .map(|p| f.transpose() * (*p - self.pivot))
            .collect();
        let extent = 1.0
            + local
                .iter()
                .map(|l| l.abs().max_element())
                .fold(0.0, f64::max);
        let half_turn = 0.5 * std::f64::consts::PI;
        let mut theta = start.to_array();
        for _ in 0..iterations.max(1) {
            let blend = self.blend(JawParams::from_array(theta));
            let residuals: Vec<DVec3> = points
                .iter()
                .zip(targets)
                .enumerate()
                .map(|(i, (p, y))| blend.skin(*p, weight(i)) - *y)
                .collect();
            let robust = huber_weights(&residuals, huber);
            // d skin / dθ = w F dR Fᵀ (p − pivot) for the angles, w F e_z for the translation.
            let (rx, ry) = (
                DMat3::from_rotation_x(theta[0]),
                DMat3::from_rotation_y(theta[1]),
            );
            let open = f * ry * d_rotation_x(theta[0]);
            let lateral = f * d_rotation_y(theta[1]) * rx;
            let (mut jtj, mut jtr) = ([[0.0; 3]; 3], [0.0; 3]);
            for (i, (l, r)) in local.iter().zip(&residuals).enumerate() {
                let w = weight(i);
                let cols = [open * *l * w, lateral * *l * w, f.z_axis * w];
                for a in 0..3 {
                    jtr[a] -= robust[i] * cols[a].dot(*r);
                    for b in 0..3 {
                        jtj[a][b] += robust[i] * cols[a].dot(cols[b]);
                    }
                }
            }
            let ridge = RIDGE * (jtj[0][0] + jtj[1][1] + jtj[2][2]);
            for (a, row) in jtj.iter_mut().enumerate() {
                row[a] += ridge;
            }
            let Some(step) = solve3(jtj, jtr) else { break };
            for (t, s) in theta.iter_mut().zip(step) {
                *t += s;
            }
            theta[0] = theta[0].clamp(-half_turn, half_turn);
            theta[1] = theta[1].clamp(-half_turn, half_turn);
            if step[0].abs().max(step[1].abs()) * extent + step[2].abs() <= STEP_TOLERANCE * extent
            {
                break;
            }
        }
        Ok(JawParams::from_array(theta))
    }
}

/// `d R_x(a) / da`.
fn d_rotation_x(a: f64) -> DMat3 {
    let (s, c) = a.sin_cos();
    DMat3::from_cols(DVec3::ZERO, DVec3::new(0.0, -s, c), DVec3::new(0.0, -c, -s))
}

/// `d R_y(b) / db`.
fn d_rotation_y(b: f64) -> DMat3 {
    let (s, c) = b.sin_cos();
    DMat3::from_cols(DVec3::new(-s, 0.0, -c), DVec3::ZERO, DVec3::new(c, 0.0, -s))
}

/// Huber's IRLS weight of each residual: 1 up to `huber` robust standard deviations (from the
/// median residual norm), `δ / ‖r‖` beyond; all 1 without `huber` or with no spread to scale by.
fn huber_weights(residuals: &[DVec3], huber: Option<f64>) -> Vec<f64> {
    let norms: Vec<f64> = residuals.iter().map(|r| r.length()).collect();
    let Some(k) = huber.filter(|_| !norms.is_empty()) else {
        return vec![1.0; norms.len()];
    };
    let mut sorted = norms.clone();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    let median = if n % 2 == 1 {
        sorted[n / 2]
    } else {
        (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0
    };
    let delta = k * MAD_TO_SIGMA * median;
    if !(delta > 0.0 && delta.is_finite()) {
        return vec![1.0; n];
    }
    norms
        .iter()
        .map(|&r| {
            if r <= delta {
                1.0
            } else {
                delta / r.max(1e-300)
            }
        })
        .collect()
}

/// `m x = b` by Gaussian elimination with partial pivoting; `None` when a pivot is exactly zero
/// (the ridge keeps every other system solvable).
fn solve3(mut m: [[f64; 3]; 3], mut b: [f64; 3]) -> Option<[f64; 3]> {
    for k in 0..3 {
        let p = (k..3)
            .max_by(|&i, &j| m[i][k].abs().total_cmp(&m[j][k].abs()))
            .unwrap_or(k);
        if m[p][k] == 0.0 || m[p][k].is_nan() {
            return None;
        }
        m.swap(k, p);
        b.swap(k, p);
        let (pivot, pivot_b) = (m[k], b[k]);
        for r in k + 1..3 {
            let factor = m[r][k] / pivot[k];
            for (x, p) in m[r].iter_mut().zip(pivot).skip(k) {
                *x -= factor * p;
            }
            b[r] -= factor * pivot_b;
        }
    }
    let mut x = [0.0; 3];
    for k in (0..3).rev() {
        let tail: f64 = (k + 1..3).map(|c| m[k][c] * x[c]).sum();
        x[k] = (b[k] - tail) / m[k][k];
    }
    Some(x)
}
