//! What computing sewing weights needs (the sewing geometry borrowed with its dataset and
//! bundles) and the rows it computes: Sibson weights in UV minus detours around holes, for
//! the plans (plan.rs) and the rows kept without a few bundles (memo.rs).

use crate::dataset::Dataset;
use crate::error::Result;
use crate::geodesic::{is_detour, EdgeGraph, FieldCache};
use crate::mesh::SurfacePoint;
use crate::sibson::SibsonWeights;
use crate::sparse::SparseWeights;
use crate::uvspace::SewingSpace;
use rayon::prelude::*;

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
    /// The sewing weights of [`plan`](Self::plan).
    pub(super) fn weights_for(&self, present: &[u32]) -> Result<SparseWeights> {
        let nv = self.dataset.num_vertices();
        let sewn: Vec<usize> = self.space.sewn().collect();
        let w = self.rows_for(present, &sewn)?;
        let mut row_of = vec![usize::MAX; nv];
        for (r, &v) in sewn.iter().enumerate() {
            row_of[v] = r;
        }
        Ok(self.weights_from(|v| w.row(row_of[v])))
    }

    /// Sibson rows (minus detours) of `vertices` for the present bundles; columns are bundle
    /// indices.
    pub(crate) fn rows_for(&self, present: &[u32], vertices: &[usize]) -> Result<SparseWeights> {
        Ok(self.sibson_rows(present, vertices, false)?.0)
    }

    /// [`rows_for`](Self::rows_for), with each row's columns before barriers and detours (the
    /// Sibson row's support: its natural neighbours, or the nearest hull edge's ends).
    pub(crate) fn rows_and_support_for(
        &self,
        present: &[u32],
        vertices: &[usize],
    ) -> Result<(SparseWeights, SparseWeights)> {
        self.sibson_rows(present, vertices, true)
    }

    /// The rows of [`rows_for`](Self::rows_for) and, `with_support`, their supports (else
    /// an empty matrix), columns as bundle indices.
    fn sibson_rows(
        &self,
        present: &[u32],
        vertices: &[usize],
        with_support: bool,
    ) -> Result<(SparseWeights, SparseWeights)> {
        let sp = self.space;
        let sites: Vec<_> = present.iter().map(|&i| sp.bundle_uv[i as usize]).collect();
        let sib = SibsonWeights::new(&sites, &sp.barriers)?;
        let queries: Vec<_> = vertices.iter().map(|&v| sp.vertex_uv[v]).collect();
        let (w, mut support) = match with_support {
            true => sib.weights_and_support(&queries),
            false => (sib.weights(&queries), SparseWeights::empty(0)),
        };
        let mut w = self.drop_detours(w, vertices, present);
        for m in [&mut w, &mut support] {
            for c in &mut m.cols {
                *c = present[*c as usize];
            }
            m.num_cols = self.bundles.len();
        }
        Ok((w, support))
    }

    /// The weights whose row for vertex v is `sewn_row(proxy[v])` (a sewn vertex is its own
    /// proxy).
    pub(super) fn weights_from<'w>(
        &self,
        sewn_row: impl Fn(usize) -> (&'w [u32], &'w [f64]),
    ) -> SparseWeights {
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
        weights
    }

    /// Natural neighbours of every sewn vertex among all bundles, with no barrier or detour.
    pub(crate) fn support(&self) -> Result<SparseWeights> {
        let sp = self.space;
        let sib = SibsonWeights::new(&sp.bundle_uv, &[])?;
        let queries: Vec<_> = sp.sewn().map(|v| sp.vertex_uv[v]).collect();
        Ok(sib.weights(&queries))
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
                // A site no row has: nothing to drop (and no field to fetch).
                if rows.is_empty() {
                    return Vec::new();
                }
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
    pub(super) fn filter_neighbours(&self, neighbours: Vec<Vec<u32>>) -> Vec<Vec<u32>> {
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
