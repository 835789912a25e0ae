//! The LGI model: everything precomputed from a dataset and a marker layout (bundle clouds,
//! tets and their grid indices, UV sewing weights), immutable after build and `Send + Sync`,
//! so frames are solved with `&self` in parallel (rayon over bundles, then over vertices).

use crate::choose::{
    alias_groups, choose, AliasGroups, Choice, ChoiceParams, FrameErrors, Scoring, Scratch,
};
use crate::cloud::{build_cloud, BundleCloud};
use crate::correspond::correspond;
use crate::dataset::Dataset;
use crate::error::{LgiError, Result};
use crate::geodesic::{is_detour, EdgeGraph, FieldCache};
use crate::jaw::{JawBins, JawParams, JawRig};
use crate::mesh::{Mesh, SurfacePoint};
use crate::sew::{BlendInput, BundleTargets, Pieces, ResidualPass};
use crate::sibson::SibsonWeights;
use crate::smooth::smooth_choices_in_bins;
use crate::sparse::SparseWeights;
use crate::tet_index::TetIndex;
use crate::tets::{generate_tets, Tet, TetConfig};
use crate::uvspace::{self, SewingSpace};
use glam::DVec3;
use rayon::prelude::*;
use std::borrow::Cow;
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
    /// The jaw bin whose clouds the frame was looked up in (0 for an unbinned model).
    pub bin: usize,
}

/// A solved frame without its vertices (those went to the caller's buffer, see
/// [`Model::solve_sequence_into`]).
#[derive(Debug, Clone)]
pub struct FrameInfo {
    /// Per bundle: the chosen geometry (`None` for a missing bundle).
    pub choices: Vec<Option<Choice>>,
    /// Per bundle: distance from target to reconstructed surface point (0 for missing).
    pub residuals: Vec<f64>,
    /// Per bundle: the reconstructed surface position (for missing bundles, the estimate).
    pub bundle_positions: Vec<DVec3>,
    /// The jaw bin whose clouds the frame was looked up in (0 for an unbinned model).
    pub bin: usize,
}

impl Frame {
    fn from_parts(vertices: Vec<DVec3>, info: FrameInfo) -> Frame {
        Frame {
            vertices,
            choices: info.choices,
            residuals: info.residuals,
            bundle_positions: info.bundle_positions,
            bin: info.bin,
        }
    }
}

/// What the next frame needs from the previous one.
#[derive(Debug, Clone, Default)]
pub struct FrameState {
    /// Previous choices per bundle (dataset shape ids, as in [`Frame::choices`]).
    pub choices: Vec<Option<Choice>>,
    /// The previous frame's jaw bin ([`Frame::bin`]): kept while the opening allows, and the
    /// choices are only preferred within the same bin. `None`: no bin hysteresis.
    pub bin: Option<usize>,
}

/// Jaw articulation of a model (paper Eq. 2): the rig, each dataset shape's jaw parameters
/// (its jaw motion is unskinned before indexing) and each bundle's jaw weight.
#[derive(Debug, Clone)]
pub struct JawSetup {
    /// What the model was built with: the rig, the shapes' jaw poses and the bins.
    pub input: JawInput,
    /// Jaw weight of every bundle (barycentric blend of its triangle's vertex weights).
    pub bundle_weights: Vec<f64>,
}

/// The jaw part of a build: the rig, every dataset shape's jaw pose, and optionally bins of
/// jaw opening (each with its own point clouds, shapes unskinned to the bin's reference).
#[derive(Debug, Clone)]
pub struct JawInput {
    /// Two-bone skinning rig.
    pub rig: JawRig,
    /// Jaw parameters θ_k of every dataset shape.
    pub shape_thetas: Vec<JawParams>,
    /// Jaw-opening bins (`None`: unbinned).
    pub bins: Option<JawBins>,
}

/// The per-shape lookup structures of one jaw bin (the only one when unbinned): its shapes
/// re-posed to the bin's reference pose, their bundle positions, clouds, alias groups and
/// tet indices. Shape ids inside are local: 0 the bin's neutral, `j ≥ 1` the dataset shape
/// `members[j - 1]`.
#[derive(Debug)]
pub struct Lookup {
    /// The bin's reference pose; `None` for an unbinned model (shapes at the rest pose, and
    /// no re-posing of frames beyond the jaw unskinning).
    reference: Option<JawParams>,
    members: Vec<u32>,
    /// Dataset shape id (0 = neutral) → local id, `u32::MAX` for a non-member.
    local_of: Vec<u32>,
    /// Neutral (skinned to the reference) and member displacements the pieces come from.
    data: Arc<Dataset>,
    shape_positions: Vec<DVec3>,
    clouds: Vec<BundleCloud>,
    groups: Vec<Vec<AliasGroups>>,
    indices: Vec<TetIndex>,
}

impl Lookup {
    /// The bin's reference pose (`None` when the model is unbinned).
    pub fn reference(&self) -> Option<JawParams> {
        self.reference
    }
    /// Dataset shape index (0-based) of each local shape id `j ≥ 1` (`members[j - 1]`).
    pub fn members(&self) -> &[u32] {
        &self.members
    }
    /// Clouds of all bundles (local shape ids).
    pub fn clouds(&self) -> &[BundleCloud] {
        &self.clouds
    }
    /// Alias groups of every bundle's cloud points.
    pub fn alias_groups(&self) -> &[Vec<AliasGroups>] {
        &self.groups
    }
    /// Tet indices of all bundles.
    pub fn indices(&self) -> &[TetIndex] {
        &self.indices
    }
    /// Bundle positions on every local shape, `(members + 1) × B`.
    pub fn shape_positions(&self) -> &[DVec3] {
        &self.shape_positions
    }
    /// Dataset shape id (0 = neutral, k ≥ 1 dataset shape k − 1) of a local shape id.
    pub fn global_id(&self, local: u32) -> u32 {
        match local {
            0 => 0,
            j => self.members[j as usize - 1] + 1,
        }
    }
    /// A choice with its shape ids mapped from local to dataset ids.
    fn globalize(&self, mut c: Choice) -> Choice {
        for s in &mut c.shapes {
            *s = self.global_id(*s);
        }
        c
    }
    /// Choices in dataset ids mapped to this bin's local ids (a non-member shape gets an id
    /// no candidate has); borrowed unchanged for an unbinned model.
    fn localize<'a>(&self, choices: &'a [Option<Choice>]) -> Cow<'a, [Option<Choice>]> {
        if self.reference.is_none() {
            return Cow::Borrowed(choices);
        }
        let map = |s: u32| self.local_of.get(s as usize).copied().unwrap_or(u32::MAX);
        Cow::Owned(
            choices
                .iter()
                .map(|c| {
                    c.map(|mut c| {
                        for s in &mut c.shapes {
                            *s = map(*s);
                        }
                        c
                    })
                })
                .collect(),
        )
    }
}

/// What one lookup is built from: its reference pose, member shapes and re-posed dataset.
pub(crate) struct LookupSource {
    reference: Option<JawParams>,
    members: Vec<u32>,
    data: Arc<Dataset>,
}

impl LookupSource {
    /// Number of local shapes (members, not counting the neutral).
    pub(crate) fn num_shapes(&self) -> usize {
        self.members.len()
    }
    /// The re-posed dataset (bin neutral and member displacements).
    pub(crate) fn data(&self) -> &Dataset {
        &self.data
    }
}

/// A lookup's source with its built clouds and tets (what a saved model stores).
pub(crate) struct LookupParts {
    pub(crate) source: LookupSource,
    pub(crate) shape_positions: Vec<DVec3>,
    pub(crate) clouds: Vec<BundleCloud>,
    pub(crate) tets: Vec<Vec<Tet>>,
}

/// A frame's targets after the checks: as given (NaN rows missing) and as looked up (jaw
/// unskinned), with the present bundles and the jaw pose.
struct Prepared {
    targets: Vec<DVec3>,
    lookup: Vec<DVec3>,
    present: Vec<u32>,
    theta: Option<JawParams>,
    bin: usize,
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
    jaw: Option<JawSetup>,
    config: BuildConfig,
    markers_rest: Vec<DVec3>,
    bundles: Vec<SurfacePoint>,
    diagonal: f64,
    /// One per jaw bin (one when unbinned); everything else is shared by the bins.
    lookups: Vec<Lookup>,
    space: SewingSpace,
    graph: EdgeGraph,
    neighbours: Vec<Vec<u32>>,
    full_plan: Arc<SewPlan>,
    /// Every sewn vertex's natural neighbours among all bundles, before barriers and detours
    /// (rows of the sewn vertices in order): which rows a missing bundle can change.
    support: SparseWeights,
    plans: Mutex<HashMap<Vec<u32>, Arc<SewPlan>>>,
    /// Bundles' surface-distance fields, reused by the plans of new missing sets.
    fields: FieldCache,
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
    /// (rig, the dataset shapes' jaw parameters — their jaw motion is unskinned first — and
    /// optional jaw-opening bins, each with its own clouds).
    pub fn build_shared(
        dataset: Arc<Dataset>,
        markers_rest: &[DVec3],
        config: &BuildConfig,
        jaw: Option<JawInput>,
    ) -> Result<Model> {
        config.validate()?;
        let sources = lookup_sources(&dataset, jaw.as_ref())?;
        let mesh = dataset.neutral();
        let b = markers_rest.len();
        if b < 3 {
            return Err(LgiError::Input(format!(
                "need at least 3 markers to sew, got {b}"
            )));
        }
        let diagonal = mesh.diagonal();
        let bundles = locate_bundles(mesh, markers_rest, config)?;
        let tet_cfg = TetConfig {
            neighbours: config.tet_neighbours,
            max_tets: config.max_tets,
            min_quality: config.min_quality,
            max_edge: config.max_edge * diagonal,
        };
        let mut parts = Vec::with_capacity(sources.len());
        for source in sources {
            let shape_positions = shape_bundle_positions(&source.data, &bundles);
            let s1 = source.num_shapes() + 1;
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
            let (clouds, tets) = built.into_iter().unzip();
            parts.push(LookupParts {
                source,
                shape_positions,
                clouds,
                tets,
            });
        }
        Model::assemble(dataset, jaw, markers_rest, config, bundles, parts)
    }

    /// The cheap part of a build, shared with loading a saved model: everything derived from
    /// the dataset, markers, clouds and tets (grid indices, sewing weights, alias groups).
    pub(crate) fn assemble(
        dataset: Arc<Dataset>,
        jaw: Option<JawInput>,
        markers_rest: &[DVec3],
        config: &BuildConfig,
        bundles: Vec<SurfacePoint>,
        parts: Vec<LookupParts>,
    ) -> Result<Model> {
        let mesh = dataset.neutral();
        let b = markers_rest.len();
        let diagonal = mesh.diagonal();
        let space = uvspace::build(mesh, &bundles)?;
        let graph = EdgeGraph::new(mesh, |t| {
            mesh.triangles[t]
                .iter()
                .all(|&v| space.contains(v as usize))
        });
        let uv_neighbours = SibsonWeights::new(&space.bundle_uv, &space.barriers)
            .map_err(|e| bundle_context(e, "bundle UV layout"))?
            .neighbours();
        let fields = FieldCache::default();
        let sew = SewContext {
            dataset: &dataset,
            bundles: &bundles,
            space: &space,
            graph: &graph,
            fields: &fields,
            detour_ratio: config.detour_ratio,
            slack: DETOUR_SLACK * diagonal,
        };
        let neighbours = sew.filter_neighbours(uv_neighbours);
        let mut lookups = Vec::with_capacity(parts.len());
        for part in parts {
            let indices: Vec<TetIndex> = part
                .clouds
                .par_iter()
                .zip(part.tets)
                .map(|(c, t)| TetIndex::new(c.points.clone(), t))
                .collect::<Result<_>>()?;
            let groups = part
                .clouds
                .par_iter()
                .zip(&neighbours)
                .map(|(c, nb)| alias_groups(c, nb, &part.shape_positions, b))
                .collect();
            let src = part.source;
            let mut local_of = vec![u32::MAX; dataset.num_shapes() + 1];
            local_of[0] = 0;
            for (j, &k) in src.members.iter().enumerate() {
                local_of[k as usize + 1] = j as u32 + 1;
            }
            lookups.push(Lookup {
                reference: src.reference,
                members: src.members,
                local_of,
                data: src.data,
                shape_positions: part.shape_positions,
                clouds: part.clouds,
                groups,
                indices,
            });
        }
        let all: Vec<u32> = (0..b as u32).collect();
        let full_plan = Arc::new(sew.plan(&all)?);
        let support = sew.support()?;
        let jaw = match jaw {
            None => None,
            Some(input) => {
                let bundle_weights = bundles
                    .iter()
                    .map(|b| {
                        input
                            .rig
                            .interpolate_weight(mesh.triangles[b.triangle as usize], b.bary)
                    })
                    .collect::<Result<_>>()?;
                Some(JawSetup {
                    input,
                    bundle_weights,
                })
            }
        };
        Ok(Model {
            dataset,
            jaw,
            config: config.clone(),
            markers_rest: markers_rest.to_vec(),
            bundles,
            diagonal,
            lookups,
            space,
            graph,
            neighbours,
            full_plan,
            support,
            plans: Mutex::new(HashMap::new()),
            fields,
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
    /// With jaw bins, `previous.bin` is kept while the opening allows (hysteresis), and the
    /// previous choices are preferred only when the frame stays in that bin.
    pub fn solve_frame(
        &self,
        targets: &[DVec3],
        previous: Option<&FrameState>,
        jaw: Option<JawParams>,
    ) -> Result<Frame> {
        let prep = self.prepare(targets, jaw, previous.and_then(|p| p.bin))?;
        let lookup = &self.lookups[prep.bin];
        let previous = previous
            .filter(|p| p.bin.is_none_or(|b| b == prep.bin))
            .map(|p| lookup.localize(&p.choices));
        self.solve_prepared(&prep, previous.as_deref())
    }

    /// As [`Model::solve_frame`] in a given jaw bin (no previous frame): what a frame would
    /// give if hysteresis had kept it in `bin`.
    pub fn solve_frame_in_bin(
        &self,
        targets: &[DVec3],
        jaw: Option<JawParams>,
        bin: usize,
    ) -> Result<Frame> {
        if bin >= self.lookups.len() {
            return Err(LgiError::Input(format!(
                "jaw bin {bin} out of range: the model has {}",
                self.lookups.len()
            )));
        }
        let mut prep = self.prepare(targets, jaw, None)?;
        if prep.bin != bin {
            prep.bin = bin;
            prep.lookup = self.lookup_targets(&prep.targets, prep.theta, bin)?;
        }
        self.solve_prepared(&prep, None)
    }

    /// Choice, then sewing of the unsmoothed choices, for a checked frame.
    fn solve_prepared(
        &self,
        prep: &Prepared,
        previous: Option<&[Option<Choice>]>,
    ) -> Result<Frame> {
        let mut vertices = vec![DVec3::ZERO; self.dataset.num_vertices()];
        let info = self.solve_prepared_into(prep, previous, &mut vertices)?;
        Ok(Frame::from_parts(vertices, info))
    }

    /// [`solve_prepared`](Self::solve_prepared) writing the vertices into `out` (V).
    fn solve_prepared_into(
        &self,
        prep: &Prepared,
        previous: Option<&[Option<Choice>]>,
        out: &mut [DVec3],
    ) -> Result<FrameInfo> {
        let choices = self.choose_all(prep, previous);
        let pieces = Pieces::from_choices(&choices);
        self.sew_frame_into(prep, choices, &pieces, out)
    }

    /// Checks a frame's targets, picks its jaw bin and, with a jaw, maps them into the bin's
    /// space for the lookup.
    fn prepare(
        &self,
        targets: &[DVec3],
        jaw: Option<JawParams>,
        previous_bin: Option<usize>,
    ) -> Result<Prepared> {
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
        let bin = match self.jaw.as_ref().and_then(|j| j.input.bins.as_ref()) {
            Some(bins) => bins.select(theta.unwrap_or(JawParams::ZERO).open, previous_bin),
            None => 0,
        };
        let lookup = self.lookup_targets(&targets_clean, theta, bin)?;
        Ok(Prepared {
            targets: targets_clean,
            lookup,
            present,
            theta,
            bin,
        })
    }

    /// Targets in bin `bin`'s space: unskinned with the frame's pose, then skinned to the
    /// bin's reference pose, `T(θ_b) T(θ)⁻¹` with each bundle's jaw weight.
    fn lookup_targets(
        &self,
        targets: &[DVec3],
        theta: Option<JawParams>,
        bin: usize,
    ) -> Result<Vec<DVec3>> {
        let Some(j) = &self.jaw else {
            return Ok(targets.to_vec());
        };
        let mut out = targets.to_vec();
        if let Some(t) = theta {
            j.input
                .rig
                .unskin_weighted(targets, &j.bundle_weights, t, &mut out)?;
        }
        if let Some(r) = self.lookups[bin].reference {
            let unskinned = out.clone();
            j.input
                .rig
                .skin_weighted(&unskinned, &j.bundle_weights, r, &mut out)?;
        }
        Ok(out)
    }

    /// Every present bundle's choice (rayon over bundles).
    fn choose_all(
        &self,
        prep: &Prepared,
        previous: Option<&[Option<Choice>]>,
    ) -> Vec<Option<Choice>> {
        let targets = &prep.lookup;
        let errors = self.frame_errors(prep.bin, targets);
        (0..self.bundles.len())
            .into_par_iter()
            .map_init(Scratch::default, |scratch, i| {
                if targets[i].is_nan() {
                    return None;
                }
                let previous = previous.and_then(|p| p.get(i)).and_then(|c| c.as_ref());
                Some(self.choose_bundle(prep.bin, i, targets, &errors, previous, scratch))
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
    /// of `previous` (the bundle's previous choice, bin-local ids). What a solve does for each
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
        let lk = &self.lookups[bin];
        let scoring = Scoring {
            shape_positions: &lk.shape_positions,
            num_bundles: self.bundles.len(),
            neighbours: &self.neighbours[i],
            targets,
            previous,
            temporal_weight: self.temporal_penalty(),
            pure_errors: &errors.pure,
            distances: &errors.distances,
        };
        choose(
            &lk.indices[i],
            &lk.clouds[i],
            &lk.groups[i],
            targets[i],
            &scoring,
            &self.choice_params(),
            scratch,
        )
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
    /// residual pass — one pass over the vertices, written into `out` (V).
    fn sew_frame_into(
        &self,
        prep: &Prepared,
        choices: Vec<Option<Choice>>,
        pieces: &Pieces,
        out: &mut [DVec3],
    ) -> Result<FrameInfo> {
        let b = self.bundles.len();
        let (targets_clean, theta) = (&prep.targets, prep.theta);
        let plan = self.plan_for(&prep.present)?;
        let mesh = self.dataset.neutral();
        let lk = &self.lookups[prep.bin];
        let input = BlendInput::new(
            &lk.data.neutral().positions,
            lk.data.displacements(),
            &plan.weights,
            pieces,
        );
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
        let bad = match &jaw_map {
            Some(m) => plan.residual.sew(&input, |v, p| m.apply(v, p), &at, out),
            None => plan.residual.sew(&input, |_, p| p, &at, out),
        };
        if let Some(v) = bad {
            return Err(LgiError::Input(format!(
                "the solve produced a non-finite vertex {v}: targets are probably far outside \
                 the dataset's range"
            )));
        }
        let bundle_positions: Vec<DVec3> = self
            .bundles
            .iter()
            .map(|sp| sp.evaluate(&mesh.triangles, out))
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
        let choices = if lk.reference.is_some() {
            choices
                .into_iter()
                .map(|c| c.map(|c| lk.globalize(c)))
                .collect()
        } else {
            choices
        };
        Ok(FrameInfo {
            choices,
            residuals,
            bundle_positions,
            bin: prep.bin,
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
        on_frame: impl FnMut(usize),
    ) -> Result<Vec<Frame>> {
        let nv = self.dataset.num_vertices();
        let mut vertices = vec![DVec3::ZERO; frames.len() * nv];
        let infos = self.solve_sequence_into(
            frames,
            jaw,
            temporal,
            smooth_window,
            &mut vertices,
            on_frame,
        )?;
        Ok(infos
            .into_iter()
            .zip(vertices.chunks(nv.max(1)))
            .map(|(info, v)| Frame::from_parts(v.to_vec(), info))
            .collect())
    }

    /// As [`Model::solve_sequence`], writing frame f's vertices into
    /// `vertices[f * V..(f + 1) * V]` (a caller's buffer, e.g. a numpy array: no per-frame
    /// allocation) and returning the rest of each frame.
    pub fn solve_sequence_into(
        &self,
        frames: &[Vec<DVec3>],
        jaw: Option<&[JawParams]>,
        temporal: bool,
        smooth_window: usize,
        vertices: &mut [DVec3],
        mut on_frame: impl FnMut(usize),
    ) -> Result<Vec<FrameInfo>> {
        let nv = self.dataset.num_vertices();
        if vertices.len() != frames.len() * nv {
            return Err(LgiError::Input(format!(
                "output buffer holds {} vertices, {} frames of {nv} need {}",
                vertices.len(),
                frames.len(),
                frames.len() * nv
            )));
        }
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
        // Bins are picked in order: in a temporal solve a frame keeps the previous frame's bin
        // while its opening allows (hysteresis).
        let mut prepared: Vec<Prepared> = Vec::with_capacity(frames.len());
        for (f, t) in frames.iter().enumerate() {
            let previous_bin = prepared.last().filter(|_| temporal).map(|p| p.bin);
            let prep = self
                .prepare(t, theta(f), previous_bin)
                .map_err(|e| frame_context(e, f))?;
            prepared.push(prep);
        }
        // An empty mesh still gets one (empty) slot per frame.
        let slots = vertices.chunks_mut(nv.max(1));
        if smooth_window <= 1 {
            // Frame by frame: each frame is finished (and reported) before the next starts.
            let mut out: Vec<FrameInfo> = Vec::with_capacity(frames.len());
            if temporal {
                // Frame f + 1's choice needs only frame f's choices, not its vertices: it runs
                // beside frame f's sewing (rayon::join), which fills the gaps of either stage.
                let mut current = prepared.first().map(|p| self.choose_all(p, None));
                for (f, (prep, slot)) in prepared.iter().zip(slots).enumerate() {
                    let choices = current.take().unwrap_or_default();
                    let pieces = Pieces::from_choices(&choices);
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
            } else {
                out = prepared
                    .par_iter()
                    .zip(vertices.par_chunks_mut(nv.max(1)))
                    .enumerate()
                    .map(|(f, (prep, slot))| {
                        self.solve_prepared_into(prep, None, slot)
                            .map_err(|e| frame_context(e, f))
                    })
                    .collect::<Result<_>>()?;
                (0..out.len()).for_each(&mut on_frame);
            }
            return Ok(out);
        }
        let choices: Vec<Vec<Option<Choice>>> = if temporal {
            // Local shape ids: the previous choices count only within the same bin.
            let mut out: Vec<Vec<Option<Choice>>> = Vec::with_capacity(frames.len());
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
        let mut out = Vec::with_capacity(frames.len());
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

    fn sew_context(&self) -> SewContext<'_> {
        SewContext {
            dataset: &self.dataset,
            bundles: &self.bundles,
            space: &self.space,
            graph: &self.graph,
            fields: &self.fields,
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
    /// Per-bundle cloud, tet and memory statistics, summed over the jaw bins.
    pub fn bundle_stats(&self) -> Vec<BundleStats> {
        let mut out = vec![
            BundleStats {
                points: 0,
                tets: 0,
                index_bytes: 0,
            };
            self.bundles.len()
        ];
        for lk in &self.lookups {
            for ((o, c), i) in out.iter_mut().zip(&lk.clouds).zip(&lk.indices) {
                o.points += c.points.len();
                o.tets += i.num_tets();
                o.index_bytes += i.memory_bytes();
            }
        }
        out
    }
    /// The per-bin lookup structures (one when the model is unbinned).
    pub fn lookups(&self) -> &[Lookup] {
        &self.lookups
    }
    /// Clouds of all bundles (of the first jaw bin; the only one when unbinned).
    pub fn clouds(&self) -> &[BundleCloud] {
        &self.lookups[0].clouds
    }
    /// Alias groups of every bundle's cloud points (see [`alias_groups`]; first jaw bin).
    pub fn alias_groups(&self) -> &[Vec<AliasGroups>] {
        &self.lookups[0].groups
    }
    /// Tet indices of all bundles (first jaw bin).
    pub fn indices(&self) -> &[TetIndex] {
        &self.lookups[0].indices
    }
    /// Bundle surface positions on every shape, `(S + 1) × B` (index `[k * B + n]`, shape id
    /// 0 the neutral; first jaw bin): what [`Scoring`] needs to score candidates outside a
    /// full solve.
    pub fn shape_positions(&self) -> &[DVec3] {
        &self.lookups[0].shape_positions
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
    fields: &'a FieldCache,
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
                // A cached field may reach farther: a vertex beyond `radius` is a detour
                // either way (its path exceeds ratio × reach + slack ≥ ratio × straight + slack).
                let field = self.fields.field(present[c], radius, |r| {
                    self.graph.distances_from(mesh, b, r)
                });
                rows.iter()
                    .copied()
                    .filter(|&r| {
                        let v = sewn[r];
                        let straight = origin.distance(pos[v]);
                        field
                            .distances
                            .get(&(v as u32))
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

/// The dataset whose pieces are indexed when unbinned: with a jaw, every shape's jaw motion is
/// unskinned, `s*_k = T(θ_k)⁻¹ (x0 + s_k) − x0` (Eq. 2), so clouds hold expression without jaw
/// rotation.
fn unskinned_dataset(
    dataset: &Arc<Dataset>,
    rig: &JawRig,
    thetas: &[JawParams],
) -> Result<Arc<Dataset>> {
    let mesh = dataset.neutral();
    let disp = rig.unskin_shapes(&mesh.positions, dataset.displacements(), thetas)?;
    Ok(Arc::new(Dataset::new(
        mesh.clone(),
        disp,
        dataset.names().to_vec(),
    )?))
}

/// What each lookup is built from: without a jaw the dataset as given; with a jaw and no bins
/// every shape unskinned to the rest pose; with bins, per bin its member shapes re-posed to the
/// bin's reference, `T(θ_b) T(θ_k)⁻¹ (x0 + s_k)`, relative to the bin's neutral `T(θ_b) x0`.
pub(crate) fn lookup_sources(
    dataset: &Arc<Dataset>,
    jaw: Option<&JawInput>,
) -> Result<Vec<LookupSource>> {
    let all = || (0..dataset.num_shapes() as u32).collect();
    let Some(j) = jaw else {
        return Ok(vec![LookupSource {
            reference: None,
            members: all(),
            data: dataset.clone(),
        }]);
    };
    let (rig, thetas) = (&j.rig, &j.shape_thetas);
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
    let Some(bins) = &j.bins else {
        return Ok(vec![LookupSource {
            reference: None,
            members: all(),
            data: unskinned_dataset(dataset, rig, thetas)?,
        }]);
    };
    bins.validate()?;
    let mesh = dataset.neutral();
    (0..bins.num_bins())
        .map(|b| {
            let members = bins.members(b, thetas);
            if members.is_empty() {
                let (lo, hi) = bins.core_range(b);
                return Err(LgiError::Input(format!(
                    "jaw bin {b} (opening {lo} to {hi} rad, overlap {}) has no member shapes: \
                     no dataset shape opens the jaw that far; change the bin edges",
                    bins.overlap
                )));
            }
            let reference = bins.reference(b);
            let (base, disp) = rig.repose_shapes(
                &mesh.positions,
                dataset.displacements(),
                thetas,
                &members,
                reference,
            )?;
            let names = members
                .iter()
                .map(|&k| dataset.names()[k as usize].clone())
                .collect();
            let neutral = Mesh {
                positions: base,
                ..mesh.clone()
            };
            Ok(LookupSource {
                reference: Some(reference),
                members,
                data: Arc::new(Dataset::new(neutral, disp, names)?),
            })
        })
        .collect()
}

/// Bundles' closest points on the neutral.
pub(crate) fn locate_bundles(
    mesh: &Mesh,
    markers_rest: &[DVec3],
    config: &BuildConfig,
) -> Result<Vec<SurfacePoint>> {
    Ok(correspond(
        mesh,
        markers_rest,
        config.surface_tolerance * mesh.diagonal(),
    )?
    .into_iter()
    .map(|(sp, _)| sp)
    .collect())
}

/// Bundle positions on every shape, `(S + 1) × B` with shape id 0 the neutral.
pub(crate) fn shape_bundle_positions(dataset: &Dataset, bundles: &[SurfacePoint]) -> Vec<DVec3> {
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

    /// Same sparsity pattern, values within `tol` (0: equal).
    fn assert_weights_match(a: &SparseWeights, b: &SparseWeights, tol: f64, missing: &[u32]) {
        assert_eq!(a.row_start, b.row_start, "{missing:?}");
        assert_eq!(a.cols, b.cols, "{missing:?}");
        for (x, y) in a.vals.iter().zip(&b.vals) {
            assert!((x - y).abs() <= tol, "{missing:?}: {x} vs {y}");
        }
    }

    /// `n` markers on the surface of [`patch`] at seeded pseudo-random (u, v) in [0.05, 0.95]².
    fn patch_markers(seed: u64, n: usize) -> Vec<DVec3> {
        let mut s = seed;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            0.05 + 0.9 * ((s >> 11) as f64 / (1u64 << 53) as f64)
        };
        (0..n)
            .map(|_| {
                let (u, v) = (next(), next());
                DVec3::new(u, v, 0.1 * (3.0 * u).sin() * (2.0 * v).cos())
            })
            .collect()
    }

    #[test]
    fn plan_for_missing_bundles_equals_the_plan_built_from_scratch() {
        let data = patch(24);
        let markers = patch_markers(3, 30);
        let model = Model::build(&data, &markers, &BuildConfig::default()).unwrap();
        let ctx = model.sew_context();
        for missing in [vec![0u32], vec![3, 17], vec![5, 6, 7, 29]] {
            let present: Vec<u32> = (0..30).filter(|b| !missing.contains(b)).collect();
            let fresh = ctx.plan(&present).unwrap();
            let derived = ctx
                .plan_without(&present, &model.full_plan, &model.support)
                .unwrap();
            assert_weights_match(&fresh.weights, &derived.weights, 1e-12, &missing);
        }
    }

    /// A cached distance field may reach farther than a plan asks: plans for a sequence of
    /// missing sets built with the model's warm cache equal those built with an empty one
    /// exactly, with a detour ratio tight enough that edge-path zigzag drops weights.
    #[test]
    fn plans_from_cached_distance_fields_equal_plans_from_fresh_fields() {
        let data = patch(24);
        let markers = patch_markers(11, 30);
        let config = BuildConfig {
            detour_ratio: 1.02,
            ..BuildConfig::default()
        };
        let model = Model::build(&data, &markers, &config).unwrap();
        let loose = Model::build(&data, &markers, &BuildConfig::default()).unwrap();
        assert!(
            model.full_plan.weights.cols.len() < loose.full_plan.weights.cols.len(),
            "the tight ratio drops weights"
        );
        assert!(!model.fields.is_empty(), "the full plan filled the cache");
        for missing in [
            vec![4u32],
            vec![4, 5],
            vec![3, 4, 5, 6],
            vec![4],
            vec![20, 21, 22],
        ] {
            let present: Vec<u32> = (0..30).filter(|b| !missing.contains(b)).collect();
            let warm = model
                .sew_context()
                .plan_without(&present, &model.full_plan, &model.support)
                .unwrap();
            let empty = FieldCache::default();
            let cold = SewContext {
                fields: &empty,
                ..model.sew_context()
            }
            .plan_without(&present, &model.full_plan, &model.support)
            .unwrap();
            assert_weights_match(&warm.weights, &cold.weights, 0.0, &missing);
        }
    }

    /// The patch's jaw: a hinge about the frame's first axis (x for the identity) through a
    /// pivot behind and above the patch, weight 1 below y = 0.35, 0 above y = 0.65, linear
    /// between.
    fn patch_rig(data: &Dataset, frame: glam::DMat3) -> JawRig {
        let weights = data
            .neutral()
            .positions
            .iter()
            .map(|p| ((0.65 - p.y) / 0.3).clamp(0.0, 1.0))
            .collect();
        JawRig::with_frame(DVec3::new(0.5, 0.8, -0.6), weights, frame).unwrap()
    }

    /// Dataset shape jaw openings of [`jaw_patch`] (radians).
    const OPENINGS: [f64; 10] = [0.0, 0.0, 0.0, 0.2, 0.2, 0.3, 0.3, 0.4, 0.5, 0.5];

    /// The patch's expressions, each at its opening from [`OPENINGS`] (skinned with the rig),
    /// plus markers only where the jaw weight is constant over their triangle (so a marker's
    /// own weight skins it exactly like its triangle's vertices).
    fn jaw_patch() -> (Dataset, JawRig, Vec<JawParams>, Vec<DVec3>) {
        jaw_patch_in(glam::DMat3::IDENTITY)
    }

    /// [`jaw_patch`] with the rig's axes the columns of `frame`.
    fn jaw_patch_in(frame: glam::DMat3) -> (Dataset, JawRig, Vec<JawParams>, Vec<DVec3>) {
        let base = patch(24);
        let rig = patch_rig(&base, frame);
        let x0 = &base.neutral().positions;
        let mut shapes = Vec::new();
        let mut thetas = Vec::new();
        for (k, &open) in OPENINGS.iter().enumerate() {
            let theta = JawParams {
                open,
                ..JawParams::ZERO
            };
            let expr: Vec<DVec3> = (0..x0.len())
                .map(|v| x0[v] + base.displacement(k % base.num_shapes(), v))
                .collect();
            let mut posed = expr.clone();
            rig.skin(&expr, theta, &mut posed).unwrap();
            shapes.push((format!("e{k}_open{open}"), posed));
            thetas.push(theta);
        }
        let data = Dataset::from_shape_positions(base.neutral().clone(), shapes).unwrap();
        let mut markers = Vec::new();
        for &y in &[0.08, 0.17, 0.26, 0.74, 0.83, 0.92] {
            for &x in &[0.1, 0.3, 0.5, 0.7, 0.9] {
                let (u, v) = (x + 0.013 * y, y);
                markers.push(DVec3::new(u, v, 0.1 * (3.0 * u).sin() * (2.0 * v).cos()));
            }
        }
        (data, rig, thetas, markers)
    }

    fn binned_model(edges: Vec<f64>, overlap: f64) -> Result<(Model, Dataset, Vec<JawParams>)> {
        let (data, rig, thetas, markers) = jaw_patch();
        let model = jaw_model(
            &data,
            &markers,
            rig,
            &thetas,
            Some(JawBins { edges, overlap }),
        )?;
        Ok((model, data, thetas))
    }

    /// A model of `data` (default config) with the jaw `rig`, the shapes' poses and `bins`.
    fn jaw_model(
        data: &Dataset,
        markers: &[DVec3],
        rig: JawRig,
        thetas: &[JawParams],
        bins: Option<JawBins>,
    ) -> Result<Model> {
        let jaw = JawInput {
            rig,
            shape_thetas: thetas.to_vec(),
            bins,
        };
        Model::build_shared(
            Arc::new(data.clone()),
            markers,
            &BuildConfig::default(),
            Some(jaw),
        )
    }

    fn shape_mesh(data: &Dataset, k: usize) -> Vec<DVec3> {
        let x0 = &data.neutral().positions;
        (0..x0.len())
            .map(|v| x0[v] + data.displacement(k, v))
            .collect()
    }

    /// The old sewing, one stage after another over every vertex: blend, jaw maps, residual
    /// pass (the reference of the fused one-pass sewing).
    fn staged_sewing(model: &Model, prep: &Prepared, pieces: &Pieces) -> Vec<DVec3> {
        let plan = model.plan_for(&prep.present).unwrap();
        let lk = &model.lookups[prep.bin];
        let mesh = model.dataset.neutral();
        let mut v = vec![DVec3::ZERO; mesh.num_vertices()];
        crate::sew::blend(
            &lk.data.neutral().positions,
            lk.data.displacements(),
            &plan.weights,
            pieces,
            &mut v,
        );
        if let Some(j) = &model.jaw {
            if let Some(r) = lk.reference {
                let c = v.clone();
                j.input.rig.unskin(&c, r, &mut v).unwrap();
            }
            if let Some(t) = prep.theta {
                let c = v.clone();
                j.input.rig.skin(&c, t, &mut v).unwrap();
            }
        }
        plan.residual.apply(
            &mesh.triangles,
            &model.bundles,
            &plan.weights,
            &prep.targets,
            RESIDUAL_TOLERANCE * model.diagonal,
            &mut v,
        );
        v
    }

    #[test]
    fn fused_sewing_equals_blend_then_jaw_maps_then_residual_pass_bit_for_bit() {
        let (binned, data, thetas) = binned_model(vec![0.0, 0.25, 0.5], 0.06).unwrap();
        let plain =
            Model::build(&patch(24), binned.markers_rest(), &BuildConfig::default()).unwrap();
        let mut checked = 0;
        for (model, jaw) in [(&binned, true), (&plain, false)] {
            for k in [2usize, 5, 8] {
                let mesh = shape_mesh(if jaw { &data } else { plain.dataset() }, k % 6);
                let mut targets = model.bundle_positions(&mesh).unwrap();
                // Off the dataset (noise), and one marker missing in the second case.
                for (i, t) in targets.iter_mut().enumerate() {
                    *t += DVec3::new(0.003, -0.002, 0.004) * ((i * 7 + k) % 5) as f64;
                }
                for missing in [None, Some(3usize)] {
                    let mut t = targets.clone();
                    if let Some(m) = missing {
                        t[m] = DVec3::NAN;
                    }
                    let theta = jaw.then(|| thetas[k]);
                    let prep = model.prepare(&t, theta, None).unwrap();
                    let choices = model.choose_all(&prep, None);
                    let pieces = Pieces::from_choices(&choices);
                    let mut fused = vec![DVec3::ZERO; model.dataset.num_vertices()];
                    model
                        .sew_frame_into(&prep, choices, &pieces, &mut fused)
                        .unwrap();
                    assert_eq!(fused, staged_sewing(model, &prep, &pieces), "k {k}");
                    checked += 1;
                }
            }
        }
        assert_eq!(checked, 12);
    }

    #[test]
    fn every_member_shape_of_every_bin_is_reproduced_at_its_own_jaw_pose() {
        let (model, data, thetas) = binned_model(vec![0.0, 0.25, 0.5], 0.06).unwrap();
        assert_eq!(model.lookups()[0].members(), &[0, 1, 2, 3, 4, 5, 6]);
        assert_eq!(model.lookups()[1].members(), &[3, 4, 5, 6, 7, 8, 9]);
        let diag = model.diagonal();
        for (bin, lk) in model.lookups().iter().enumerate() {
            for &k in lk.members() {
                let k = k as usize;
                let mesh = shape_mesh(&data, k);
                let targets = model.bundle_positions(&mesh).unwrap();
                let frame = model
                    .solve_frame_in_bin(&targets, Some(thetas[k]), bin)
                    .unwrap();
                assert_eq!(frame.bin, bin);
                for (i, c) in frame.choices.iter().enumerate() {
                    let c = c.unwrap();
                    let w: f64 = (0..4)
                        .filter(|&j| c.shapes[j] == k as u32 + 1)
                        .map(|j| c.weights[j])
                        .sum();
                    // The target matches the cloud point up to the f32 storage of shapes.
                    assert!(w > 1.0 - 1e-6, "bin {bin} shape {k} bundle {i}: {c:?}");
                }
                // f32 storage of the re-posed displacements (like the dataset's) bounds the
                // round trip T(θ_k) T(θ_b)⁻¹ (T(θ_b) T(θ_k)⁻¹ x) at ~1e-7 of the motion.
                let err = (0..mesh.len())
                    .filter(|&v| model.sewing_space().contains(v))
                    .map(|v| frame.vertices[v].distance(mesh[v]))
                    .fold(0.0, f64::max);
                assert!(err <= 1e-6 * diag, "bin {bin} shape {k}: {err:e}");
                assert!(frame.residuals.iter().all(|&r| r <= 1e-9 * diag));
            }
        }
    }

    #[test]
    fn one_bin_holding_every_shape_matches_the_unbinned_model_to_f32_round_off() {
        let (binned, data, thetas) = binned_model(vec![0.0, 0.5], 0.0).unwrap();
        let (_, rig, _, markers) = jaw_patch();
        let plain = jaw_model(&data, &markers, rig, &thetas, None).unwrap();
        // Frames between shapes: blends of two shapes' meshes at an intermediate pose.
        for (a, b, t) in [(0, 5, 0.3), (3, 8, 0.6), (1, 7, 0.5)] {
            let (ma, mb) = (shape_mesh(&data, a), shape_mesh(&data, b));
            let mesh: Vec<DVec3> = ma.iter().zip(&mb).map(|(p, q)| p.lerp(*q, t)).collect();
            let targets = plain.bundle_positions(&mesh).unwrap();
            let theta = JawParams {
                open: (1.0 - t) * thetas[a].open + t * thetas[b].open,
                ..JawParams::ZERO
            };
            let f0 = plain.solve_frame(&targets, None, Some(theta)).unwrap();
            let f1 = binned.solve_frame(&targets, None, Some(theta)).unwrap();
            let err = f0
                .vertices
                .iter()
                .zip(&f1.vertices)
                .map(|(p, q)| p.distance(*q))
                .fold(0.0, f64::max);
            assert!(err <= 1e-5 * plain.diagonal(), "{a}-{b}: {err:e}");
        }
    }

    #[test]
    fn bin_selection_follows_a_hand_written_sequence_with_hysteresis() {
        let bins = JawBins {
            edges: vec![0.0, 0.2, 0.4, 0.6],
            overlap: 0.05,
        };
        bins.validate().unwrap();
        // (opening, expected bin) in order; each frame sees the previous frame's bin.
        let script = [
            (0.0, 0), // core of bin 0
            (0.19, 0),
            (0.23, 0), // past edge 0.2 but inside bin 0's overlap (to 0.25): kept
            (0.26, 1), // outside: core bin 1
            (0.17, 1), // inside bin 1's overlap (from 0.15): kept
            (0.14, 0), // outside: core bin 0
            (-0.3, 0), // below the first edge: clamped to bin 0
            (0.9, 2),  // above the last edge: clamped to the last bin
            (0.36, 2), // inside bin 2's overlap (from 0.35): kept
            (0.34, 1), // outside: core bin 1
            (0.4, 1),  // on an edge, inside bin 1's range: kept
            (0.46, 2), // outside bin 1's overlap (to 0.45)
        ];
        let mut previous = None;
        for (f, &(open, want)) in script.iter().enumerate() {
            let got = bins.select(open, previous);
            assert_eq!(got, want, "frame {f}, opening {open}");
            previous = Some(got);
        }
        // Without a previous frame: the core bin (an edge belongs to the bin above it).
        assert_eq!(bins.select(0.2, None), 1);
        assert_eq!(bins.select(0.6, None), 2);
    }

    #[test]
    fn a_temporal_solve_picks_bins_by_hysteresis_and_reports_dataset_shape_ids() {
        let (model, data, _) = binned_model(vec![0.0, 0.25, 0.5], 0.06).unwrap();
        let opens = [0.0, 0.2, 0.29, 0.32, 0.2, 0.18, 0.5];
        let want = [0, 0, 0, 1, 1, 0, 1];
        let frames: Vec<Vec<DVec3>> = opens
            .iter()
            .enumerate()
            .map(|(f, _)| {
                let k = [0, 3, 5, 7, 4, 1, 9][f];
                model.bundle_positions(&shape_mesh(&data, k)).unwrap()
            })
            .collect();
        let poses: Vec<JawParams> = opens
            .iter()
            .map(|&open| JawParams {
                open,
                ..JawParams::ZERO
            })
            .collect();
        for window in [0, 3] {
            let out = model
                .solve_sequence(&frames, Some(&poses), true, window, |_| {})
                .unwrap();
            let bins: Vec<usize> = out.iter().map(|f| f.bin).collect();
            assert_eq!(bins, want, "window {window}");
            for (f, fr) in out.iter().enumerate() {
                let members = model.lookups()[fr.bin].members();
                for c in fr.choices.iter().flatten() {
                    for j in 0..4 {
                        let s = c.shapes[j];
                        assert!(c.weights[j] == 0.0 || s == 0 || members.contains(&(s - 1)));
                    }
                }
                assert!(
                    fr.residuals.iter().all(|&r| r <= 1e-9 * model.diagonal()),
                    "{f}"
                );
            }
        }
        // Frame 1 is shape 3 at its own pose (0.2): it chooses that shape (id 4), purely.
        let out = model
            .solve_sequence(&frames[..2], Some(&poses[..2]), true, 0, |_| {})
            .unwrap();
        for c in out[1].choices.iter().flatten() {
            let w: f64 = (0..4)
                .filter(|&j| c.shapes[j] == 4)
                .map(|j| c.weights[j])
                .sum();
            assert!(w > 1.0 - 1e-6, "{c:?}");
        }
        // solve_frame with a FrameState applies the same rule.
        let state = FrameState {
            choices: out[1].choices.clone(),
            bin: Some(out[1].bin),
        };
        let fr = model
            .solve_frame(&frames[2], Some(&state), Some(poses[2]))
            .unwrap();
        assert_eq!(fr.bin, 0);
    }

    #[test]
    fn binned_model_save_load_round_trip_gives_identical_frames() {
        let (model, data, thetas) = binned_model(vec![0.0, 0.25, 0.5], 0.06).unwrap();
        let path = std::env::temp_dir().join(format!("lgi-bins-{}.lgi", std::process::id()));
        crate::io::model_file::save(&model, &path).unwrap();
        let loaded = crate::io::model_file::load(&path);
        std::fs::remove_file(&path).unwrap();
        let loaded = loaded.unwrap();
        assert_eq!(
            loaded.jaw().unwrap().input.bins,
            model.jaw().unwrap().input.bins
        );
        assert_eq!(loaded.lookups().len(), 2);
        let frames: Vec<Vec<DVec3>> = [0, 3, 5, 7, 9]
            .iter()
            .map(|&k| model.bundle_positions(&shape_mesh(&data, k)).unwrap())
            .collect();
        let poses: Vec<JawParams> = [0, 3, 5, 7, 9].iter().map(|&k| thetas[k]).collect();
        let a = model
            .solve_sequence(&frames, Some(&poses), true, 3, |_| {})
            .unwrap();
        let b = loaded
            .solve_sequence(&frames, Some(&poses), true, 3, |_| {})
            .unwrap();
        for (fa, fb) in a.iter().zip(&b) {
            assert_eq!(fa.vertices, fb.vertices);
            assert_eq!(fa.choices, fb.choices);
            assert_eq!(fa.bin, fb.bin);
        }
    }

    /// A jaw frame tilted 0.3 rad about (1, 2, -1), built from the axis-angle formula.
    fn tilted_frame() -> glam::DMat3 {
        glam::DMat3::from_axis_angle(DVec3::new(1.0, 2.0, -1.0).normalize(), 0.3)
    }

    #[test]
    fn a_tilted_frame_jaw_model_reproduces_its_shapes_and_its_frame_survives_save_load() {
        let frame = tilted_frame();
        let (data, rig, thetas, markers) = jaw_patch_in(frame);
        let bins = JawBins {
            edges: vec![0.0, 0.25, 0.5],
            overlap: 0.06,
        };
        let model = jaw_model(&data, &markers, rig, &thetas, Some(bins)).unwrap();
        assert_eq!(model.jaw().unwrap().input.rig.frame, frame);
        let diag = model.diagonal();
        for k in [0usize, 3, 5, 7, 9] {
            let mesh = shape_mesh(&data, k);
            let targets = model.bundle_positions(&mesh).unwrap();
            let fr = model.solve_frame(&targets, None, Some(thetas[k])).unwrap();
            let err = (0..mesh.len())
                .filter(|&v| model.sewing_space().contains(v))
                .map(|v| fr.vertices[v].distance(mesh[v]))
                .fold(0.0, f64::max);
            assert!(err <= 1e-6 * diag, "shape {k}: {err:e}");
            assert!(fr.residuals.iter().all(|&r| r <= 1e-9 * diag));
        }
        let path = std::env::temp_dir().join(format!("lgi-frame-{}.lgi", std::process::id()));
        crate::io::model_file::save(&model, &path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let loaded = crate::io::model_file::load(&path);
        // A frame that is no rotation (its first axis doubled), checksum fixed: a format error.
        let cols: Vec<u8> = frame
            .to_cols_array()
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let at = bytes
            .windows(cols.len())
            .position(|w| w == &cols[..])
            .unwrap();
        let mut bad = bytes.clone();
        for i in 0..3 {
            let x = f64::from_le_bytes(bad[at + 8 * i..at + 8 * i + 8].try_into().unwrap());
            bad[at + 8 * i..at + 8 * i + 8].copy_from_slice(&(2.0 * x).to_le_bytes());
        }
        let sum = crate::io::model_file::checksum(&bad[28..]);
        bad[20..28].copy_from_slice(&sum.to_le_bytes());
        std::fs::write(&path, bad).unwrap();
        let corrupt = crate::io::model_file::load(&path);
        std::fs::remove_file(&path).unwrap();
        let loaded = loaded.unwrap();
        assert_eq!(
            loaded.jaw().unwrap().input.rig,
            model.jaw().unwrap().input.rig
        );
        let frames: Vec<Vec<DVec3>> = [0, 4, 8]
            .iter()
            .map(|&k| model.bundle_positions(&shape_mesh(&data, k)).unwrap())
            .collect();
        let poses: Vec<JawParams> = [0, 4, 8].iter().map(|&k| thetas[k]).collect();
        let a = model
            .solve_sequence(&frames, Some(&poses), true, 0, |_| {})
            .unwrap();
        let b = loaded
            .solve_sequence(&frames, Some(&poses), true, 0, |_| {})
            .unwrap();
        for (fa, fb) in a.iter().zip(&b) {
            assert_eq!(fa.vertices, fb.vertices);
        }
        match corrupt {
            Err(LgiError::ModelFormat { message, .. }) => {
                assert!(message.contains("jaw frame"), "{message}")
            }
            other => panic!("expected a format error, got {other:?}"),
        }
    }

    #[test]
    fn a_version_2_file_still_loads_as_an_unbinned_model() {
        let (data, rig, thetas, markers) = jaw_patch();
        let model = jaw_model(&data, &markers, rig, &thetas, None).unwrap();
        let path = std::env::temp_dir().join(format!("lgi-v2-{}.lgi", std::process::id()));
        crate::io::model_file::save(&model, &path).unwrap();
        // Version 2 is version 3 without the trailing bins section (a u64 0 when unbinned).
        let bytes = std::fs::read(&path).unwrap();
        let payload = &bytes[28..bytes.len() - 8];
        assert_eq!(&bytes[bytes.len() - 8..], &[0u8; 8]);
        let mut v2 = bytes[..8].to_vec();
        v2.extend_from_slice(&2u32.to_le_bytes());
        v2.extend_from_slice(&(payload.len() as u64).to_le_bytes());
        v2.extend_from_slice(&crate::io::model_file::checksum_v2(payload).to_le_bytes());
        v2.extend_from_slice(payload);
        std::fs::write(&path, v2).unwrap();
        let loaded = crate::io::model_file::load(&path);
        std::fs::remove_file(&path).unwrap();
        let loaded = loaded.unwrap();
        assert!(loaded.jaw().unwrap().input.bins.is_none());
        let t = model
            .bundle_positions(&shape_mesh(model.dataset(), 5))
            .unwrap();
        let a = model.solve_frame(&t, None, Some(thetas[5])).unwrap();
        let b = loaded.solve_frame(&t, None, Some(thetas[5])).unwrap();
        assert_eq!(a.vertices, b.vertices);
    }

    #[test]
    fn invalid_bin_specs_are_rejected_with_named_errors() {
        let cases: [(Vec<f64>, f64, &str); 6] = [
            (vec![0.1], 0.0, "at least 2 edges"),
            (vec![0.0, f64::NAN], 0.0, "edge 1 must be finite"),
            (vec![0.0, 0.3, 0.2], 0.0, "edge 2 (0.2) <= edge 1 (0.3)"),
            (vec![0.0, 0.5], -0.1, "overlap must be finite and >= 0"),
            (vec![0.0, 0.5], f64::INFINITY, "overlap must be finite"),
            (
                vec![0.0, 0.1, 0.15, 0.5],
                0.0,
                "jaw bin 1 (opening 0.1 to 0.15 rad",
            ),
        ];
        for (edges, overlap, want) in cases {
            let e = binned_model(edges.clone(), overlap).unwrap_err();
            assert!(matches!(e, LgiError::Input(_)), "{edges:?}: {e:?}");
            assert!(e.to_string().contains(want), "{edges:?}: {e}");
        }
    }
}
