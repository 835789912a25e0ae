//! Sewing plans: for one set of present bundles, the V × B natural-neighbour weights (Sibson
//! in UV, minus paths that detour around a hole) and the residual pass, built once for all
//! bundles and per set of missing bundles on demand (derived from the full plan, cached).

use super::{BlendInput, BundleTargets, Pieces, ResidualPass};
use crate::dataset::Dataset;
use crate::error::{LgiError, Result};
use crate::geodesic::{is_detour, EdgeGraph, FieldCache};
use crate::jaw::VertexMap;
use crate::mesh::Mesh;
use crate::mesh::SurfacePoint;
use crate::sibson::SibsonWeights;
use crate::sparse::SparseWeights;
use crate::uvspace::{self, SewingSpace};
use glam::DVec3;
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// Natural-neighbour weights and residual pass for one set of present bundles.
#[derive(Debug)]
pub struct SewPlan {
    /// V × B weights (columns of missing bundles are empty).
    pub weights: SparseWeights,
    residual: ResidualPass,
}

impl SewPlan {
    /// The residual pass of the plan's present bundles.
    #[cfg(test)]
    pub(crate) fn residual(&self) -> &ResidualPass {
        &self.residual
    }

    /// Sews one frame into `out` (V) in one pass over the vertices ([`ResidualPass::sew`]):
    /// blends `pieces` of the space whose neutral is `x0` with shapes `displacements` using
    /// this plan's weights, maps every vertex with `jaw` (from the pieces' pose to the frame's;
    /// `None`: no jaw motion) and corrects the bundles onto their targets `at`. Returns the
    /// first vertex that is not finite, if any.
    pub fn sew_into(
        &self,
        x0: &[DVec3],
        displacements: &[f32],
        pieces: &Pieces,
        jaw: Option<&VertexMap<'_>>,
        at: &BundleTargets<'_>,
        out: &mut [DVec3],
    ) -> Option<usize> {
        let input = BlendInput::new(x0, displacements, &self.weights, pieces);
        match jaw {
            Some(m) => self.residual.sew(&input, |v, p| m.apply(v, p), at, out),
            None => self.residual.sew(&input, |_, p| p, at, out),
        }
    }
}

/// Plans kept for distinct sets of missing bundles before the cache is cleared.
const PLAN_CACHE: usize = 64;

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

/// A model's sewing plans: the full plan (every bundle present), the natural-neighbour support
/// that tells which rows a missing bundle changes, and a cache of the plans of missing sets.
#[derive(Debug)]
pub struct SewPlans {
    geometry: SewGeometry,
    full: Arc<SewPlan>,
    /// Every sewn vertex's natural neighbours among all bundles, before barriers and detours
    /// (rows of the sewn vertices in order): which rows a missing bundle can change.
    support: SparseWeights,
    cache: Mutex<HashMap<Vec<u32>, Arc<SewPlan>>>,
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
        let full = Arc::new(sew.plan(&all)?);
        let support = sew.support()?;
        Ok(SewPlans {
            geometry,
            full,
            support,
            cache: Mutex::new(HashMap::new()),
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
            if let Some(p) = cache.get(&key) {
                return Ok(p.clone());
            }
        }
        let ctx = self.geometry.context(dataset, bundles);
        let plan = Arc::new(ctx.plan_without(present, &self.full, &self.support)?);
        if let Ok(mut cache) = self.cache.lock() {
            if cache.len() >= PLAN_CACHE {
                cache.clear();
            }
            cache.insert(key, plan.clone());
        }
        Ok(plan)
    }

    /// The plan with every bundle present.
    pub fn full(&self) -> &SewPlan {
        &self.full
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
    /// Natural neighbours of every sewn vertex among all bundles (no barrier, no detour).
    #[cfg(test)]
    pub(crate) fn support(&self) -> &SparseWeights {
        &self.support
    }
}

/// What computing sewing weights needs: the geometry borrowed with its dataset and bundles.
pub(crate) struct SewContext<'a> {
    pub(crate) dataset: &'a Dataset,
    pub(crate) bundles: &'a [SurfacePoint],
    pub(crate) space: &'a SewingSpace,
    pub(crate) graph: &'a EdgeGraph,
    pub(crate) fields: &'a FieldCache,
    pub(crate) detour_ratio: f64,
    pub(crate) slack: f64,
}

impl SewContext<'_> {
    /// Sewing weights for the present bundles: Sibson weights in UV for sewn vertices (minus
    /// detours around holes), copied from the proxy for the others; plus the residual pass.
    pub(crate) fn plan(&self, present: &[u32]) -> Result<SewPlan> {
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
    pub(crate) fn support(&self) -> Result<SparseWeights> {
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

fn bundle_context(e: LgiError, what: &str) -> LgiError {
    match e {
        LgiError::Input(m) => LgiError::Input(format!("{what}: {m}")),
        other => other,
    }
}
