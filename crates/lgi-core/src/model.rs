//! The LGI model: everything precomputed from a dataset and a marker layout (bundle clouds,
//! tets and their grid indices, UV sewing weights), immutable after build and `Send + Sync`,
//! so frames are solved with `&self` in parallel (rayon over bundles, then over vertices).

use crate::choose::{
    alias_groups, choose, pure_errors, AliasGroups, Choice, ChoiceParams, Scoring, Scratch,
};
use crate::cloud::{build_cloud, BundleCloud};
use crate::correspond::{correspond, SurfacePoint};
use crate::dataset::Dataset;
use crate::error::{LgiError, Result};
use crate::geodesic::{is_detour, EdgeGraph};
use crate::grid::TetIndex;
use crate::jaw::{JawParams, JawRig};
use crate::sew::{blend, Pieces, ResidualPass};
use crate::sibson::{SibsonWeights, SparseWeights};
use crate::smooth::smooth_choices;
use crate::tets::{generate_tets, Tet, TetConfig};
use crate::uvspace::{self, SewingSpace};
use glam::DVec3;
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// Build parameters. Distances are relative to the neutral's bounding-box diagonal.
#[derive(Debug, Clone, PartialEq)]
pub struct BuildConfig {
    /// Markers farther than this from the neutral surface are an error (relative).
    pub surface_tolerance: f64,
    /// Shapes moving a bundle less than this are aliases of the neutral point (relative).
    pub prune_motion: f64,
    /// Cloud points closer than this are merged as aliases (relative).
    pub duplicate_distance: f64,
    /// Nearest neighbours per cloud point for tet generation.
    pub tet_neighbours: usize,
    /// Tets kept per bundle, best quality first.
    pub max_tets: usize,
    /// Tets below this quality (1 = regular) are dropped.
    pub min_quality: f64,
    /// Tets with an edge longer than this are dropped (relative; infinity = no limit).
    pub max_edge: f64,
    /// Barycentric tolerance of "contains".
    pub containment_eps: f64,
    /// Nearest tets scored when a target is outside every tet.
    pub projection_candidates: usize,
    /// Penalty per shape not shared with the previous frame's choice (relative to diagonal²).
    pub temporal_weight: f64,
    /// A bundle gives no weight to a vertex (and is no neighbour of another bundle) when the
    /// surface path between them is longer than this many times the straight line: that path
    /// goes around a hole (the mouth slit, an eye). Infinity disables the rule.
    pub detour_ratio: f64,
}

impl Default for BuildConfig {
    fn default() -> Self {
        BuildConfig {
            surface_tolerance: 0.02,
            prune_motion: 1e-5,
            duplicate_distance: 1e-7,
            tet_neighbours: 10,
            max_tets: 20_000,
            min_quality: 0.02,
            max_edge: f64::INFINITY,
            containment_eps: 1e-9,
            projection_candidates: 8,
            temporal_weight: 1e-6,
            detour_ratio: 1.4,
        }
    }
}

impl BuildConfig {
    /// Checks every field's domain.
    pub fn validate(&self) -> Result<()> {
        let pos = |name: &str, v: f64| {
            if v.is_nan() || v <= 0.0 {
                Err(LgiError::Input(format!(
                    "BuildConfig.{name} must be > 0, got {v}"
                )))
            } else {
                Ok(())
            }
        };
        pos("surface_tolerance", self.surface_tolerance)?;
        pos("max_edge", self.max_edge)?;
        if self.detour_ratio.is_nan() || self.detour_ratio < 1.0 {
            return Err(LgiError::Input(format!(
                "BuildConfig.detour_ratio must be >= 1, got {}",
                self.detour_ratio
            )));
        }
        for (name, v) in [
            ("prune_motion", self.prune_motion),
            ("duplicate_distance", self.duplicate_distance),
            ("containment_eps", self.containment_eps),
            ("temporal_weight", self.temporal_weight),
            ("min_quality", self.min_quality),
        ] {
            if !v.is_finite() || v < 0.0 {
                return Err(LgiError::Input(format!(
                    "BuildConfig.{name} must be finite and >= 0, got {v}"
                )));
            }
        }
        if self.tet_neighbours < 3 || self.max_tets == 0 || self.projection_candidates == 0 {
            return Err(LgiError::Input(
                "BuildConfig.tet_neighbours must be >= 3, max_tets and projection_candidates >= 1"
                    .into(),
            ));
        }
        Ok(())
    }
}

/// Natural-neighbour weights and residual pass for one set of present bundles.
#[derive(Debug)]
pub struct SewPlan {
    /// V × B weights (columns of missing bundles are empty).
    pub weights: SparseWeights,
    residual: ResidualPass,
}

/// One solved frame.
#[derive(Debug, Clone)]
pub struct Frame {
    /// Reconstructed vertices (V).
    pub vertices: Vec<DVec3>,
    /// Per bundle: the chosen geometry (`None` for a missing bundle).
    pub choices: Vec<Option<Choice>>,
    /// Per bundle: distance from target to reconstructed surface point (0 for missing).
    pub residuals: Vec<f64>,
    /// Per bundle: the reconstructed surface position (for missing bundles, the estimate).
    pub bundle_positions: Vec<DVec3>,
}

/// What the next frame needs from the previous one.
#[derive(Debug, Clone, Default)]
pub struct FrameState {
    /// Previous choices per bundle.
    pub choices: Vec<Option<Choice>>,
}

/// Jaw articulation of a model (paper Eq. 2): the rig, each dataset shape's jaw parameters
/// (its jaw motion is unskinned before indexing) and each bundle's jaw weight.
#[derive(Debug, Clone)]
pub struct JawSetup {
    /// Two-bone skinning rig (skull fixed, jaw rigid about a pivot).
    pub rig: JawRig,
    /// Jaw parameters θ_k of every dataset shape.
    pub shape_thetas: Vec<JawParams>,
    /// Jaw weight of every bundle (barycentric blend of its triangle's vertex weights).
    pub bundle_weights: Vec<f64>,
}

/// A frame's targets after the checks: as given (NaN rows missing) and as looked up (jaw
/// unskinned), with the present bundles and the jaw pose.
struct Prepared {
    targets: Vec<DVec3>,
    lookup: Vec<DVec3>,
    present: Vec<u32>,
    theta: Option<JawParams>,
}

/// Per-bundle statistics of a built model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BundleStats {
    /// Distinct points in the cloud.
    pub points: usize,
    /// Tets in the index.
    pub tets: usize,
    /// Bytes of the index.
    pub index_bytes: usize,
}

/// A built model. See the module docs.
#[derive(Debug)]
pub struct Model {
    /// The dataset as given (what `dataset()` returns and what is saved).
    dataset: Arc<Dataset>,
    /// The dataset the pieces come from: `dataset` with its jaw unskinned when a jaw rig is
    /// used (the same `Arc` otherwise).
    sew_dataset: Arc<Dataset>,
    jaw: Option<JawSetup>,
    config: BuildConfig,
    markers_rest: Vec<DVec3>,
    bundles: Vec<SurfacePoint>,
    diagonal: f64,
    shape_positions: Vec<DVec3>,
    clouds: Vec<BundleCloud>,
    groups: Vec<Vec<AliasGroups>>,
    indices: Vec<TetIndex>,
    space: SewingSpace,
    graph: EdgeGraph,
    neighbours: Vec<Vec<u32>>,
    full_plan: Arc<SewPlan>,
    /// Every sewn vertex's natural neighbours among all bundles, before barriers and detours
    /// (rows of the sewn vertices in order): which rows a missing bundle can change.
    support: SparseWeights,
    plans: Mutex<HashMap<Vec<u32>, Arc<SewPlan>>>,
}

/// Round-off left at a bundle after the residual pass that triggers a refinement round
/// (relative to the diagonal; the promise to users is 1e-6).
const RESIDUAL_TOLERANCE: f64 = 1e-12;

/// Plans kept for distinct sets of missing bundles before the cache is cleared.
const PLAN_CACHE: usize = 64;

impl Model {
    /// Builds the model for `dataset` and marker rest positions `markers_rest` (B).
    pub fn build(dataset: &Dataset, markers_rest: &[DVec3], config: &BuildConfig) -> Result<Model> {
        Model::build_shared(Arc::new(dataset.clone()), markers_rest, config, None)
    }

    /// As [`Model::build`], sharing the dataset instead of copying it, with an optional jaw
    /// rig and the dataset shapes' jaw parameters (their jaw motion is unskinned first).
    pub fn build_shared(
        dataset: Arc<Dataset>,
        markers_rest: &[DVec3],
        config: &BuildConfig,
        jaw: Option<(JawRig, Vec<JawParams>)>,
    ) -> Result<Model> {
        config.validate()?;
        let dataset_given = dataset;
        let sew_dataset = unskinned_dataset(&dataset_given, jaw.as_ref())?;
        let dataset_arc = sew_dataset.clone();
        let dataset: &Dataset = &dataset_arc;
        let mesh = dataset.neutral();
        let b = markers_rest.len();
        if b < 3 {
            return Err(LgiError::Input(format!(
                "need at least 3 markers to sew, got {b}"
            )));
        }
        let diagonal = mesh.diagonal();
        let (bundles, shape_positions) = locate_bundles(dataset, markers_rest, config)?;
        let s1 = dataset.num_shapes() + 1;
        let tet_cfg = TetConfig {
            neighbours: config.tet_neighbours,
            max_tets: config.max_tets,
            min_quality: config.min_quality,
            max_edge: config.max_edge * diagonal,
        };
        let built: Vec<(BundleCloud, Vec<Tet>)> = (0..b)
            .into_par_iter()
            .map(|i| {
                let pos: Vec<DVec3> = (0..s1).map(|k| shape_positions[k * b + i]).collect();
                let cloud = build_cloud(
                    &pos,
                    config.prune_motion * diagonal,
                    config.duplicate_distance * diagonal,
                )?;
                let tets = generate_tets(&cloud.points, &tet_cfg);
                Ok((cloud, tets))
            })
            .collect::<Result<_>>()?;
        let (clouds, tets): (Vec<BundleCloud>, Vec<Vec<Tet>>) = built.into_iter().unzip();
        let given = if jaw.is_some() {
            dataset_given
        } else {
            sew_dataset
        };
        Model::assemble(
            (given, dataset_arc),
            jaw,
            markers_rest,
            config,
            (bundles, shape_positions),
            clouds,
            tets,
        )
    }

    /// The cheap part of a build, shared with loading a saved model: everything derived from
    /// the dataset, markers, clouds and tets (correspondences, grid indices, sewing weights).
    pub(crate) fn assemble(
        (given, dataset): (Arc<Dataset>, Arc<Dataset>),
        jaw: Option<(JawRig, Vec<JawParams>)>,
        markers_rest: &[DVec3],
        config: &BuildConfig,
        (bundles, shape_positions): (Vec<SurfacePoint>, Vec<DVec3>),
        clouds: Vec<BundleCloud>,
        tets: Vec<Vec<Tet>>,
    ) -> Result<Model> {
        let mesh = dataset.neutral();
        let b = markers_rest.len();
        let diagonal = mesh.diagonal();
        let indices: Vec<TetIndex> = clouds
            .par_iter()
            .zip(tets)
            .map(|(c, t)| TetIndex::new(c.points.clone(), t))
            .collect::<Result<_>>()?;
        let space = uvspace::build(mesh, &bundles)?;
        let graph = EdgeGraph::new(mesh, |t| {
            mesh.triangles[t]
                .iter()
                .all(|&v| space.contains(v as usize))
        });
        let uv_neighbours = SibsonWeights::new(&space.bundle_uv, &space.barriers)
            .map_err(|e| bundle_context(e, "bundle UV layout"))?
            .neighbours();
        let sew = SewContext {
            dataset: &dataset,
            bundles: &bundles,
            space: &space,
            graph: &graph,
            detour_ratio: config.detour_ratio,
            slack: DETOUR_SLACK * diagonal,
        };
        let neighbours = sew.filter_neighbours(uv_neighbours);
        let groups = clouds
            .par_iter()
            .zip(&neighbours)
            .map(|(c, nb)| alias_groups(c, nb, &shape_positions, b))
            .collect();
        let all: Vec<u32> = (0..b as u32).collect();
        let full_plan = Arc::new(sew.plan(&all)?);
        let support = sew.support()?;
        let jaw = match jaw {
            None => None,
            Some((rig, shape_thetas)) => {
                let bundle_weights = bundles
                    .iter()
                    .map(|b| rig.interpolate_weight(mesh.triangles[b.triangle as usize], b.bary))
                    .collect::<Result<_>>()?;
                Some(JawSetup {
                    rig,
                    shape_thetas,
                    bundle_weights,
                })
            }
        };
        Ok(Model {
            dataset: given,
            sew_dataset: dataset,
            jaw,
            config: config.clone(),
            markers_rest: markers_rest.to_vec(),
            bundles,
            diagonal,
            shape_positions,
            clouds,
            groups,
            indices,
            space,
            graph,
            neighbours,
            full_plan,
            support,
            plans: Mutex::new(HashMap::new()),
        })
    }

    fn plan_for(&self, present: &[u32]) -> Result<Arc<SewPlan>> {
        if present.len() == self.bundles.len() {
            return Ok(self.full_plan.clone());
        }
        let key = present.to_vec();
        if let Ok(cache) = self.plans.lock() {
            if let Some(p) = cache.get(&key) {
                return Ok(p.clone());
            }
        }
        let ctx = self.sew_context();
        let plan = Arc::new(ctx.plan_without(present, &self.full_plan, &self.support)?);
        if let Ok(mut cache) = self.plans.lock() {
            if cache.len() >= PLAN_CACHE {
                cache.clear();
            }
            cache.insert(key, plan.clone());
        }
        Ok(plan)
    }

    /// Solves one frame. `targets` (B) are bundle positions; a row with a NaN is missing.
    /// `jaw` is the frame's jaw pose for a model built with a jaw rig (`None` = rest).
    pub fn solve_frame(
        &self,
        targets: &[DVec3],
        previous: Option<&FrameState>,
        jaw: Option<JawParams>,
    ) -> Result<Frame> {
        let prep = self.prepare(targets, jaw)?;
        self.solve_prepared(&prep, previous.map(|p| p.choices.as_slice()))
    }

    /// Choice, then sewing of the unsmoothed choices, for a checked frame.
    fn solve_prepared(
        &self,
        prep: &Prepared,
        previous: Option<&[Option<Choice>]>,
    ) -> Result<Frame> {
        let choices = self.choose_all(prep, previous);
        let pieces = Pieces::from_choices(&choices);
        self.sew_frame(prep, choices, &pieces)
    }

    /// Checks a frame's targets and, with a jaw, unskins them for the lookup.
    fn prepare(&self, targets: &[DVec3], jaw: Option<JawParams>) -> Result<Prepared> {
        let b = self.bundles.len();
        if targets.len() != b {
            return Err(LgiError::Input(format!(
                "frame has {} bundles, the model has {b}",
                targets.len()
            )));
        }
        let mut present = Vec::with_capacity(b);
        let mut targets_clean = targets.to_vec();
        for (i, t) in targets.iter().enumerate() {
            if t.to_array().iter().any(|x| x.is_infinite()) {
                return Err(LgiError::Input(format!(
                    "bundle {i} has an infinite coordinate {t:?}"
                )));
            } else if t.is_nan() {
                targets_clean[i] = DVec3::NAN;
            } else {
                present.push(i as u32);
            }
        }
        if present.len() < 3 {
            return Err(LgiError::Input(format!(
                "only {} bundles present: at least 3 are needed",
                present.len()
            )));
        }
        // With a jaw, bundles are indexed in the unskinned space of the dataset's pieces.
        let theta = match (&self.jaw, jaw) {
            (None, Some(_)) => {
                return Err(LgiError::Input(
                    "a jaw pose was given but the model was built without a jaw rig".into(),
                ))
            }
            (Some(_), Some(t)) => {
                t.validate()?;
                Some(t)
            }
            _ => None,
        };
        let lookup_targets = match (&self.jaw, theta) {
            (Some(j), Some(t)) => {
                let mut out = targets_clean.clone();
                j.rig
                    .unskin_weighted(&targets_clean, &j.bundle_weights, t, &mut out)?;
                out
            }
            _ => targets_clean.clone(),
        };
        Ok(Prepared {
            targets: targets_clean,
            lookup: lookup_targets,
            present,
            theta,
        })
    }

    /// Every present bundle's choice (rayon over bundles).
    fn choose_all(
        &self,
        prep: &Prepared,
        previous: Option<&[Option<Choice>]>,
    ) -> Vec<Option<Choice>> {
        let b = self.bundles.len();
        let lookup_targets = &prep.lookup;
        let params = ChoiceParams {
            eps: self.config.containment_eps,
            projection_candidates: self.config.projection_candidates,
            hit_distance: self.config.prune_motion.max(self.config.duplicate_distance)
                * self.diagonal,
            ..ChoiceParams::default()
        };
        let temporal_weight = self.config.temporal_weight * self.diagonal * self.diagonal;
        let pure = pure_errors(&self.shape_positions, b, lookup_targets);
        (0..b)
            .into_par_iter()
            .map_init(Scratch::default, |scratch, i| {
                let t = lookup_targets[i];
                if t.is_nan() {
                    return None;
                }
                let scoring = Scoring {
                    shape_positions: &self.shape_positions,
                    num_bundles: b,
                    neighbours: &self.neighbours[i],
                    targets: lookup_targets,
                    previous: previous.and_then(|p| p.get(i)).and_then(|c| c.as_ref()),
                    temporal_weight,
                    pure_errors: &pure,
                };
                Some(choose(
                    &self.indices[i],
                    &self.clouds[i],
                    &self.groups[i],
                    t,
                    &scoring,
                    &params,
                    scratch,
                ))
            })
            .collect()
    }

    /// Blends `pieces`, reskins the jaw, and runs the residual pass.
    fn sew_frame(
        &self,
        prep: &Prepared,
        choices: Vec<Option<Choice>>,
        pieces: &Pieces,
    ) -> Result<Frame> {
        let b = self.bundles.len();
        let (targets_clean, theta) = (&prep.targets, prep.theta);
        let plan = self.plan_for(&prep.present)?;
        let mesh = self.dataset.neutral();
        let mut vertices = vec![DVec3::ZERO; mesh.num_vertices()];
        blend(
            &mesh.positions,
            self.sew_dataset.displacements(),
            &plan.weights,
            pieces,
            &mut vertices,
        );
        if let (Some(j), Some(t)) = (&self.jaw, theta) {
            let unskinned = vertices.clone();
            j.rig.skin(&unskinned, t, &mut vertices)?;
        }
        plan.residual.apply(
            &mesh.triangles,
            &self.bundles,
            &plan.weights,
            targets_clean,
            RESIDUAL_TOLERANCE * self.diagonal,
            &mut vertices,
        );
        if let Some(v) = vertices.iter().position(|p| !p.is_finite()) {
            return Err(LgiError::Input(format!(
                "the solve produced a non-finite vertex {v}: targets are probably far outside \
                 the dataset's range"
            )));
        }
        let bundle_positions: Vec<DVec3> = self
            .bundles
            .iter()
            .map(|sp| sp.evaluate(&mesh.triangles, &vertices))
            .collect();
        let residuals = (0..b)
            .map(|i| {
                if targets_clean[i].is_nan() {
                    0.0
                } else {
                    targets_clean[i].distance(bundle_positions[i])
                }
            })
            .collect();
        Ok(Frame {
            vertices,
            choices,
            residuals,
            bundle_positions,
        })
    }

    /// Solves a sequence. With `temporal`, frames are solved in order, each preferring tets
    /// that share shapes with the previous frame's choice; without, frames are independent and
    /// solved in parallel. `smooth_window` > 1 averages each bundle's shape weights over that
    /// many frames (centred) before sewing, in the jaw-unskinned space so jaw motion is not
    /// smoothed; the residual pass still interpolates every marker. `jaw` gives each frame's
    /// jaw pose for a model with a jaw rig. `on_frame` is called as frames finish (progress).
    pub fn solve_sequence(
        &self,
        frames: &[Vec<DVec3>],
        jaw: Option<&[JawParams]>,
        temporal: bool,
        smooth_window: usize,
        mut on_frame: impl FnMut(usize),
    ) -> Result<Vec<Frame>> {
        if let Some(j) = jaw {
            if j.len() != frames.len() {
                return Err(LgiError::Input(format!(
                    "{} jaw poses for {} frames",
                    j.len(),
                    frames.len()
                )));
            }
        }
        let theta = |f: usize| jaw.map(|j| j[f]);
        let prepared: Vec<Prepared> = frames
            .iter()
            .enumerate()
            .map(|(f, t)| self.prepare(t, theta(f)).map_err(|e| frame_context(e, f)))
            .collect::<Result<_>>()?;
        if smooth_window <= 1 {
            // Frame by frame: each frame is finished (and reported) before the next starts.
            let mut out: Vec<Frame> = Vec::with_capacity(frames.len());
            if temporal {
                for (f, prep) in prepared.iter().enumerate() {
                    let previous = out.last().map(|fr| fr.choices.as_slice());
                    let frame = self.solve_prepared(prep, previous);
                    out.push(frame.map_err(|e| frame_context(e, f))?);
                    on_frame(f);
                }
            } else {
                out = prepared
                    .par_iter()
                    .enumerate()
                    .map(|(f, prep)| {
                        self.solve_prepared(prep, None)
                            .map_err(|e| frame_context(e, f))
                    })
                    .collect::<Result<_>>()?;
                (0..out.len()).for_each(&mut on_frame);
            }
            return Ok(out);
        }
        let choices: Vec<Vec<Option<Choice>>> = if temporal {
            let mut out: Vec<Vec<Option<Choice>>> = Vec::with_capacity(frames.len());
            for prep in &prepared {
                let previous = out.last().map(|c| c.as_slice());
                out.push(self.choose_all(prep, previous));
            }
            out
        } else {
            prepared
                .par_iter()
                .map(|p| self.choose_all(p, None))
                .collect()
        };
        let pieces = smooth_choices(&choices, smooth_window);
        let mut out = Vec::with_capacity(frames.len());
        for (f, (prep, (ch, pc))) in prepared
            .iter()
            .zip(choices.into_iter().zip(&pieces))
            .enumerate()
        {
            out.push(
                self.sew_frame(prep, ch, pc)
                    .map_err(|e| frame_context(e, f))?,
            );
            on_frame(f);
        }
        Ok(out)
    }

    fn sew_context(&self) -> SewContext<'_> {
        SewContext {
            dataset: &self.sew_dataset,
            bundles: &self.bundles,
            space: &self.space,
            graph: &self.graph,
            detour_ratio: self.config.detour_ratio,
            slack: DETOUR_SLACK * self.diagonal,
        }
    }

    /// Bundle surface positions on a mesh with the neutral's topology.
    pub fn bundle_positions(&self, positions: &[DVec3]) -> Result<Vec<DVec3>> {
        let nv = self.dataset.num_vertices();
        if positions.len() != nv {
            return Err(LgiError::Input(format!(
                "mesh has {} vertices, the model's neutral has {nv}",
                positions.len()
            )));
        }
        let tris = &self.dataset.neutral().triangles;
        Ok(self
            .bundles
            .iter()
            .map(|sp| sp.evaluate(tris, positions))
            .collect())
    }

    /// The dataset the model was built from.
    pub fn dataset(&self) -> &Dataset {
        &self.dataset
    }
    /// The jaw setup, when the model was built with a jaw rig.
    pub fn jaw(&self) -> Option<&JawSetup> {
        self.jaw.as_ref()
    }
    /// The dataset, shared.
    pub fn dataset_shared(&self) -> Arc<Dataset> {
        self.dataset.clone()
    }
    /// The build configuration.
    pub fn config(&self) -> &BuildConfig {
        &self.config
    }
    /// Marker rest positions as given.
    pub fn markers_rest(&self) -> &[DVec3] {
        &self.markers_rest
    }
    /// Bundles' closest points on the neutral.
    pub fn bundles(&self) -> &[SurfacePoint] {
        &self.bundles
    }
    /// Number of bundles B.
    pub fn num_bundles(&self) -> usize {
        self.bundles.len()
    }
    /// Bounding-box diagonal of the neutral.
    pub fn diagonal(&self) -> f64 {
        self.diagonal
    }
    /// Natural neighbours of each bundle (UV Delaunay, not across holes).
    pub fn neighbours(&self) -> &[Vec<u32>] {
        &self.neighbours
    }
    /// Full sewing weights (V × B, every bundle present).
    pub fn sew_weights(&self) -> &SparseWeights {
        &self.full_plan.weights
    }
    /// The sewing space (chart UVs, proxies, barriers).
    pub fn sewing_space(&self) -> &SewingSpace {
        &self.space
    }
    /// Per-bundle cloud, tet and memory statistics.
    pub fn bundle_stats(&self) -> Vec<BundleStats> {
        self.clouds
            .iter()
            .zip(&self.indices)
            .map(|(c, i)| BundleStats {
                points: c.points.len(),
                tets: i.num_tets(),
                index_bytes: i.memory_bytes(),
            })
            .collect()
    }
    /// Clouds of all bundles.
    pub fn clouds(&self) -> &[BundleCloud] {
        &self.clouds
    }
    /// Alias groups of every bundle's cloud points (see [`alias_groups`]).
    pub fn alias_groups(&self) -> &[Vec<AliasGroups>] {
        &self.groups
    }
    /// Tet indices of all bundles.
    pub fn indices(&self) -> &[TetIndex] {
        &self.indices
    }
    /// Bundle surface positions on every shape, `(S + 1) × B` (index `[k * B + n]`, shape id
    /// 0 the neutral): what [`Scoring`] needs to score candidates outside a full solve.
    pub fn shape_positions(&self) -> &[DVec3] {
        &self.shape_positions
    }
}

/// Zig-zag allowance of mesh-edge paths at short range (relative to the diagonal).
const DETOUR_SLACK: f64 = 2e-3;

/// What computing sewing weights needs from a model.
struct SewContext<'a> {
    dataset: &'a Dataset,
    bundles: &'a [SurfacePoint],
    space: &'a SewingSpace,
    graph: &'a EdgeGraph,
    detour_ratio: f64,
    slack: f64,
}

impl SewContext<'_> {
    /// Sewing weights for the present bundles: Sibson weights in UV for sewn vertices (minus
    /// detours around holes), copied from the proxy for the others; plus the residual pass.
    fn plan(&self, present: &[u32]) -> Result<SewPlan> {
        let nv = self.dataset.num_vertices();
        let sewn: Vec<usize> = (0..nv).filter(|&v| self.space.contains(v)).collect();
        let w = self.rows_for(present, &sewn)?;
        let mut row_of = vec![usize::MAX; nv];
        for (r, &v) in sewn.iter().enumerate() {
            row_of[v] = r;
        }
        self.plan_from(present, |v| w.row(row_of[v]))
    }

    /// Sibson rows (minus detours) of `vertices` for the present bundles; columns are bundle
    /// indices.
    fn rows_for(&self, present: &[u32], vertices: &[usize]) -> Result<SparseWeights> {
        let sp = self.space;
        let sites: Vec<_> = present.iter().map(|&i| sp.bundle_uv[i as usize]).collect();
        let sib = SibsonWeights::new(&sites, &sp.barriers)?;
        let queries: Vec<_> = vertices.iter().map(|&v| sp.vertex_uv[v]).collect();
        let mut w = self.drop_detours(sib.weights(&queries), vertices, present);
        for c in &mut w.cols {
            *c = present[*c as usize];
        }
        w.num_cols = self.bundles.len();
        Ok(w)
    }

    /// The plan whose row for vertex v is `sewn_row(proxy[v])` (a sewn vertex is its own
    /// proxy), with the residual pass for the present bundles.
    fn plan_from<'w>(
        &self,
        present: &[u32],
        sewn_row: impl Fn(usize) -> (&'w [u32], &'w [f64]),
    ) -> Result<SewPlan> {
        let nv = self.dataset.num_vertices();
        let mut weights = SparseWeights {
            row_start: Vec::with_capacity(nv + 1),
            cols: Vec::new(),
            vals: Vec::new(),
            num_cols: self.bundles.len(),
        };
        weights.row_start.push(0);
        for v in 0..nv {
            let (cols, vals) = sewn_row(self.space.proxy[v] as usize);
            weights.cols.extend_from_slice(cols);
            weights.vals.extend_from_slice(vals);
            weights.row_start.push(weights.cols.len() as u32);
        }
        let tris = &self.dataset.neutral().triangles;
        let residual = ResidualPass::new(tris, self.bundles, &weights, present)?;
        Ok(SewPlan { weights, residual })
    }

    /// Natural neighbours of every sewn vertex among all bundles, with no barrier or detour.
    fn support(&self) -> Result<SparseWeights> {
        let sp = self.space;
        let sib = SibsonWeights::new(&sp.bundle_uv, &[])?;
        let queries: Vec<_> = (0..self.dataset.num_vertices())
            .filter(|&v| sp.contains(v))
            .map(|v| sp.vertex_uv[v])
            .collect();
        Ok(sib.weights(&queries))
    }

    /// The plan for `present` bundles derived from the full plan: removing a site changes the
    /// natural-neighbour weights only of points that had it as a natural neighbour, so only
    /// those rows are recomputed (same rules as [`plan`](Self::plan)).
    fn plan_without(
        &self,
        present: &[u32],
        full: &SewPlan,
        support: &SparseWeights,
    ) -> Result<SewPlan> {
        let (dataset, sp) = (self.dataset, self.space);
        let mut missing = vec![true; self.bundles.len()];
        for &b in present {
            missing[b as usize] = false;
        }
        let nv = dataset.num_vertices();
        let sewn: Vec<usize> = (0..nv).filter(|&v| sp.contains(v)).collect();
        let touches = |cols: &[u32]| cols.iter().any(|&c| missing[c as usize]);
        let affected: Vec<usize> = sewn
            .iter()
            .enumerate()
            .filter(|&(r, &v)| touches(support.row(r).0) || touches(full.weights.row(v).0))
            .map(|(_, &v)| v)
            .collect();
        let mut new_row = vec![usize::MAX; nv];
        for (r, &v) in affected.iter().enumerate() {
            new_row[v] = r;
        }
        let recomputed = self.rows_for(present, &affected)?;
        // A proxy has the same row as its own vertex in the full plan.
        self.plan_from(present, |v| match new_row[v] {
            usize::MAX => full.weights.row(v),
            r => recomputed.row(r),
        })
    }

    /// Removes the weights whose surface path detours around a hole; rows renormalised (a
    /// row that would lose everything keeps its weights).
    fn drop_detours(&self, w: SparseWeights, sewn: &[usize], present: &[u32]) -> SparseWeights {
        if !self.detour_ratio.is_finite() {
            return w;
        }
        let mesh = self.dataset.neutral();
        let pos = &mesh.positions;
        // Column-wise: the sewn rows that each site touches.
        let mut by_site: Vec<Vec<usize>> = vec![Vec::new(); present.len()];
        for r in 0..w.num_rows() {
            for &c in w.row(r).0 {
                by_site[c as usize].push(r);
            }
        }
        let dropped: Vec<Vec<usize>> = by_site
            .par_iter()
            .enumerate()
            .map(|(c, rows)| {
                let b = &self.bundles[present[c] as usize];
                let origin = b.position(mesh);
                let reach = rows
                    .iter()
                    .map(|&r| origin.distance(pos[sewn[r]]))
                    .fold(0.0, f64::max);
                let radius = self.detour_ratio * reach + self.slack;
                let dist = self.graph.distances_from(mesh, b, radius);
                rows.iter()
                    .copied()
                    .filter(|&r| {
                        let v = sewn[r];
                        let straight = origin.distance(pos[v]);
                        dist.get(&(v as u32))
                            .is_none_or(|&d| is_detour(d, straight, self.detour_ratio, self.slack))
                    })
                    .collect()
            })
            .collect();
        let mut drop_set: Vec<Vec<u32>> = vec![Vec::new(); w.num_rows()];
        for (c, rows) in dropped.iter().enumerate() {
            for &r in rows {
                drop_set[r].push(c as u32);
            }
        }
        let mut out = SparseWeights {
            row_start: vec![0],
            cols: Vec::with_capacity(w.cols.len()),
            vals: Vec::with_capacity(w.vals.len()),
            num_cols: w.num_cols,
        };
        for (r, drops) in drop_set.iter().enumerate() {
            let (cols, vals) = w.row(r);
            let kept: f64 = cols
                .iter()
                .zip(vals)
                .filter(|(c, _)| !drops.contains(c))
                .map(|(_, v)| v)
                .sum();
            if drops.is_empty() || kept <= 0.0 {
                out.cols.extend_from_slice(cols);
                out.vals.extend_from_slice(vals);
            } else {
                for (&c, &v) in cols.iter().zip(vals) {
                    if !drops.contains(&c) {
                        out.cols.push(c);
                        out.vals.push(v / kept);
                    }
                }
            }
            out.row_start.push(out.cols.len() as u32);
        }
        out
    }

    /// Drops neighbour pairs whose surface path detours around a hole.
    fn filter_neighbours(&self, neighbours: Vec<Vec<u32>>) -> Vec<Vec<u32>> {
        if !self.detour_ratio.is_finite() {
            return neighbours;
        }
        let mesh = self.dataset.neutral();
        neighbours
            .into_par_iter()
            .enumerate()
            .map(|(i, nb)| {
                let b = &self.bundles[i];
                let origin = b.position(mesh);
                let reach = nb
                    .iter()
                    .map(|&j| origin.distance(self.bundles[j as usize].position(mesh)))
                    .fold(0.0, f64::max);
                let radius = self.detour_ratio * reach + self.slack;
                let dist = self.graph.distances_from(mesh, b, radius);
                nb.into_iter()
                    .filter(|&j| {
                        let bj = &self.bundles[j as usize];
                        let pj = bj.position(mesh);
                        let path = mesh.triangles[bj.triangle as usize]
                            .iter()
                            .filter_map(|v| {
                                dist.get(v)
                                    .map(|d| d + mesh.positions[*v as usize].distance(pj))
                            })
                            .fold(f64::INFINITY, f64::min);
                        !is_detour(path, origin.distance(pj), self.detour_ratio, self.slack)
                    })
                    .collect()
            })
            .collect()
    }
}

/// The dataset whose pieces are indexed: with a jaw, every shape's jaw motion is unskinned,
/// `s*_k = T(θ_k)⁻¹ (x0 + s_k) − x0` (Eq. 2), so clouds hold expression without jaw rotation.
pub(crate) fn unskinned_dataset(
    dataset: &Arc<Dataset>,
    jaw: Option<&(JawRig, Vec<JawParams>)>,
) -> Result<Arc<Dataset>> {
    let Some((rig, thetas)) = jaw else {
        return Ok(dataset.clone());
    };
    if rig.num_vertices() != dataset.num_vertices() {
        return Err(LgiError::Input(format!(
            "jaw rig has {} weights, the dataset {} vertices",
            rig.num_vertices(),
            dataset.num_vertices()
        )));
    }
    if thetas.len() != dataset.num_shapes() {
        return Err(LgiError::Input(format!(
            "{} shape jaw poses for {} shapes",
            thetas.len(),
            dataset.num_shapes()
        )));
    }
    let mesh = dataset.neutral();
    let disp = rig.unskin_shapes(&mesh.positions, dataset.displacements(), thetas)?;
    Ok(Arc::new(Dataset::new(
        mesh.clone(),
        disp,
        dataset.names().to_vec(),
    )?))
}

/// Bundles' closest points on the neutral and their positions on every shape.
pub(crate) fn locate_bundles(
    dataset: &Dataset,
    markers_rest: &[DVec3],
    config: &BuildConfig,
) -> Result<(Vec<SurfacePoint>, Vec<DVec3>)> {
    let mesh = dataset.neutral();
    let bundles: Vec<SurfacePoint> = correspond(
        mesh,
        markers_rest,
        config.surface_tolerance * mesh.diagonal(),
    )?
    .into_iter()
    .map(|(sp, _)| sp)
    .collect();
    let positions = shape_bundle_positions(dataset, &bundles);
    Ok((bundles, positions))
}

/// Bundle positions on every shape, `(S + 1) × B` with shape id 0 the neutral.
fn shape_bundle_positions(dataset: &Dataset, bundles: &[SurfacePoint]) -> Vec<DVec3> {
    let mesh = dataset.neutral();
    let b = bundles.len();
    let s1 = dataset.num_shapes() + 1;
    let mut out = vec![DVec3::ZERO; s1 * b];
    out.par_chunks_mut(b).enumerate().for_each(|(k, row)| {
        for (i, sp) in bundles.iter().enumerate() {
            let tri = mesh.triangles[sp.triangle as usize];
            let mut p = DVec3::ZERO;
            for (&v, &w) in tri.iter().zip(&sp.bary) {
                let v = v as usize;
                let d = if k == 0 {
                    DVec3::ZERO
                } else {
                    dataset.displacement(k - 1, v)
                };
                p += (mesh.positions[v] + d) * w;
            }
            row[i] = p;
        }
    });
    out
}

fn frame_context(e: LgiError, frame: usize) -> LgiError {
    match e {
        LgiError::Input(m) => LgiError::Input(format!("frame {frame}: {m}")),
        other => other,
    }
}

fn bundle_context(e: LgiError, what: &str) -> LgiError {
    match e {
        LgiError::Input(m) => LgiError::Input(format!("{what}: {m}")),
        other => other,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Mesh;
    use glam::DVec2;

    /// A wavy n×n grid patch with UVs = xy and a few smooth shapes.
    fn patch(n: usize) -> Dataset {
        let mut positions = Vec::new();
        let mut uvs = Vec::new();
        for y in 0..n {
            for x in 0..n {
                let (u, v) = (x as f64 / (n - 1) as f64, y as f64 / (n - 1) as f64);
                positions.push(DVec3::new(u, v, 0.1 * (3.0 * u).sin() * (2.0 * v).cos()));
                uvs.push(DVec2::new(u, v));
            }
        }
        let mut triangles = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let a = (y * n + x) as u32;
                let (b, c, d) = (a + 1, a + n as u32 + 1, a + n as u32);
                triangles.push([a, b, c]);
                triangles.push([a, c, d]);
            }
        }
        let mesh = Mesh {
            positions: positions.clone(),
            uv_triangles: triangles.clone(),
            triangles,
            uvs,
        };
        let shapes = (0..6)
            .map(|k| {
                let f = k as f64 + 1.0;
                let pos = positions
                    .iter()
                    .map(|p| *p + DVec3::new(0.0, 0.0, 0.05 * (f * p.x + 0.3 * f * p.y).sin()))
                    .collect();
                (format!("s{k}"), pos)
            })
            .collect();
        Dataset::from_shape_positions(mesh, shapes).unwrap()
    }

    #[test]
    fn plan_for_missing_bundles_equals_the_plan_built_from_scratch() {
        let data = patch(24);
        let mut markers = Vec::new();
        let mut s = 3u64;
        for _ in 0..30 {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = 0.05 + 0.9 * ((s >> 11) as f64 / (1u64 << 53) as f64);
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let v = 0.05 + 0.9 * ((s >> 11) as f64 / (1u64 << 53) as f64);
            markers.push(DVec3::new(u, v, 0.1 * (3.0 * u).sin() * (2.0 * v).cos()));
        }
        let model = Model::build(&data, &markers, &BuildConfig::default()).unwrap();
        let ctx = model.sew_context();
        for missing in [vec![0u32], vec![3, 17], vec![5, 6, 7, 29]] {
            let present: Vec<u32> = (0..30).filter(|b| !missing.contains(b)).collect();
            let fresh = ctx.plan(&present).unwrap();
            let derived = ctx
                .plan_without(&present, &model.full_plan, &model.support)
                .unwrap();
            assert_eq!(
                fresh.weights.row_start, derived.weights.row_start,
                "{missing:?}"
            );
            assert_eq!(fresh.weights.cols, derived.weights.cols, "{missing:?}");
            for (a, b) in fresh.weights.vals.iter().zip(&derived.weights.vals) {
                assert!((a - b).abs() <= 1e-12, "{missing:?}: {a} vs {b}");
            }
        }
    }
}
