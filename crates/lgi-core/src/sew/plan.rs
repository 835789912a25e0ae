//! Sewing plans: for one set of present bundles, the V × B natural-neighbour weights (Sibson
//! in UV, minus paths that detour around a hole) and the residual pass, built once for all
//! bundles and per set of missing bundles on demand (derived from the full plan, cached).
//!
//! A missing set's plan costs about the same however many distinct sets a take has: each
//! bundle's rows with that bundle alone missing are computed the first time it goes missing
//! and kept ([`WithoutOne`]); a set's plan reuses them wherever no other missing bundle is a
//! natural neighbour of the row, and recomputes only rows that two missing bundles share.

use super::context::SewContext;
use super::memo::{Gone, GoneMap, RowMemo, Rows};
use super::{BlendInput, BundleTargets, Pieces, ResidualPass, ShapeSpans};
use crate::dataset::Dataset;
use crate::error::{LgiError, Result};
use crate::geodesic::{EdgeGraph, FieldCache};
use crate::jaw::VertexMap;
use crate::mesh::Mesh;
use crate::mesh::SurfacePoint;
use crate::sibson::SibsonWeights;
use crate::sparse::{BlockColumns, PatchBuffers, PatchedWeights, Row, SparseWeights, WeightRows};
use crate::uvspace::{self, SewingSpace};
use glam::DVec3;
use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

/// Natural-neighbour weights and residual pass for one set of present bundles.
#[derive(Debug)]
pub struct SewPlan {
    /// V × B weights (columns of missing bundles are empty).
    weights: PlanWeights,
    residual: ResidualPass,
    /// `weights` by column within the blend's blocks, made on the plan's second sewing: the
    /// full plan's every clean frame, a missing set's once it lasts a frame more (a fresh set
    /// every frame never pays the transposition, ~0.4 ms on ICT, for one frame's blend).
    columns: OnceLock<BlockColumns>,
    sewings: AtomicU32,
}

/// A plan's weights: its own (the full plan's, or a plan built from scratch), or the full
/// plan's with the rows near the missing bundles replaced (a missing set's).
#[derive(Debug)]
enum PlanWeights {
    Whole(Arc<SparseWeights>),
    Patched(PatchedWeights),
}

impl PlanWeights {
    fn rows(&self) -> WeightRows<'_> {
        match self {
            PlanWeights::Whole(w) => WeightRows::Whole(w),
            PlanWeights::Patched(p) => WeightRows::Patched(p),
        }
    }

    /// The full plan's weights: these (a whole matrix), or the ones this patch reads.
    fn base(&self) -> &Arc<SparseWeights> {
        match self {
            PlanWeights::Whole(w) => w,
            PlanWeights::Patched(p) => p.base(),
        }
    }
}

impl SewPlan {
    fn new(weights: PlanWeights, residual: ResidualPass) -> SewPlan {
        SewPlan {
            weights,
            residual,
            columns: OnceLock::new(),
            sewings: AtomicU32::new(0),
        }
    }

    /// The weights by column for a sewing, once the plan has been sewn before.
    fn columns(&self) -> Option<&BlockColumns> {
        if let Some(columns) = self.columns.get() {
            return Some(columns);
        }
        if self.sewings.fetch_add(1, Ordering::Relaxed) == 0 {
            return None;
        }
        Some(
            self.columns
                .get_or_init(|| self.weights().block_columns(super::BLEND_BLOCK)),
        )
    }

    /// The V × B weights (columns of missing bundles are empty).
    pub fn weights(&self) -> WeightRows<'_> {
        self.weights.rows()
    }

    /// The residual pass of the plan's present bundles.
    #[cfg(test)]
    pub(crate) fn residual(&self) -> &ResidualPass {
        &self.residual
    }

    /// Sews one frame into `out` (V) in one pass over the vertices ([`ResidualPass::sew`]):
    /// blends `pieces` of the space whose neutral is `x0` with shapes `displacements` using
    /// this plan's weights, maps every vertex with `jaw` (from the pieces' pose to the frame's;
    /// `None`: no jaw motion) and corrects the bundles onto their targets `at`. Returns the
    /// first vertex that is not finite, if any. `spans`, when given, are those of
    /// `displacements`: the fit is then summed only where its shapes move (the same bits).
    #[allow(clippy::too_many_arguments)]
    pub fn sew_into(
        &self,
        x0: &[DVec3],
        displacements: &[f32],
        spans: Option<&ShapeSpans>,
        pieces: &Pieces,
        jaw: Option<&VertexMap<'_>>,
        at: &BundleTargets<'_>,
        out: &mut [DVec3],
    ) -> Option<usize> {
        let input = BlendInput::new(x0, displacements, self.weights(), pieces).with_spans(spans);
        let columns = self.columns();
        match jaw {
            Some(m) => self
                .residual
                .sew(&input, columns, |v, p| m.apply(v, p), at, out),
            None => self.residual.sew(&input, columns, |_, p| p, at, out),
        }
    }

    /// Every bundle's position on the surface [`sew_into`](Self::sew_into) makes (the same
    /// bits), without the surface: only the bundles' triangle corners are blended
    /// ([`ResidualPass::sew_markers`]).
    pub fn sew_markers(
        &self,
        x0: &[DVec3],
        displacements: &[f32],
        spans: Option<&ShapeSpans>,
        pieces: &Pieces,
        jaw: Option<&VertexMap<'_>>,
        at: &BundleTargets<'_>,
    ) -> Vec<DVec3> {
        let input = BlendInput::new(x0, displacements, self.weights(), pieces).with_spans(spans);
        match jaw {
            Some(m) => self.residual.sew_markers(&input, |v, p| m.apply(v, p), at),
            None => self.residual.sew_markers(&input, |_, p| p, at),
        }
    }
}

/// Plans kept for distinct sets of missing bundles (the oldest goes first).
const PLAN_CACHE: usize = 64;

/// The plans of missing sets by present bundles, in the order they were made, and the
/// weights of the last one evicted, for the next plan to write into.
#[derive(Debug, Default)]
struct PlanCache {
    plans: HashMap<Vec<u32>, Arc<SewPlan>>,
    order: VecDeque<Vec<u32>>,
    spare: PatchBuffers,
}

/// Zig-zag allowance of mesh-edge paths at short range (relative to the diagonal).
const DETOUR_SLACK: f64 = 2e-3;

/// What the sewing plans of one model are computed from: the sewing space, the neutral's edge
/// graph restricted to it, the bundles' surface-distance fields (filled as plans are made) and
/// the detour rule of [`BuildConfig::detour_ratio`](crate::model::BuildConfig::detour_ratio).
#[derive(Debug)]
pub struct SewGeometry {
    space: SewingSpace,
    graph: EdgeGraph,
    fields: FieldCache,
    detour_ratio: f64,
    slack: f64,
}

impl SewGeometry {
    /// The sewing geometry of `bundles` on `mesh` (the neutral) with the given detour ratio.
    pub fn new(mesh: &Mesh, bundles: &[SurfacePoint], detour_ratio: f64) -> Result<SewGeometry> {
        let space = uvspace::build(mesh, bundles)?;
        let graph = EdgeGraph::new(mesh, |t| {
            mesh.triangles[t]
                .iter()
                .all(|&v| space.contains(v as usize))
        });
        Ok(SewGeometry {
            space,
            graph,
            fields: FieldCache::default(),
            detour_ratio,
            slack: DETOUR_SLACK * mesh.diagonal(),
        })
    }

    /// Natural neighbours of each bundle in UV (Delaunay, not across barriers), without the
    /// pairs whose surface path detours around a hole.
    pub fn neighbours(&self, dataset: &Dataset, bundles: &[SurfacePoint]) -> Result<Vec<Vec<u32>>> {
        let uv_neighbours = SibsonWeights::new(&self.space.bundle_uv, &self.space.barriers)
            .map_err(|e| bundle_context(e, "bundle UV layout"))?
            .neighbours();
        Ok(self
            .context(dataset, bundles)
            .filter_neighbours(uv_neighbours))
    }

    /// The plans' view of this geometry with the dataset and bundles it was built for.
    pub(crate) fn context<'a>(
        &'a self,
        dataset: &'a Dataset,
        bundles: &'a [SurfacePoint],
    ) -> SewContext<'a> {
        SewContext {
            dataset,
            bundles,
            space: &self.space,
            graph: &self.graph,
            fields: &self.fields,
            detour_ratio: self.detour_ratio,
            slack: self.slack,
        }
    }

    /// The bundles' cached distance fields.
    #[cfg(test)]
    pub(crate) fn fields(&self) -> &FieldCache {
        &self.fields
    }
}

/// A model's sewing plans: the full plan (every bundle present), which rows each bundle's
/// absence can change, the rows kept without one bundle or a pair, and a cache of the plans
/// of missing sets.
#[derive(Debug)]
pub struct SewPlans {
    geometry: SewGeometry,
    full: Arc<SewPlan>,
    /// Every sewn vertex's natural neighbours among all bundles, before barriers and detours
    /// (rows of the sewn vertices in order), for the tests' reference derivation.
    #[cfg(test)]
    support: SparseWeights,
    /// The sewn vertices, in the order of `support`'s rows.
    sewn: Vec<u32>,
    /// Per sewn vertex: the vertices whose row is its row (itself and those it is the proxy of).
    by_proxy: Proxied,
    /// Per bundle: the sewn rows (ascending) whose support or full-plan row has it, i.e. the
    /// rows that can change when it is missing.
    touching: Vec<Vec<u32>>,
    /// Rows kept with a few bundles missing, for the plans of later missing sets.
    memo: RowMemo,
    cache: Mutex<PlanCache>,
}

impl SewPlans {
    /// The full plan and support of `geometry` for `dataset` and `bundles` (those it was built
    /// for).
    pub fn new(
        geometry: SewGeometry,
        dataset: &Dataset,
        bundles: &[SurfacePoint],
    ) -> Result<SewPlans> {
        let sew = geometry.context(dataset, bundles);
        let all: Vec<u32> = (0..bundles.len() as u32).collect();
        let full_weights = Arc::new(sew.weights_for(&all)?);
        let full = Arc::new(sew.with_residual(&all, PlanWeights::Whole(full_weights.clone()))?);
        let support = sew.support()?;
        let sewn: Vec<u32> = geometry.space.sewn().map(|v| v as u32).collect();
        let mut touching = vec![Vec::new(); bundles.len()];
        for (r, &v) in sewn.iter().enumerate() {
            let (a, b) = (support.row(r).0, full_weights.row(v as usize).0);
            for &c in a.iter().chain(b.iter().filter(|c| !a.contains(c))) {
                touching[c as usize].push(r as u32);
            }
        }
        let by_proxy = Proxied::new(&geometry.space.proxy);
        Ok(SewPlans {
            geometry,
            full,
            #[cfg(test)]
            support,
            sewn,
            by_proxy,
            touching,
            memo: RowMemo::new(bundles.len()),
            cache: Mutex::new(PlanCache::default()),
        })
    }

    /// The plan for the `present` bundles (ascending) of `dataset` and `bundles` (those the
    /// plans were built for): the full plan, a cached one, or one derived from the full plan.
    pub fn plan_for(
        &self,
        dataset: &Dataset,
        bundles: &[SurfacePoint],
        present: &[u32],
    ) -> Result<Arc<SewPlan>> {
        if present.len() == bundles.len() {
            return Ok(self.full.clone());
        }
        let key = present.to_vec();
        if let Ok(cache) = self.cache.lock() {
            if let Some(p) = cache.plans.get(&key) {
                return Ok(p.clone());
            }
        }
        let ctx = self.geometry.context(dataset, bundles);
        let plan = Arc::new(self.derive(&ctx, present)?);
        if let Ok(mut cache) = self.cache.lock() {
            if cache.plans.len() >= PLAN_CACHE {
                // The oldest set goes; its weights' memory is the next plan's.
                if let Some(old) = cache.order.pop_front().and_then(|k| cache.plans.remove(&k)) {
                    if let Ok(SewPlan {
                        weights: PlanWeights::Patched(old),
                        ..
                    }) = Arc::try_unwrap(old)
                    {
                        cache.spare = old.into_buffers();
                    }
                }
            }
            cache.order.push_back(key.clone());
            cache.plans.insert(key, plan.clone());
        }
        Ok(plan)
    }

    /// The plan for `present` from the full plan and the rows kept without a few bundles
    /// ([`RowMemo`]). Removing sites changes only the rows of points that had one of them as
    /// a natural neighbour (the rule [`SewContext::plan_without`] applies from the full set):
    /// so a sewn row that no missing bundle touches (columns or support) is the full plan's,
    /// and one that missing bundles G touch is its row without G, provided no other missing
    /// bundle touches that row; if some do, G grows by them and the test repeats. Rows that
    /// G would grow beyond [`MAX_GONE`](super::memo::MAX_GONE) for are recomputed.
    fn derive(&self, ctx: &SewContext<'_>, present: &[u32]) -> Result<SewPlan> {
        let nb = self.touching.len();
        let mut is_missing = vec![true; nb];
        for &b in present {
            is_missing[b as usize] = false;
        }
        // Per sewn row touched by a missing bundle: those bundles (None: too many to keep),
        // and its index among the rows the first of them touches (where the rows kept without
        // that bundle alone hold it).
        let mut slot = vec![u32::MAX; self.sewn.len()];
        let mut touched: Vec<(u32, Option<Gone>, u32)> = Vec::new();
        for m in (0..nb as u32).filter(|&b| is_missing[b as usize]) {
            for (j, &r) in self.touching[m as usize].iter().enumerate() {
                let s = &mut slot[r as usize];
                if *s == u32::MAX {
                    *s = touched.len() as u32;
                    touched.push((r, Some(Gone::one(m)), j as u32));
                } else {
                    let e = &mut touched[*s as usize].1;
                    *e = e.and_then(|g| g.with(m));
                }
            }
        }
        let mut view = self.memo.view();
        // Per touched row: the kept rows holding it and its index there, once resolved.
        let mut found: Vec<Option<(Kept<'_>, u32)>> = (0..touched.len()).map(|_| None).collect();
        let mut pending: Vec<usize> = (0..touched.len()).collect();
        while !pending.is_empty() {
            let mut queue: GoneMap<Vec<u32>> = GoneMap::default();
            let mut next = Vec::new();
            for k in pending {
                let (r, Some(gone), j) = touched[k] else {
                    continue;
                };
                // Alone, a bundle's kept rows are its `touching` rows: the index is known.
                let hit = match gone.single().and_then(|m| self.memo.without_one(m)) {
                    Some(rows) => Some((Kept::One(rows), j as usize)),
                    None => view
                        .find(gone, r)
                        .map(|(rows, i)| (Kept::Set(rows.clone()), i)),
                };
                let Some((rows, i)) = hit else {
                    queue.entry(gone).or_default().push(r);
                    next.push(k);
                    continue;
                };
                // The row kept without `gone` holds, unless other missing bundles touch it:
                // then it is the row without those too.
                let (cols, support) = (rows.get().weights.row(i).0, rows.get().support.row(i).0);
                let mut grown = Some(gone);
                for &c in cols.iter().chain(support) {
                    if is_missing[c as usize] {
                        grown = grown.and_then(|g| g.with(c));
                    }
                }
                match grown {
                    Some(g) if g == gone => found[k] = Some((rows, i as u32)),
                    Some(g) => {
                        touched[k].1 = Some(g);
                        next.push(k);
                    }
                    None => touched[k].1 = None,
                }
            }
            for (gone, mut rows) in queue {
                rows.sort_unstable();
                view.compute(ctx, gone, rows, &self.touching, &self.sewn)?;
            }
            pending = next;
        }
        // The rest: recomputed.
        let mut direct: Vec<usize> = touched
            .iter()
            .zip(&found)
            .filter(|(_, f)| f.is_none())
            .map(|((r, _, _), _)| self.sewn[*r as usize] as usize)
            .collect();
        direct.sort_unstable();
        let recomputed = match direct.is_empty() {
            true => SparseWeights::empty(nb),
            false => ctx.rows_for(present, &direct)?,
        };
        let mut changed: Vec<(u32, Row<'_>)> = direct
            .iter()
            .enumerate()
            .map(|(i, &v)| (v as u32, recomputed.row(i)))
            .collect();
        for ((r, _, _), f) in touched.iter().zip(&found) {
            if let Some((rows, i)) = f {
                changed.push((self.sewn[*r as usize], rows.get().weights.row(*i as usize)));
            }
        }
        let spare = match self.cache.lock() {
            Ok(mut c) => std::mem::take(&mut c.spare),
            Err(_) => PatchBuffers::default(),
        };
        ctx.plan_patched(
            present,
            self.full.weights.base(),
            &self.by_proxy,
            changed,
            spare,
        )
    }

    /// The plan with every bundle present.
    #[cfg(test)]
    pub(crate) fn full(&self) -> &SewPlan {
        &self.full
    }
    /// The full plan's weights.
    pub fn full_weights(&self) -> &SparseWeights {
        self.full.weights.base()
    }
    /// The sewing space (chart UVs, proxies, barriers).
    pub fn space(&self) -> &SewingSpace {
        &self.geometry.space
    }
    /// What the plans are computed from.
    #[cfg(test)]
    pub(crate) fn geometry(&self) -> &SewGeometry {
        &self.geometry
    }
    /// Rows kept without one bundle and without pairs.
    #[cfg(test)]
    pub(crate) fn kept_rows(&self) -> (usize, usize) {
        self.memo.kept_rows()
    }
    /// Natural neighbours of every sewn vertex among all bundles (no barrier, no detour).
    #[cfg(test)]
    pub(crate) fn support(&self) -> &SparseWeights {
        &self.support
    }
}

/// Kept rows a plan reads: a bundle's alone borrowed from the memo (no reference count
/// touched per row), a set's shared.
enum Kept<'m> {
    One(&'m Rows),
    Set(Arc<Rows>),
}

impl Kept<'_> {
    fn get(&self) -> &Rows {
        match self {
            Kept::One(rows) => rows,
            Kept::Set(rows) => rows,
        }
    }
}

/// The vertices grouped by their proxy (CSR).
#[derive(Debug)]
struct Proxied {
    start: Vec<u32>,
    vertices: Vec<u32>,
}

impl Proxied {
    fn new(proxy: &[u32]) -> Proxied {
        let mut start = vec![0u32; proxy.len() + 1];
        for &p in proxy {
            start[p as usize + 1] += 1;
        }
        for i in 0..proxy.len() {
            start[i + 1] += start[i];
        }
        let mut at = start.clone();
        let mut vertices = vec![0u32; proxy.len()];
        for (v, &p) in proxy.iter().enumerate() {
            vertices[at[p as usize] as usize] = v as u32;
            at[p as usize] += 1;
        }
        Proxied { start, vertices }
    }

    /// The vertices whose proxy is `v`.
    fn of(&self, v: u32) -> &[u32] {
        let (a, b) = (self.start[v as usize], self.start[v as usize + 1]);
        &self.vertices[a as usize..b as usize]
    }
}

/// The plans a context makes (its rows with the residual pass).
impl SewContext<'_> {
    /// Sewing weights for the present bundles: Sibson weights in UV for sewn vertices (minus
    /// detours around holes), copied from the proxy for the others; plus the residual pass.
    #[cfg(test)]
    pub(crate) fn plan(&self, present: &[u32]) -> Result<SewPlan> {
        let weights = self.weights_for(present)?;
        self.with_residual(present, PlanWeights::Whole(Arc::new(weights)))
    }

    /// The plan of `weights` with the residual pass for the `present` bundles.
    fn with_residual(&self, present: &[u32], weights: PlanWeights) -> Result<SewPlan> {
        let tris = &self.dataset.neutral().triangles;
        let residual = ResidualPass::new(tris, self.bundles, weights.rows(), present)?;
        Ok(SewPlan::new(weights, residual))
    }

    /// The plan whose rows are `full`'s with those of `changed` (sewn vertex, its row)
    /// replaced, for them and the vertices they are the proxy of, with the residual pass for
    /// the present bundles; the new rows are written into `buffers`.
    fn plan_patched<'w>(
        &self,
        present: &[u32],
        full: &Arc<SparseWeights>,
        by_proxy: &Proxied,
        changed: Vec<(u32, Row<'w>)>,
        buffers: PatchBuffers,
    ) -> Result<SewPlan> {
        let fill = |rows: &mut SparseWeights| {
            for &(_, (cols, vals)) in &changed {
                rows.push_row(cols, vals);
            }
        };
        let replaced = changed
            .iter()
            .enumerate()
            .flat_map(|(i, &(v, _))| by_proxy.of(v).iter().map(move |&u| (u as usize, i as u32)));
        let weights = PatchedWeights::new(full.clone(), buffers, fill, replaced);
        self.with_residual(present, PlanWeights::Patched(weights))
    }

    /// The plan for `present` bundles derived from the full plan: removing a site changes the
    /// natural-neighbour weights only of points that had it as a natural neighbour, so only
    /// those rows are recomputed (same rules as [`plan`](Self::plan)). The tests' reference
    /// for [`SewPlans::plan_for`], which keeps rows across plans.
    #[cfg(test)]
    pub(crate) fn plan_without(
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
        let sewn: Vec<usize> = sp.sewn().collect();
        let touches = |cols: &[u32]| cols.iter().any(|&c| missing[c as usize]);
        let affected: Vec<usize> = sewn
            .iter()
            .enumerate()
            .filter(|&(r, &v)| touches(support.row(r).0) || touches(full.weights().row(v).0))
            .map(|(_, &v)| v)
            .collect();
        let mut new_row = vec![usize::MAX; nv];
        for (r, &v) in affected.iter().enumerate() {
            new_row[v] = r;
        }
        let recomputed = self.rows_for(present, &affected)?;
        // A proxy has the same row as its own vertex in the full plan.
        let weights = self.weights_from(|v| match new_row[v] {
            usize::MAX => full.weights().row(v),
            r => recomputed.row(r),
        });
        self.with_residual(present, PlanWeights::Whole(Arc::new(weights)))
    }
}

fn bundle_context(e: LgiError, what: &str) -> LgiError {
    match e {
        LgiError::Input(m) => LgiError::Input(format!("{what}: {m}")),
        other => other,
    }
}
