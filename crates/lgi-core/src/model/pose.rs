//! The jaw pose of every frame, the solve's first stage on a model with a jaw rig: none (the
//! rest pose), given, from the dataset's blendshape fit then refined ([`JawPose::Fit`]), or
//! tracked from the markers the jaw carries ([`JawPose::Track`]).

use super::prepare::{frame_context, Prepared};
use super::{JawSetup, Model};
use crate::baselines::BlendshapeSolver;
use crate::error::{LgiError, Result};
use crate::geom::interpolate3;
use crate::jaw::{JawParams, JawRig};
use crate::linalg::Lu;
use crate::magnitude::Extent;
use crate::prior::{FitPrior, FrameFit, GramCache, FIT_L2, FIT_PENALTY};
use glam::DVec3;
use rayon::prelude::*;

/// Where each frame's jaw pose comes from ([`SolveOptions::jaw`](super::SolveOptions::jaw)).
/// Every kind but [`Rest`](JawPose::Rest) needs a model built with a jaw rig.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum JawPose {
    /// No pose: every frame is solved at the rest pose.
    #[default]
    Rest,
    /// Each frame's pose from the global blendshape fit of the dataset as given (jaw not
    /// unskinned) at the bundles, the shapes' poses weighted by their fitted weights clipped
    /// to [0, 1]; then refined to the pose whose unskinned markers the frame's jaw bin's fit
    /// explains best (Gauss–Newton, `Model::refine_jaw`). The fit explains the markers with
    /// every shape at once, so the jaw markers' non-rigid motion (lips, chin) does not bend
    /// the pose the way it bends [`Track`](JawPose::Track)'s.
    Fit,
    /// Each frame's pose fitted to the markers the jaw carries (jaw weight above 0.5) by
    /// [`JawRig::fit_pose`] (Huber-robust, from the previous frame's pose); a frame with fewer
    /// than 3 such markers present takes the pose interpolated between its neighbours'; then
    /// a centred moving average over 5 frames (shrinking at the ends). Biased where lips and
    /// chin move with other shapes; a take solved in chunks is tracked chunk by chunk.
    Track,
    /// One pose per frame, as given (checked like the frames: finite, angles below 180°, the
    /// translation within the magnitude limit).
    Given(Vec<JawParams>),
}

/// Markers with a jaw weight above this are the jaw's in a tracked pose.
const TRACK_MIN_WEIGHT: f64 = 0.5;
/// Huber threshold of the tracked pose's fit, in robust standard deviations of its residuals.
const TRACK_HUBER: f64 = 1.345;
/// Frames the tracked poses are averaged over (centred).
const TRACK_WINDOW: usize = 5;
/// Gauss–Newton iterations of each tracked frame's fit at most.
const TRACK_ITERATIONS: usize = 50;
/// Fewest jaw markers a tracked frame's fit needs (a rigid motion needs 3 points).
const TRACK_MIN_MARKERS: usize = 3;

/// Gauss–Newton iterations of [`Model::refine_jaw`] at most.
const JAW_ITERATIONS: usize = 6;
/// Its largest step per iteration: open and lateral in radians, forward in diagonals.
const JAW_STEP: [f64; 3] = [0.1, 0.05, 0.01];
/// Its finite-difference step (the same units).
const JAW_DIFFERENCE: f64 = 1e-6;
/// A step below this (the same units: 1e-6 rad moves a point 5 cm from the hinge by 5e-6 cm)
/// ends it.
const JAW_TOLERANCE: f64 = 1e-6;

/// The global blendshape fit of the dataset as given at the bundles (the start of
/// [`JawPose::Fit`]), made on first use: the solver and the bundles' rest positions.
#[derive(Debug)]
pub(super) struct RestFit {
    solver: BlendshapeSolver,
    rest: Vec<DVec3>,
}

impl RestFit {
    /// The fit made with its solver's factors ([`BlendshapeSolver::derive`]): what a model's
    /// build or load keeps, so that a take's first pose costs what its next does.
    pub(super) fn derived(model: &Model) -> Result<RestFit> {
        let fit = RestFit::new(model)?;
        fit.solver.derive()?;
        Ok(fit)
    }

    /// The matrix's column k is shape k's displacement of the bundles (`x0 + s_k` evaluated
    /// at the bundles, minus the neutral's), row `3i + c` coordinate c of bundle i; the ridge
    /// and penalty are [`FIT_L2`] and [`FIT_PENALTY`] times the columns' mean squared norm.
    /// Each sum is taken in the order numpy takes it, so poses match the numpy fit this
    /// replaces bit for bit.
    pub(super) fn new(model: &Model) -> Result<RestFit> {
        let data = &model.dataset;
        let (tris, x0) = (&data.neutral().triangles, &data.neutral().positions);
        let (b, s) = (model.bundles.len(), data.num_shapes());
        let rest: Vec<DVec3> = model
            .bundles
            .iter()
            .map(|sp| sp.evaluate(tris, x0))
            .collect();
        let mut a = vec![0.0; 3 * b * s];
        for k in 0..s {
            for (i, sp) in model.bundles.iter().enumerate() {
                let Some(tri) = tris.get(sp.triangle as usize) else {
                    return Err(LgiError::Input(format!(
                        "bundle {i}: triangle out of range"
                    )));
                };
                // `x0 + s_k` (f32 shapes widened) at the bundle's corners, as numpy adds them.
                let corners = tri.map(|v| x0[v as usize] + data.displacement(k, v as usize));
                let moved = (interpolate3(corners, sp.bary) - rest[i]).to_array();
                for (c, x) in moved.iter().enumerate() {
                    a[(3 * i + c) * s + k] = *x;
                }
            }
        }
        // numpy's `mean(sum(a**2, axis=0))`: each column summed row by row (pairwise when
        // the matrix is one column), the column sums pairwise.
        let column_norms: Vec<f64> = (0..s)
            .map(|k| {
                let squares = (0..3 * b).map(|r| a[r * s + k] * a[r * s + k]);
                if s == 1 {
                    pairwise_sum(&squares.collect::<Vec<_>>())
                } else {
                    squares.fold(0.0, |acc, x| acc + x)
                }
            })
            .collect();
        let mean = pairwise_sum(&column_norms) / s as f64;
        let scale = if mean == 0.0 { 1.0 } else { mean };
        let solver = BlendshapeSolver::new(a, 3 * b, s, FIT_L2 * scale, FIT_PENALTY * scale)?;
        Ok(RestFit { solver, rest })
    }

    /// The pose of a checked frame: the shapes' poses weighted by its fit's weights clipped
    /// to [0, 1], summed in shape order; and the fit's weights (S, dataset shape order).
    fn pose(&self, frame: &[DVec3], shape_thetas: &[JawParams]) -> Result<(JawParams, Vec<f64>)> {
        let target: Vec<f64> = frame
            .iter()
            .zip(&self.rest)
            .flat_map(|(t, r)| (*t - *r).to_array())
            .collect();
        let w = self.solver.solve(&target)?.weights;
        let mut theta = [0.0; 3];
        for (wk, tk) in w.iter().zip(shape_thetas) {
            let wk = wk.clamp(0.0, 1.0);
            for (t, x) in theta.iter_mut().zip(tk.to_array()) {
                *t += wk * x;
            }
        }
        Ok((JawParams::from_array(theta), w))
    }
}

/// Each frame's jaw pose (`None`: the rest pose) and, for a pose from the fit, the fit's
/// weights (S, dataset shape order): where the frame's fit in its bin starts
/// ([`Model::refine_jaw`]), the same minimum in fewer steps.
pub(super) struct FramePoses {
    pub(super) poses: Option<Vec<JawParams>>,
    pub(super) fit_starts: Vec<Vec<f64>>,
}

/// numpy's `pairwise_sum` of float64 (what `np.sum` of a contiguous vector adds): below 8
/// values in order, up to 128 in eight interleaved partial sums combined as a tree, beyond
/// that the two halves (split at a multiple of 8) recursively.
fn pairwise_sum(x: &[f64]) -> f64 {
    let n = x.len();
    if n < 8 {
        return x.iter().fold(0.0, |acc, v| acc + v);
    }
    if n <= 128 {
        let mut r = [0.0; 8];
        r.copy_from_slice(&x[..8]);
        let whole = n - n % 8;
        for chunk in x[8..whole].chunks_exact(8) {
            for (acc, v) in r.iter_mut().zip(chunk) {
                *acc += v;
            }
        }
        let tree = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        return x[whole..].iter().fold(tree, |acc, v| acc + v);
    }
    let half = n / 2;
    let half = half - half % 8;
    pairwise_sum(&x[..half]) + pairwise_sum(&x[half..])
}

impl Model {
    /// The model's jaw setup, which every pose but the rest pose needs.
    pub(super) fn jaw_setup(&self) -> Result<&JawSetup> {
        self.jaw
            .as_ref()
            .ok_or_else(|| LgiError::Input("jaw: this model was built without a jaw rig".into()))
    }

    /// Each frame's jaw pose (`None`: the rest pose). Frames whose pose is computed from them
    /// are checked first (as [`prepare`](Self::prepare) checks them; errors name the frame).
    pub(super) fn jaw_poses(&self, frames: &[Vec<DVec3>], pose: &JawPose) -> Result<FramePoses> {
        let jaw = match pose {
            JawPose::Rest => {
                return Ok(FramePoses {
                    poses: None,
                    fit_starts: Vec::new(),
                })
            }
            _ => self.jaw_setup()?,
        };
        if let JawPose::Given(poses) = pose {
            if poses.len() != frames.len() {
                return Err(LgiError::Input(format!(
                    "{} jaw poses for {} frames",
                    poses.len(),
                    frames.len()
                )));
            }
            return Ok(FramePoses {
                poses: Some(poses.clone()),
                fit_starts: Vec::new(),
            });
        }
        let extent = Extent::new(&self.markers_rest, self.diagonal);
        for (f, t) in frames.iter().enumerate() {
            self.check_targets(&extent, t)
                .map_err(|e| frame_context(e, f))?;
        }
        let (poses, fit_starts) = match pose {
            JawPose::Fit => {
                let fit = match self.rest_fit.get() {
                    Some(fit) => fit,
                    None => {
                        let made = RestFit::new(self)?;
                        self.rest_fit.get_or_init(|| made)
                    }
                };
                let thetas = &jaw.input.shape_thetas;
                frames
                    .par_iter()
                    .enumerate()
                    .map(|(f, t)| fit.pose(t, thetas).map_err(|e| frame_context(e, f)))
                    .collect::<Result<Vec<_>>>()?
                    .into_iter()
                    .unzip()
            }
            _ => {
                let rest = self.bundle_positions(&self.dataset.neutral().positions)?;
                let poses = track(
                    &jaw.input.rig,
                    &rest,
                    &jaw.bundle_weights,
                    frames,
                    TRACK_WINDOW,
                )?;
                (poses, Vec::new())
            }
        };
        Ok(FramePoses {
            poses: Some(poses),
            fit_starts,
        })
    }

    /// Moves a prepared frame's jaw pose to the one whose unskinned markers `u(θ)` the
    /// dataset's fit explains best: Gauss–Newton on `‖u(θ) − fit(u(θ))‖²` over the pose
    /// components some dataset shape has, from the frame's pose, the fit's derivative taken
    /// on its piece (so each step costs one fit). A linear fit of the skinned markers (the
    /// usual start) reads a partly open jaw as a mix of jawOpen and other shapes; in the
    /// unskinned space the jaw's rotation is gone and the rest is what the shapes span.
    /// Steps are bounded, each component stays at or above the smallest any dataset shape has
    /// (0 where none goes below the neutral), the best pose evaluated is kept (and its fit
    /// returned, the one the frame is solved with), and a frame without a pose or rig is left
    /// as it is.
    pub(super) fn refine_jaw(
        &self,
        prep: &mut Prepared,
        prior: &FitPrior,
    ) -> Result<Option<FrameFit>> {
        let (Some(jaw), Some(start)) = (&self.jaw, prep.theta) else {
            return Ok(None);
        };
        let scale = [1.0, 1.0, self.diagonal];
        let dims: Vec<usize> = (0..3)
            .filter(|&d| {
                jaw.input
                    .shape_thetas
                    .iter()
                    .any(|t| t.to_array()[d] != 0.0)
            })
            .collect();
        if dims.is_empty() {
            return Ok(None);
        }
        // No dataset shape turns the jaw past the neutral in these directions (e.g. ICT's
        // jaw is never pushed back): a pose there is one the dataset cannot vouch for, where
        // the refinement would explain a face that is not the dataset's by moving the jaw.
        let mut floor = [0.0f64; 3];
        for t in &jaw.input.shape_thetas {
            for (f, x) in floor.iter_mut().zip(t.to_array()) {
                *f = f.min(x);
            }
        }
        let at = |t: [f64; 3]| {
            self.lookup_targets(&prep.targets, Some(JawParams::from_array(t)), prep.bin)
        };
        let mut theta = start.to_array();
        // The Gram entries over the frame's present markers, kept between the steps.
        let mut gram = GramCache::default();
        // The best pose evaluated, its residual and its fit (what the frame is solved with).
        let mut best: Option<(f64, [f64; 3], FrameFit)> = None;
        // The first fit starts at the frame's fit of the dataset as given (the pose's start),
        // each later one at the fit before it.
        let mut last: Option<FrameFit> = prep.fit_start.take().map(|mut weights| {
            weights.insert(0, 0.0);
            FrameFit {
                weights,
                positions: Vec::new(),
                dual: Vec::new(),
            }
        });
        for _ in 0..JAW_ITERATIONS {
            let u = at(theta)?;
            let mut dirs = Vec::with_capacity(dims.len());
            for &d in &dims {
                let h = JAW_DIFFERENCE * scale[d];
                let mut t = theta;
                t[d] += h;
                let moved = at(t)?;
                dirs.push(
                    moved
                        .iter()
                        .zip(&u)
                        .map(|(a, b)| {
                            if b.is_nan() {
                                DVec3::ZERO
                            } else {
                                (*a - *b) / h
                            }
                        })
                        .collect::<Vec<_>>(),
                );
            }
            // Only the fit the frame is solved with needs the bundles' positions (below).
            let fit = prior.weights_from(&u, last.as_ref())?;
            // The residual of the fit's active shapes without its ridge: zero at a dataset
            // shape's own pose, so the refinement is not pulled off it by the ridge.
            let active: Vec<usize> = (1..fit.weights.len())
                .filter(|&j| fit.weights[j] > 0.0)
                .map(|j| j - 1)
                .collect();
            let (res, pjs) = prior.active_residuals(&u, &dirs, &active, &mut gram)?;
            let n = dims.len();
            let (mut m, mut g, mut e) = (vec![0.0; n * n], vec![[0.0; 3]; n], 0.0);
            for &i in &prep.present {
                let i = i as usize;
                let r = res[i];
                e += r.length_squared();
                let pj: Vec<DVec3> = (0..n).map(|a| pjs[a][i]).collect();
                for a in 0..n {
                    g[a][0] -= pj[a].dot(r);
                    for b in 0..n {
                        m[a * n + b] += pj[a].dot(pj[b]);
                    }
                }
            }
            if best.as_ref().is_some_and(|b| e >= b.0) {
                break;
            }
            best = Some((e, theta, fit.clone()));
            let trace: f64 = (0..n).map(|a| m[a * n + a]).sum();
            for a in 0..n {
                m[a * n + a] += 1e-9 * trace + f64::MIN_POSITIVE;
            }
            last = Some(fit);
            let Ok(lu) = Lu::factor(n, m) else { break };
            let step = lu.solve3(&g);
            let mut largest = 0.0f64;
            for (a, &d) in dims.iter().enumerate() {
                let limit = JAW_STEP[d] * scale[d];
                let moved = (theta[d] + step[a][0].clamp(-limit, limit)).max(floor[d]);
                largest = largest.max((moved - theta[d]).abs() / scale[d]);
                theta[d] = moved;
            }
            if largest < JAW_TOLERANCE {
                // The pose has settled: the last one evaluated stands.
                break;
            }
        }
        let Some((_, pose, mut fit)) = best else {
            return Ok(None);
        };
        prior.place(&mut fit);
        let pose = JawParams::from_array(pose);
        if pose.validate().is_err() {
            return Ok(None);
        }
        prep.lookup = at(pose.to_array())?;
        prep.theta = Some(pose);
        Ok(Some(fit))
    }
}

/// The tracked poses of checked `frames` ([`JawPose::Track`]) with a rig, the bundles' rest
/// positions and jaw weights, averaged over `window` frames.
fn track(
    rig: &JawRig,
    rest: &[DVec3],
    bundle_weights: &[f64],
    frames: &[Vec<DVec3>],
    window: usize,
) -> Result<Vec<JawParams>> {
    let carried: Vec<usize> = (0..rest.len())
        .filter(|&i| bundle_weights[i] > TRACK_MIN_WEIGHT)
        .collect();
    if carried.len() < TRACK_MIN_MARKERS {
        return Err(LgiError::Input(format!(
            "only {} bundles have a jaw weight above {TRACK_MIN_WEIGHT}; need \
             {TRACK_MIN_MARKERS}",
            carried.len()
        )));
    }
    let mut poses: Vec<Option<[f64; 3]>> = vec![None; frames.len()];
    let mut previous = JawParams::ZERO;
    for (pose, frame) in poses.iter_mut().zip(frames) {
        let present: Vec<usize> = carried
            .iter()
            .copied()
            .filter(|&i| frame[i].is_finite())
            .collect();
        if present.len() < TRACK_MIN_MARKERS {
            continue;
        }
        let points: Vec<DVec3> = present.iter().map(|&i| rest[i]).collect();
        let targets: Vec<DVec3> = present.iter().map(|&i| frame[i]).collect();
        let weights: Vec<f64> = present.iter().map(|&i| bundle_weights[i]).collect();
        previous = rig.fit_pose(
            &points,
            &targets,
            Some(&weights),
            previous,
            Some(TRACK_HUBER),
            TRACK_ITERATIONS,
        )?;
        let t = previous.to_array();
        *pose = t.iter().all(|x| x.is_finite()).then_some(t);
    }
    let filled = fill_gaps(&poses).ok_or_else(|| {
        LgiError::Input(format!(
            "no frame has {TRACK_MIN_MARKERS} usable jaw bundles"
        ))
    })?;
    Ok(moving_average(&filled, window)
        .into_iter()
        .map(JawParams::from_array)
        .collect())
}

/// Every frame's pose, a missing one interpolated linearly between the nearest frames with
/// one (held constant before the first and after the last), as numpy's `interp` does;
/// `None` when no frame has one.
fn fill_gaps(poses: &[Option<[f64; 3]>]) -> Option<Vec<[f64; 3]>> {
    let known: Vec<(f64, [f64; 3])> = poses
        .iter()
        .enumerate()
        .filter_map(|(f, p)| p.map(|p| (f as f64, p)))
        .collect();
    let (first, last) = (known.first()?.1, known.last()?.1);
    // `next` is the first known frame after the one being filled.
    let mut next = 0;
    let out = poses
        .iter()
        .enumerate()
        .map(|(f, p)| {
            let x = f as f64;
            while next < known.len() && known[next].0 <= x {
                next += 1;
            }
            match (p, next) {
                (Some(p), _) => *p,
                (None, 0) => first,
                (None, n) if n == known.len() => last,
                (None, n) => {
                    let ((x0, y0), (x1, y1)) = (known[n - 1], known[n]);
                    std::array::from_fn(|c| {
                        let slope = (y1[c] - y0[c]) / (x1 - x0);
                        let y = slope * (x - x0) + y0[c];
                        if !y.is_nan() {
                            return y;
                        }
                        // numpy's fallbacks: from the other end, then a flat stretch.
                        let y = slope * (x - x1) + y1[c];
                        if y.is_nan() && y0[c] == y1[c] {
                            y0[c]
                        } else {
                            y
                        }
                    })
                }
            }
        })
        .collect();
    Some(out)
}

/// Centred moving average over `window` frames, the window shrinking symmetrically near the
/// ends; written as differences of running sums, as the numpy tracker this replaces did.
fn moving_average(x: &[[f64; 3]], window: usize) -> Vec<[f64; 3]> {
    let half = window / 2;
    let n = x.len();
    if half == 0 || n < 2 {
        return x.to_vec();
    }
    let mut sums = Vec::with_capacity(n + 1);
    sums.push([0.0; 3]);
    sums.push(x[0]);
    for p in &x[1..] {
        let s: [f64; 3] = sums[sums.len() - 1];
        sums.push(std::array::from_fn(|c| s[c] + p[c]));
    }
    (0..n)
        .map(|i| {
            let h = half.min(i).min(n - 1 - i);
            let count = (2 * h + 1) as f64;
            std::array::from_fn(|c| (sums[i + h + 1][c] - sums[i - h][c]) / count)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairwise_sum_adds_in_numpys_order() {
        // Values whose sum depends on the order: each rule's grouping gives its own bits.
        let x: Vec<f64> = (0..300)
            .map(|i| {
                if i % 3 == 0 {
                    1e16
                } else {
                    1.0 + i as f64 * 1e-3
                }
            })
            .collect();
        let sequential = |v: &[f64]| v.iter().fold(0.0, |a, b| a + b);
        assert_eq!(
            pairwise_sum(&x[..7]).to_bits(),
            sequential(&x[..7]).to_bits()
        );
        let tree = |v: &[f64]| {
            let mut r = [0.0; 8];
            r.copy_from_slice(&v[..8]);
            let whole = v.len() - v.len() % 8;
            for i in (8..whole).step_by(8) {
                for j in 0..8 {
                    r[j] += v[i + j];
                }
            }
            let t = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
            v[whole..].iter().fold(t, |a, b| a + b)
        };
        assert_eq!(pairwise_sum(&x[..100]).to_bits(), tree(&x[..100]).to_bits());
        // 300 values: halves of 144 (a multiple of 8) and 156, each split again.
        let want = (tree(&x[..72]) + tree(&x[72..144])) + (tree(&x[144..222]) + tree(&x[222..]));
        assert_eq!(pairwise_sum(&x).to_bits(), want.to_bits());
    }

    #[test]
    fn gaps_are_filled_linearly_and_held_at_the_ends() {
        let p = |x: f64| Some([x, -x, 2.0 * x]);
        let poses = [None, p(1.0), None, None, p(4.0), None];
        let filled = fill_gaps(&poses).unwrap();
        let open: Vec<f64> = filled.iter().map(|t| t[0]).collect();
        assert_eq!(open, [1.0, 1.0, 2.0, 3.0, 4.0, 4.0]);
        assert_eq!(filled[2], [2.0, -2.0, 4.0]);
        assert!(fill_gaps(&[None, None]).is_none());
    }

    /// A rig and 150 points on a grid below and in front of its pivot: weight 1 (the jaw's)
    /// on the first third, falling to 0.05 over the rest.
    fn grid_rig() -> (JawRig, Vec<DVec3>, Vec<f64>) {
        let points: Vec<DVec3> = (0..150)
            .map(|i| {
                let (a, b, c) = ((i % 5) as f64, ((i / 5) % 6) as f64, (i / 30) as f64);
                DVec3::new(2.0 * a - 4.0, -1.5 * b - 1.0, 5.0 + c + 0.1 * a * b)
            })
            .collect();
        let weights: Vec<f64> = (0..150)
            .map(|i| {
                if i < 50 {
                    1.0
                } else {
                    1.0 - 0.95 * (i - 50) as f64 / 99.0
                }
            })
            .collect();
        let rig = JawRig::new(DVec3::new(0.3, -1.2, 2.5), vec![1.0; 150]).unwrap();
        (rig, points, weights)
    }

    #[test]
    fn tracking_is_exact_on_pure_jaw_frames_and_fills_frames_without_markers() {
        let (rig, rest, weights) = grid_rig();
        let truth: Vec<[f64; 3]> = (0..30)
            .map(|f| {
                let t = f as f64 / 29.0;
                [0.4 * (3.0 * t).sin(), 0.1 * (2.0 * t).cos(), 0.3 * t]
            })
            .collect();
        let mut frames: Vec<Vec<DVec3>> = truth
            .iter()
            .map(|&t| {
                let mut out = vec![DVec3::ZERO; rest.len()];
                let pose = JawParams::from_array(t);
                rig.skin_weighted(&rest, &weights, pose, &mut out).unwrap();
                out
            })
            .collect();
        frames[3].fill(DVec3::NAN); // a frame with every marker lost
        for frame in &mut frames[5..9] {
            for p in frame.iter_mut().step_by(3) {
                *p = DVec3::NAN;
            }
        }
        let close = |a: [f64; 3], b: [f64; 3], tol: f64| (0..3).all(|c| (a[c] - b[c]).abs() <= tol);
        let raw: Vec<[f64; 3]> = track(&rig, &rest, &weights, &frames, 1)
            .unwrap()
            .iter()
            .map(|p| p.to_array())
            .collect();
        for (f, (got, want)) in raw.iter().zip(&truth).enumerate() {
            if f != 3 {
                assert!(close(*got, *want, 1e-9), "frame {f}: {got:?} vs {want:?}");
            }
        }
        let between: [f64; 3] = std::array::from_fn(|c| 0.5 * (truth[2][c] + truth[4][c]));
        assert!(close(raw[3], between, 1e-9));
        let smoothed = track(&rig, &rest, &weights, &frames, TRACK_WINDOW).unwrap();
        assert!(close(smoothed[0].to_array(), raw[0], 1e-12)); // the window shrinks at the ends
        let mean: [f64; 3] =
            std::array::from_fn(|c| raw[8..13].iter().map(|p| p[c]).sum::<f64>() / 5.0);
        assert!(close(smoothed[10].to_array(), mean, 1e-12));
        // Too few markers on the jaw, or no frame with three of them: named errors.
        let e = track(&rig, &rest, &vec![0.4; 150], &frames, 1).unwrap_err();
        assert!(
            e.to_string()
                .contains("only 0 bundles have a jaw weight above 0.5"),
            "{e}"
        );
        let lost = vec![vec![DVec3::NAN; 150]; 2];
        let e = track(&rig, &rest, &weights, &lost, 1).unwrap_err();
        assert!(
            e.to_string().contains("no frame has 3 usable jaw bundles"),
            "{e}"
        );
    }

    #[test]
    fn the_moving_average_shrinks_its_window_at_the_ends() {
        let x: Vec<[f64; 3]> = (0..7).map(|i| [(i * i) as f64, i as f64, 1.0]).collect();
        let avg = moving_average(&x, 5);
        assert_eq!(avg[0], x[0]);
        assert_eq!(avg[1][0], (0.0 + 1.0 + 4.0) / 3.0);
        assert_eq!(avg[3][0], (1.0 + 4.0 + 9.0 + 16.0 + 25.0) / 5.0);
        assert_eq!(avg[6], x[6]);
        assert_eq!(moving_average(&x, 1), x);
    }
}
