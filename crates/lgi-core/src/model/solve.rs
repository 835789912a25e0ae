//! Solving frames: each frame's targets checked and mapped into its jaw bin's space, every
//! present bundle's choice (rayon over bundles), then one sewing pass over the vertices with
//! the frame's plan and jaw map. Sequences run one of three pipelines: temporal (frame by frame,
//! the next frame's choice beside this frame's sewing), independent (frames in parallel) or
//! smoothed (all choices, then temporal smoothing of the shape weights, then sewing).

use super::pose::{FramePoses, JawPose};
use super::prepare::{frame_context, Prepared};
use super::{FrameInfo, FrameState, LocalShapeId, Model};
use crate::choose::{choose, Choice, ChoiceParams, FrameErrors, Scoring, Scratch};
use crate::error::{LgiError, Result};
use crate::jaw::JawParams;
use crate::magnitude::Extent;
use crate::sew::{BundleTargets, Pieces};
use crate::smooth::smooth_choices_in_bins;
use crate::take_prior::{TakeFit, TakePrior};
use glam::DVec3;
use rayon::prelude::*;
use std::sync::Arc;

/// Round-off left at a bundle after the residual pass that triggers a refinement round
/// (relative to the diagonal; the promise to users is 1e-6).
pub(super) const RESIDUAL_TOLERANCE: f64 = 1e-12;

/// How much of each frame's surface a solve makes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Sewn {
    /// Every vertex: the solve's output.
    #[default]
    Mesh,
    /// The choices and the sewing's corrections, and every bundle's position on the sewn
    /// surface (the same bits as [`Mesh`](Self::Mesh) gives), with no vertex written: what a
    /// reading of left-out markers needs, at a fraction of the work.
    Markers,
    /// No choice and no sewing: the frames' targets (noise-aware ones with a marker noise),
    /// global fits and jaw poses, for a caller that makes the surface from pieces of its own
    /// (local fits). A present bundle's position is its target and its choice is reported as
    /// a fit (its piece is the caller's); a missing bundle's position is NaN.
    Nothing,
}

/// How a sequence is solved.
#[derive(Debug, Clone, PartialEq)]
pub struct SolveOptions {
    /// Frames in order, each preferring the previous frame's choices (a performance); false:
    /// independent frames, solved in parallel.
    pub temporal: bool,
    /// Average each bundle's shape weights over this many frames (centred) before sewing
    /// when > 1; the global fit is then not offered as a candidate.
    pub smooth_window: usize,
    /// Offer every bundle the frame's global blendshape fit ([`crate::prior`]) beside its
    /// tets, chosen by the same neighbour score. False is the paper's method.
    pub fit: bool,
    /// Marker noise σ (data units, per coordinate): markers are moved to the noise-aware
    /// targets of [`FitPrior::denoise`](crate::prior::FitPrior::denoise) before the
    /// solve, which then interpolates those. `None`: every marker is interpolated as given.
    pub marker_noise: Option<f64>,
    /// The frame's global fit without the box: weights by least squares with the fit's ridge
    /// alone ([`FitPrior::fit_unbounded`](crate::prior::FitPrior::fit_unbounded)), for a
    /// dataset of scans, whose weights are no activations. The jaw pose is still refined
    /// against the boxed fit (unbounded weights can stand in for the jaw's turn); the
    /// unbounded fit is made once, at that pose.
    pub unbounded_fit: bool,
    /// The take's own prior on the unbounded fit's weights ([`TakePrior`]), in place of its
    /// ridge; needs [`unbounded_fit`](Self::unbounded_fit).
    pub take_prior: Option<Arc<TakePrior>>,
    /// Each frame's jaw pose (a model built with a jaw rig): none, given, from the fit or
    /// tracked ([`JawPose`]).
    pub jaw: JawPose,
    /// How much of each frame's surface to make ([`Sewn`]; every vertex by default).
    pub sewn: Sewn,
}

impl Default for SolveOptions {
    /// The paper's method on a performance: temporal, tets only, every marker interpolated.
    fn default() -> Self {
        SolveOptions::exact(true, 0)
    }
}

impl SolveOptions {
    /// The paper's exact interpolation of every marker with tets only, at the rest pose.
    pub fn exact(temporal: bool, smooth_window: usize) -> Self {
        SolveOptions {
            temporal,
            smooth_window,
            fit: false,
            marker_noise: None,
            unbounded_fit: false,
            take_prior: None,
            jaw: JawPose::Rest,
            sewn: Sewn::Mesh,
        }
    }

    /// Options with the fit candidate on when asked (`fit`) or, left open (`None`), exactly
    /// when a marker noise is given: noise-aware solving is meant with the fit, whose
    /// residuals it measures markers against. At the rest pose; set [`jaw`](Self::jaw) for
    /// another.
    pub fn new(
        temporal: bool,
        smooth_window: usize,
        fit: Option<bool>,
        marker_noise: Option<f64>,
    ) -> Self {
        SolveOptions {
            temporal,
            smooth_window,
            fit: fit.unwrap_or(marker_noise.is_some()),
            marker_noise,
            unbounded_fit: false,
            take_prior: None,
            jaw: JawPose::Rest,
            sewn: Sewn::Mesh,
        }
    }

    fn validate(&self) -> Result<()> {
        if self.take_prior.is_some() && !self.unbounded_fit {
            return Err(LgiError::Input(
                "a take prior is a prior on the unbounded fit: solve with unbounded_fit".into(),
            ));
        }
        match self.marker_noise {
            Some(s) if !(s.is_finite() && s >= 0.0) => Err(LgiError::Input(format!(
                "marker_noise must be a finite distance >= 0 (data units), got {s}"
            ))),
            _ => Ok(()),
        }
    }
}

impl Model {
    /// Choice, then sewing of the unsmoothed choices, for a checked frame, writing the
    /// vertices into `out` (V; `None`: the bundles' positions only, [`Sewn::Markers`]).
    fn solve_prepared_into(
        &self,
        prep: &Prepared,
        previous: Option<&[Option<Choice>]>,
        out: Option<&mut [DVec3]>,
    ) -> Result<FrameInfo> {
        let choices = self.choose_all(prep, previous);
        let pieces = Pieces::from_choices_with_fit(&choices, prep.fit_weights());
        self.sew_frame_into(prep, choices, &pieces, out)
    }

    /// A prepared frame without its surface ([`Sewn::Nothing`]): its targets as the
    /// bundles' positions, each present bundle's piece reported as a fit.
    fn unsewn_frame(&self, prep: &Prepared) -> FrameInfo {
        let choices = prep
            .targets
            .iter()
            .map(|t| (!t.is_nan()).then_some(Choice::of_fit(0.0)))
            .collect();
        FrameInfo {
            choices,
            residuals: prep.residuals(&prep.targets),
            bundle_positions: prep.targets.clone(),
            bin: prep.bin,
            corrections: prep.corrections.clone(),
            fit_weights: self.global_fit_weights(prep),
            theta: prep.theta,
        }
    }

    /// The frame's fit weights per dataset shape id (empty without a fit).
    fn global_fit_weights(&self, prep: &Prepared) -> Vec<f64> {
        let lk = &self.lookups[prep.bin];
        match &prep.fit {
            Some(fit) if lk.reference.is_some() => {
                let mut global = vec![0.0; self.dataset.num_shapes() + 1];
                for (j, &w) in fit.weights.iter().enumerate() {
                    global[lk.global_id(LocalShapeId(j as u32)).0 as usize] = w;
                }
                global
            }
            Some(fit) => fit.weights.clone(),
            None => Vec::new(),
        }
    }

    /// A fit's weights over the dataset's shapes (S) as a start for bin `bin`'s fit: its
    /// members' weights, in bin-local order.
    pub(super) fn fit_start_in_bin(&self, bin: usize, start: Vec<f64>) -> Vec<f64> {
        let lk = &self.lookups[bin];
        match lk.reference {
            None => start,
            Some(_) => (1..=lk.members.len())
                .map(|j| start[lk.global_id(LocalShapeId(j as u32)).0 as usize - 1])
                .collect(),
        }
    }

    /// Adds the frame's global fit to a prepared frame (offered as a candidate with
    /// `offer`; without the box where `unbounded`, at the pose the boxed fit refined) and,
    /// with `marker_noise`, moves its targets to the noise-aware ones, in the bin's space and
    /// back to the frame's.
    pub(super) fn add_fit(
        &self,
        prep: &mut Prepared,
        offer: bool,
        marker_noise: Option<f64>,
        refine_jaw: bool,
        unbounded: bool,
        take: Option<&TakeFit>,
    ) -> Result<()> {
        let Some(prior) = &self.lookups[prep.bin].prior else {
            return Ok(());
        };
        let refined = if refine_jaw {
            self.refine_jaw(prep, prior)?
        } else {
            None
        };
        let fit = match (refined, unbounded) {
            (_, true) => match take {
                Some(take) => prior.fit_with_take(take, &prep.lookup)?,
                None => prior.fit_unbounded(&prep.lookup)?,
            },
            (Some(fit), false) => fit,
            (None, false) => prior.fit(&prep.lookup)?,
        };
        if marker_noise == Some(0.0) {
            // Noise-free markers stay where they are (no round trip through the jaw's space).
            prep.corrections = vec![0.0; prep.targets.len()];
        } else if let Some(sigma) = marker_noise {
            let denoised = prior.denoise(&prep.lookup, &fit, sigma)?;
            let targets = self.frame_targets(&denoised, prep.theta, prep.bin)?;
            prep.corrections = prep
                .targets
                .iter()
                .zip(&targets)
                .map(|(a, b)| if a.is_nan() { 0.0 } else { a.distance(*b) })
                .collect();
            prep.lookup = denoised;
            prep.given = Some(std::mem::replace(&mut prep.targets, targets));
        }
        if offer {
            if let Some(basis) = self.lookups[prep.bin].fit_basis() {
                let mut blend = vec![0.0];
                blend.extend(basis.map(&fit.weights[1..]));
                prep.blend = blend;
            }
        }
        prep.fit = Some(fit);
        prep.offer_fit = offer;
        Ok(())
    }

    /// The inverse of [`lookup_targets`](Self::lookup_targets): points of bin `bin`'s space
    /// in the frame's (skinned) space.
    fn frame_targets(
        &self,
        lookup: &[DVec3],
        theta: Option<JawParams>,
        bin: usize,
    ) -> Result<Vec<DVec3>> {
        self.repose_bundles(lookup, self.lookups[bin].reference, theta)
    }

    /// Targets in bin `bin`'s space: unskinned with the frame's pose, then skinned to the
    /// bin's reference pose, `T(θ_b) T(θ)⁻¹` with each bundle's jaw weight.
    pub(super) fn lookup_targets(
        &self,
        targets: &[DVec3],
        theta: Option<JawParams>,
        bin: usize,
    ) -> Result<Vec<DVec3>> {
        self.repose_bundles(targets, theta, self.lookups[bin].reference)
    }

    /// Bundle positions at jaw pose `from` moved to pose `to` (`None`: the rest pose, no
    /// step), each with its bundle's jaw weight: unskinned by `from`, then skinned by `to`.
    fn repose_bundles(
        &self,
        points: &[DVec3],
        from: Option<JawParams>,
        to: Option<JawParams>,
    ) -> Result<Vec<DVec3>> {
        let Some(j) = &self.jaw else {
            return Ok(points.to_vec());
        };
        let mut out = points.to_vec();
        if let Some(t) = from {
            j.input
                .rig
                .unskin_weighted(points, &j.bundle_weights, t, &mut out)?;
        }
        if let Some(r) = to {
            let unskinned = out.clone();
            j.input
                .rig
                .skin_weighted(&unskinned, &j.bundle_weights, r, &mut out)?;
        }
        Ok(out)
    }

    /// Every present bundle's choice (rayon over bundles).
    pub(super) fn choose_all(
        &self,
        prep: &Prepared,
        previous: Option<&[Option<Choice>]>,
    ) -> Vec<Option<Choice>> {
        let targets = &prep.lookup;
        let errors = self.frame_errors(prep.bin, targets);
        let fit = prep.fit.as_ref().filter(|_| prep.offer_fit);
        (0..self.bundles.len())
            .into_par_iter()
            .map_init(Scratch::default, |scratch, i| {
                if targets[i].is_nan() {
                    return None;
                }
                let previous = previous.and_then(|p| p.get(i)).and_then(|c| c.as_ref());
                let scoring = self.scoring(prep.bin, i, targets, &errors, previous);
                let tet = self.choose_scored(prep.bin, i, &scoring, scratch);
                let Some(fit) = fit else {
                    return Some(tet);
                };
                // The global fit against the tets, by the same score (ties keep the tet).
                if scoring.positions_score(&fit.positions, i, true) < scoring.choice_score(&tet) {
                    Some(Choice::of_fit(fit.positions[i].distance(targets[i])))
                } else {
                    Some(tet)
                }
            })
            .collect()
    }

    /// The per-frame tables the choices of one frame share ([`FrameErrors`]), for `targets` in
    /// the space of jaw bin `bin` (0 when unbinned).
    ///
    /// # Panics
    /// If `bin` is not one of the model's bins.
    pub fn frame_errors(&self, bin: usize, targets: &[DVec3]) -> FrameErrors {
        FrameErrors::new(
            &self.lookups[bin].shape_positions,
            self.bundles.len(),
            targets,
        )
    }

    /// Bundle `i`'s choice for its target `targets[i]` in jaw bin `bin`, scored against the
    /// frame's `targets` and their [`frame_errors`](Self::frame_errors), preferring the shapes
    /// of `previous` (the bundle's previous choice, bin-local ids:
    /// [`LocalShapeId`](super::LocalShapeId)). What a solve does for each
    /// present bundle, without the sewing (for benchmarks and profiling).
    ///
    /// # Panics
    /// If `bin` or `i` is out of range.
    pub fn choose_bundle(
        &self,
        bin: usize,
        i: usize,
        targets: &[DVec3],
        errors: &FrameErrors,
        previous: Option<&Choice>,
        scratch: &mut Scratch,
    ) -> Choice {
        let scoring = self.scoring(bin, i, targets, errors, previous);
        self.choose_scored(bin, i, &scoring, scratch)
    }

    /// Bundle `i`'s tet choice in bin `bin` under `scoring` (whose targets hold its target).
    fn choose_scored(
        &self,
        bin: usize,
        i: usize,
        scoring: &Scoring<'_>,
        scratch: &mut Scratch,
    ) -> Choice {
        let lk = &self.lookups[bin];
        choose(
            &lk.indices[i],
            &lk.clouds[i],
            &lk.groups[i],
            scoring.targets[i],
            scoring,
            &self.choice_params(),
            scratch,
        )
    }

    /// How bundle `i`'s candidates are scored in bin `bin` (see [`choose_bundle`](Self::choose_bundle)).
    fn scoring<'a>(
        &'a self,
        bin: usize,
        i: usize,
        targets: &'a [DVec3],
        errors: &'a FrameErrors,
        previous: Option<&'a Choice>,
    ) -> Scoring<'a> {
        Scoring {
            shape_positions: &self.lookups[bin].shape_positions,
            num_bundles: self.bundles.len(),
            neighbours: &self.neighbours[i],
            targets,
            previous,
            temporal_weight: self.temporal_penalty(),
            pure_errors: &errors.pure,
            distances: &errors.distances,
        }
    }

    /// The choice's tuning from the build config, in data units.
    pub fn choice_params(&self) -> ChoiceParams {
        let c = &self.config;
        ChoiceParams {
            eps: c.containment_eps,
            projection_candidates: c.projection_candidates,
            hit_distance: c.prune_motion.max(c.duplicate_distance) * self.diagonal,
            ..ChoiceParams::default()
        }
    }

    /// Penalty per shape not shared with the previous frame's choice, in data units²
    /// ([`Scoring::temporal_weight`](crate::choose::Scoring)).
    pub fn temporal_penalty(&self) -> f64 {
        self.config.temporal_weight * self.diagonal * self.diagonal
    }

    /// Blends `pieces`, maps them out of the bin and to the frame's jaw pose, and runs the
    /// residual pass — one pass over the vertices, written into `out` (V); with `out` `None`,
    /// only the bundles' triangle corners are sewn and the bundles' positions measured on
    /// them (the same bits, [`Sewn::Markers`]).
    pub(super) fn sew_frame_into(
        &self,
        prep: &Prepared,
        choices: Vec<Option<Choice>>,
        pieces: &Pieces,
        out: Option<&mut [DVec3]>,
    ) -> Result<FrameInfo> {
        let (targets_clean, theta) = (&prep.targets, prep.theta);
        let plan = self
            .sewing
            .plan_for(&self.dataset, &self.bundles, &prep.present)?;
        let mesh = self.dataset.neutral();
        let lk = &self.lookups[prep.bin];
        let at = BundleTargets {
            triangles: &mesh.triangles,
            bundles: &self.bundles,
            targets: targets_clean,
            tolerance: RESIDUAL_TOLERANCE * self.diagonal,
        };
        let jaw_map = match &self.jaw {
            Some(j) if lk.reference.is_some() || theta.is_some() => Some(j.input.rig.vertex_map(
                lk.reference,
                theta,
                mesh.num_vertices(),
            )?),
            _ => None,
        };
        // Spans only pay where a fit sums dozens of shapes over every block.
        let spans = (!pieces.fit_shapes.is_empty()).then(|| lk.shape_spans());
        let x0 = &lk.data.neutral().positions;
        let shapes = lk.data.displacements();
        let bundle_positions: Vec<DVec3> = match out {
            Some(out) => {
                let bad = plan.sew_into(x0, shapes, spans, pieces, jaw_map.as_ref(), &at, out);
                if let Some(v) = bad {
                    return Err(non_finite(format!("vertex {v}")));
                }
                self.bundles
                    .iter()
                    .map(|sp| sp.evaluate(&mesh.triangles, out))
                    .collect()
            }
            None => {
                let at_bundles = plan.sew_markers(x0, shapes, spans, pieces, jaw_map.as_ref(), &at);
                if let Some(b) = at_bundles.iter().position(|p| !p.is_finite()) {
                    return Err(non_finite(format!("position at bundle {b}")));
                }
                at_bundles
            }
        };
        let residuals = prep.residuals(&bundle_positions);
        let choices = if lk.reference.is_some() {
            choices
                .into_iter()
                .map(|c| c.map(|c| lk.globalize(c)))
                .collect()
        } else {
            choices
        };
        let fit_weights = self.global_fit_weights(prep);
        Ok(FrameInfo {
            choices,
            residuals,
            bundle_positions,
            bin: prep.bin,
            corrections: prep.corrections.clone(),
            fit_weights,
            theta: prep.theta,
        })
    }

    /// Solves `frames` (each B bundle positions; a row with a NaN is a missing marker) with
    /// `options`, writing frame f's vertices into `vertices[f * V..(f + 1) * V]` (a caller's
    /// buffer, e.g. a numpy array: no per-frame allocation), and returns the rest of each
    /// frame. With [`temporal`](SolveOptions::temporal), frames are solved in order, each
    /// preferring tets that share shapes with the previous frame's choice; without, frames
    /// are independent and solved in parallel. A [`smooth_window`](SolveOptions::smooth_window)
    /// above 1 averages each bundle's shape weights over that many frames (centred) before
    /// sewing, in the jaw-unskinned space so jaw motion is not smoothed; the residual pass
    /// still interpolates every marker. [`jaw`](SolveOptions::jaw) gives each frame's jaw
    /// pose ([`JawPose`]); with jaw bins a frame keeps the previous frame's bin while its
    /// opening allows (hysteresis), and the previous choices are preferred only within a bin.
    ///
    /// `previous` continues a temporal solve: the first frame prefers its choices and keeps
    /// its jaw bin as the frame after it would in one call, so a take solved chunk by chunk,
    /// each chunk given the last frame's state of the one before ([`FrameInfo::state`]), is
    /// the take solved at once (frames are independent otherwise; smoothing and a tracked
    /// pose see only their own chunk). `on_frame` is called as frames finish (progress).
    pub fn solve(
        &self,
        frames: &[Vec<DVec3>],
        options: &SolveOptions,
        previous: Option<&FrameState>,
        vertices: &mut [DVec3],
        on_frame: impl FnMut(usize),
    ) -> Result<Vec<FrameInfo>> {
        options.validate()?;
        Extent::new(&self.markers_rest, self.diagonal).check_marker_noise(options.marker_noise)?;
        let (temporal, smooth_window) = (options.temporal, options.smooth_window);
        let nv = self.dataset.num_vertices();
        // A solve that writes no vertex takes an empty buffer (or a whole one, left as it is).
        let unwritten = options.sewn != Sewn::Mesh && vertices.is_empty();
        if vertices.len() != frames.len() * nv && !unwritten {
            return Err(LgiError::Input(format!(
                "output buffer holds {} vertices, {} frames of {nv} need {}",
                vertices.len(),
                frames.len(),
                frames.len() * nv
            )));
        }
        let vertices = match options.sewn {
            Sewn::Mesh => vertices,
            Sewn::Markers | Sewn::Nothing => &mut [],
        };
        let FramePoses {
            poses,
            mut fit_starts,
        } = self.jaw_poses(frames, &options.jaw)?;
        let theta = |f: usize| poses.as_ref().map(|p| p[f]);
        // Bins are picked in order: in a temporal solve a frame keeps the previous frame's bin
        // while its opening allows (hysteresis).
        let mut prepared: Vec<Prepared> = Vec::with_capacity(frames.len());
        let previous = previous.filter(|_| temporal);
        for (f, t) in frames.iter().enumerate() {
            let previous_bin = match prepared.last() {
                Some(p) => Some(p.bin).filter(|_| temporal),
                None => previous.and_then(|s| s.bin),
            };
            let mut prep = self
                .prepare(t, theta(f), previous_bin)
                .map_err(|e| frame_context(e, f))?;
            if let Some(start) = fit_starts.get_mut(f) {
                prep.fit_start = Some(self.fit_start_in_bin(prep.bin, std::mem::take(start)));
            }
            prepared.push(prep);
        }
        // A pose from the fit is refined against the bin's fit, in the jaw's unskinned space.
        let refine = options.jaw == JawPose::Fit;
        if options.fit || options.marker_noise.is_some() || refine {
            // Frames' fits are independent of each other: in parallel.
            let offer = options.fit && smooth_window <= 1;
            if offer {
                // Found once per bin, before the parallel loop rather than inside it.
                self.lookups.iter().for_each(|lk| {
                    lk.fit_basis();
                });
            }
            // The take's prior made ready once per bin's fit matrix.
            let takes: Vec<Option<TakeFit>> = match &options.take_prior {
                Some(take) => self
                    .lookups
                    .iter()
                    .map(|lk| lk.prior.as_ref().map(|p| p.take_fit(take)).transpose())
                    .collect::<Result<_>>()?,
                None => Vec::new(),
            };
            prepared.par_iter_mut().enumerate().try_for_each(|(f, p)| {
                self.add_fit(
                    p,
                    offer,
                    options.marker_noise,
                    refine,
                    options.unbounded_fit,
                    takes.get(p.bin).and_then(Option::as_ref),
                )
                .map_err(|e| frame_context(e, f))
            })?;
        }
        if options.sewn == Sewn::Nothing {
            let out: Vec<FrameInfo> = prepared.par_iter().map(|p| self.unsewn_frame(p)).collect();
            (0..out.len()).for_each(on_frame);
            return Ok(out);
        }
        match (smooth_window <= 1, temporal) {
            (true, true) => self.solve_temporal_pipelined(&prepared, previous, vertices, on_frame),
            (true, false) => self.solve_independent(&prepared, vertices, on_frame),
            (false, _) => {
                self.solve_smoothed(&prepared, temporal, smooth_window, vertices, on_frame)
            }
        }
    }

    /// Each frame's slot of `vertices` (`None` for every frame when `vertices` is empty: a
    /// [`Sewn::Markers`] solve writes no vertex; an empty mesh still gets an empty slot).
    fn frame_slots<'v>(
        &self,
        vertices: &'v mut [DVec3],
        frames: usize,
    ) -> Vec<Option<&'v mut [DVec3]>> {
        let nv = self.dataset.num_vertices();
        if vertices.is_empty() && nv > 0 {
            return (0..frames).map(|_| None).collect();
        }
        let mut slots: Vec<Option<&mut [DVec3]>> =
            vertices.chunks_mut(nv.max(1)).map(Some).collect();
        slots.resize_with(frames, || Some(&mut []));
        slots
    }

    /// Frame by frame in order, each preferring the previous frame's choices; every frame is
    /// finished (and reported) before the next starts. Frame f + 1's choice needs only frame
    /// f's choices, not its vertices: it runs beside frame f's sewing (`rayon::join`), which
    /// fills the gaps of either stage.
    fn solve_temporal_pipelined(
        &self,
        prepared: &[Prepared],
        previous: Option<&FrameState>,
        vertices: &mut [DVec3],
        mut on_frame: impl FnMut(usize),
    ) -> Result<Vec<FrameInfo>> {
        let slots = self.frame_slots(vertices, prepared.len());
        let mut out: Vec<FrameInfo> = Vec::with_capacity(prepared.len());
        let mut current = prepared.first().map(|p| {
            // The frame before this call, as the loop below hands a frame to the next.
            let before = previous
                .filter(|s| s.bin.is_none_or(|b| b == p.bin))
                .map(|s| self.lookups[p.bin].localize(&s.choices));
            self.choose_all(p, before.as_deref())
        });
        for (f, (prep, slot)) in prepared.iter().zip(slots).enumerate() {
            let choices = current.take().unwrap_or_default();
            let pieces = Pieces::from_choices_with_fit(&choices, prep.fit_weights());
            let next = prepared.get(f + 1);
            // What the next frame prefers: this frame's choices as reported (dataset
            // ids), in the next frame's bin, when it stays in this bin.
            let previous = next.filter(|n| n.bin == prep.bin).map(|n| {
                let lk = &self.lookups[prep.bin];
                let reported: Vec<Option<Choice>> = if lk.reference.is_some() {
                    choices.iter().map(|c| c.map(|c| lk.globalize(c))).collect()
                } else {
                    choices.clone()
                };
                self.lookups[n.bin].localize(&reported).into_owned()
            });
            let (sewn, chosen) = rayon::join(
                || self.sew_frame_into(prep, choices, &pieces, slot),
                || next.map(|n| self.choose_all(n, previous.as_deref())),
            );
            out.push(sewn.map_err(|e| frame_context(e, f))?);
            on_frame(f);
            current = chosen;
        }
        Ok(out)
    }

    /// Independent frames, solved in parallel; reported once all are done.
    fn solve_independent(
        &self,
        prepared: &[Prepared],
        vertices: &mut [DVec3],
        mut on_frame: impl FnMut(usize),
    ) -> Result<Vec<FrameInfo>> {
        let out: Vec<FrameInfo> = prepared
            .par_iter()
            .zip(self.frame_slots(vertices, prepared.len()).into_par_iter())
            .enumerate()
            .map(|(f, (prep, slot))| {
                self.solve_prepared_into(prep, None, slot)
                    .map_err(|e| frame_context(e, f))
            })
            .collect::<Result<_>>()?;
        (0..out.len()).for_each(&mut on_frame);
        Ok(out)
    }

    /// Every frame's choice first (in order with `temporal`, else in parallel), then each
    /// bundle's shape weights averaged over `smooth_window` frames within the same bin, then
    /// the frames sewn in order.
    fn solve_smoothed(
        &self,
        prepared: &[Prepared],
        temporal: bool,
        smooth_window: usize,
        vertices: &mut [DVec3],
        mut on_frame: impl FnMut(usize),
    ) -> Result<Vec<FrameInfo>> {
        let choices: Vec<Vec<Option<Choice>>> = if temporal {
            // Local shape ids: the previous choices count only within the same bin.
            let mut out: Vec<Vec<Option<Choice>>> = Vec::with_capacity(prepared.len());
            for (f, prep) in prepared.iter().enumerate() {
                let same_bin = f > 0 && prepared[f - 1].bin == prep.bin;
                let previous = out.last().filter(|_| same_bin).map(|c| c.as_slice());
                let chosen = self.choose_all(prep, previous);
                out.push(chosen);
            }
            out
        } else {
            prepared
                .par_iter()
                .map(|p| self.choose_all(p, None))
                .collect()
        };
        let bins: Vec<usize> = prepared.iter().map(|p| p.bin).collect();
        let pieces = smooth_choices_in_bins(&choices, &bins, smooth_window);
        let slots = self.frame_slots(vertices, prepared.len());
        let mut out = Vec::with_capacity(prepared.len());
        for (f, ((prep, (ch, pc)), slot)) in prepared
            .iter()
            .zip(choices.into_iter().zip(&pieces))
            .zip(slots)
            .enumerate()
        {
            out.push(
                self.sew_frame_into(prep, ch, pc, slot)
                    .map_err(|e| frame_context(e, f))?,
            );
            on_frame(f);
        }
        Ok(out)
    }
}

/// The error of a solve that produced a non-finite `what` (a vertex, a bundle's position).
fn non_finite(what: String) -> LgiError {
    LgiError::Input(format!(
        "the solve produced a non-finite {what}: targets are probably far outside the \
         dataset's range"
    ))
}
