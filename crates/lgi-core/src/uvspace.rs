//! The UV space where the pieces are sewn: the UV islands that carry bundles, one chart UV per
//! vertex (seams resolved), the hole boundaries of those islands as barriers (mouth, eyes), and
//! a proxy for every vertex outside them (teeth, eyeballs, back of the head), which copies the
//! weights of its nearest sewn vertex in 3D. UV atlases often stack unrelated parts on top of
//! each other (ICT's eyeballs share the face's UV tile), so UV distance alone is not enough.
//! UV islands and the one rule for "the UV of a vertex" ([`UvIslands::vertex_uvs`]) live here
//! too, so the sewing space and every other vertex-UV question agree.

use crate::error::{LgiError, Result};
use crate::mesh::{Mesh, SurfacePoint};
use crate::sibson::Barrier;
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use std::collections::HashMap;

/// Where each vertex lives for sewing.
#[derive(Debug, Clone)]
pub struct SewingSpace {
    /// Chart UV of every vertex in the space (meaningless for proxied vertices).
    pub vertex_uv: Vec<DVec2>,
    /// `proxy[v] == v` for vertices in the space; otherwise the nearest (3D) vertex in it.
    pub proxy: Vec<u32>,
    /// UV position of every bundle.
    pub bundle_uv: Vec<DVec2>,
    /// Hole-boundary edges of the sewn islands, in UV: weights never see across them.
    pub barriers: Vec<Barrier>,
}

impl SewingSpace {
    /// Whether vertex `v` is sewn in UV (not proxied).
    pub fn contains(&self, v: usize) -> bool {
        self.proxy[v] as usize == v
    }

    /// The sewn vertices, ascending (the rows of the plans' Sibson weights).
    pub fn sewn(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.proxy.len()).filter(|&v| self.contains(v))
    }
}

/// Disjoint sets of `0..n` with path halving; a union keeps the smaller root, so roots do not
/// depend on the order of unions. The core's one union-find (UV islands need it).
#[derive(Debug, Clone)]
struct UnionFind {
    parent: Vec<u32>,
}

impl UnionFind {
    fn new(n: usize) -> Self {
        UnionFind {
            parent: (0..n as u32).collect(),
        }
    }

    fn find(&mut self, mut a: u32) -> u32 {
        while self.parent[a as usize] != a {
            let g = self.parent[self.parent[a as usize] as usize];
            self.parent[a as usize] = g;
            a = g;
        }
        a
    }

    fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.parent[ra.max(rb) as usize] = ra.min(rb);
        }
    }
}

/// UV islands of a mesh: the connected components of `uv_triangles` through shared UV indices,
/// numbered in order of their first triangle. Which UV a vertex takes is one rule,
/// [`vertex_uvs`](Self::vertex_uvs), whatever islands the question is about.
#[derive(Debug, Clone, PartialEq)]
pub struct UvIslands {
    /// Island of each triangle (empty when the mesh has no UVs; `u32::MAX` for a triangle with
    /// an out-of-range index).
    pub triangle_island: Vec<u32>,
    /// Number of triangles in each island.
    pub island_size: Vec<usize>,
}

impl UvIslands {
    /// Computes the islands of `mesh`. Expects a validated mesh (`Mesh::validate`): triangles
    /// with out-of-range indices are ignored rather than trusted.
    pub fn new(mesh: &Mesh) -> Self {
        let nv = mesh.positions.len();
        let nu = mesh.uvs.len();
        let mut out = UvIslands {
            triangle_island: Vec::new(),
            island_size: Vec::new(),
        };
        if !mesh.has_uvs() || mesh.uv_triangles.len() != mesh.triangles.len() {
            return out;
        }
        let valid = |t: usize| {
            mesh.triangles[t].iter().all(|&v| (v as usize) < nv)
                && mesh.uv_triangles[t].iter().all(|&u| (u as usize) < nu)
        };
        let mut sets = UnionFind::new(nu);
        for (t, ut) in mesh.uv_triangles.iter().enumerate() {
            if valid(t) {
                sets.union(ut[0], ut[1]);
                sets.union(ut[0], ut[2]);
            }
        }
        let mut id_of_root: HashMap<u32, u32> = HashMap::new();
        out.triangle_island = vec![u32::MAX; mesh.triangles.len()];
        for (t, ut) in mesh.uv_triangles.iter().enumerate() {
            if !valid(t) {
                continue;
            }
            let root = sets.find(ut[0]);
            let next = id_of_root.len() as u32;
            let id = *id_of_root.entry(root).or_insert(next);
            if id as usize == out.island_size.len() {
                out.island_size.push(0);
            }
            out.island_size[id as usize] += 1;
            out.triangle_island[t] = id;
        }
        out
    }

    /// One UV per vertex, the rule every "UV of a vertex" in lgi follows: among the triangles of
    /// the islands `in_space` accepts, a vertex takes its corner UV in the lowest-numbered
    /// triangle using it (`None` where no such triangle uses it). The sewing space asks about
    /// the islands carrying bundles, so a seam to any other island never moves a vertex out of
    /// them; on a seam inside the space, triangle order decides. `self` must come from `mesh`.
    pub fn vertex_uvs(&self, mesh: &Mesh, in_space: impl Fn(u32) -> bool) -> Vec<Option<DVec2>> {
        let mut out = vec![None; mesh.positions.len()];
        for (t, (tri, ut)) in mesh.triangles.iter().zip(&mesh.uv_triangles).enumerate() {
            match self.triangle_island.get(t) {
                Some(&island) if island != u32::MAX && in_space(island) => {}
                _ => continue,
            }
            for (&v, &u) in tri.iter().zip(ut) {
                if let Some(slot @ None) = out.get_mut(v as usize) {
                    *slot = mesh.uvs.get(u as usize).copied();
                }
            }
        }
        out
    }

    /// Boundary of one island in its own UVs: the UV edges used by exactly one triangle of the
    /// island. This is what a query in that chart must not see across: 3D holes inside the
    /// island *and* seams to other islands (e.g. ICT's mouth and eyes are seams to the mouth
    /// and eye-socket islands, not 3D boundaries). `self` must come from `mesh`.
    pub fn island_barriers(&self, mesh: &Mesh, island: u32) -> Vec<Barrier> {
        let mut count: HashMap<(u32, u32), u32> = HashMap::new();
        let mut order = Vec::new();
        for (t, ut) in mesh.uv_triangles.iter().enumerate() {
            if self.triangle_island.get(t) != Some(&island) {
                continue;
            }
            for k in 0..3 {
                let (a, b) = (ut[k], ut[(k + 1) % 3]);
                let key = (a.min(b), a.max(b));
                let c = count.entry(key).or_insert(0);
                if *c == 0 {
                    order.push(key);
                }
                *c += 1;
            }
        }
        order
            .into_iter()
            .filter(|key| count.get(key) == Some(&1))
            // `get`: `self` may have been computed from another mesh.
            .filter_map(|(a, b)| Some([*mesh.uvs.get(a as usize)?, *mesh.uvs.get(b as usize)?]))
            .collect()
    }
}

/// One UV per vertex over all islands ([`UvIslands::vertex_uvs`] with every island in the
/// space): the query points of [`SibsonWeights::weights`](crate::sibson::SibsonWeights::weights).
/// Vertices no triangle uses, and every vertex of a mesh without UVs, get NaN, which `weights`
/// answers with an empty row (the caller decides what such a vertex does).
///
/// Caution: UV islands may overlap in UV space (ICT: the head and face charts both span the
/// unit square), so only vertices of the bundles' islands should be weighted against them
/// (ask [`UvIslands::vertex_uvs`] about those islands only, as the sewing space does).
pub fn vertex_charts(mesh: &Mesh) -> Vec<DVec2> {
    UvIslands::new(mesh)
        .vertex_uvs(mesh, |_| true)
        .into_iter()
        .map(|uv| uv.unwrap_or(DVec2::NAN))
        .collect()
}

/// Boundary edges of the 3D mesh topology (edges used by exactly one triangle) mapped to
/// `vertex_uv` (normally [`vertex_charts`]).
///
/// An edge is skipped when an endpoint's UV is not finite or out of range, and, for a mesh with
/// UVs, when it does not lie in the chart both its endpoints were mapped to (the edge's own
/// corner UVs differ from the endpoints' chart UVs): such a segment would cut across unrelated
/// UV space. Seam edges are not 3D boundary edges; where a hole is closed by another island
/// (ICT's mouth and eyes) use [`UvIslands::island_barriers`] instead.
pub fn boundary_barriers(mesh: &Mesh, vertex_uv: &[DVec2]) -> Vec<Barrier> {
    let islands = UvIslands::new(mesh);
    let with_uvs = !islands.triangle_island.is_empty();
    let charts = islands.vertex_uvs(mesh, |_| true);
    let mut count: HashMap<(u32, u32), (u32, usize, usize)> = HashMap::new();
    let mut order = Vec::new();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            let key = (a.min(b), a.max(b));
            let e = count.entry(key).or_insert((0, t, k));
            if e.0 == 0 {
                order.push(key);
            }
            e.0 += 1;
        }
    }
    let mut out = Vec::new();
    for key in order {
        let Some(&(1, t, k)) = count.get(&key) else {
            continue;
        };
        let (a, b) = (
            mesh.triangles[t][k] as usize,
            mesh.triangles[t][(k + 1) % 3] as usize,
        );
        let (Some(&ua), Some(&ub)) = (vertex_uv.get(a), vertex_uv.get(b)) else {
            continue;
        };
        if !(ua.is_finite() && ub.is_finite()) {
            continue;
        }
        if with_uvs {
            let ut = mesh.uv_triangles[t];
            let corner = |j: usize| mesh.uvs.get(ut[j] as usize).copied();
            let chart = |v: usize| charts.get(v).copied().flatten();
            let in_chart = chart(a) == corner(k) && chart(b) == corner((k + 1) % 3);
            if !in_chart {
                continue;
            }
        }
        out.push([ua, ub]);
    }
    out
}

/// Builds the sewing space of `mesh` for bundles at `bundles` (their closest points).
pub fn build(mesh: &Mesh, bundles: &[SurfacePoint]) -> Result<SewingSpace> {
    if !mesh.has_uvs() {
        return Err(LgiError::Dataset(
            "the neutral mesh has no UVs: lgi sews the bundles' pieces in UV space, \
             so the neutral needs texture coordinates (vt in OBJ, TEXCOORD_0 in glTF)"
                .into(),
        ));
    }
    let islands = UvIslands::new(mesh);
    let island_of = |t: usize| islands.triangle_island.get(t).copied();
    let sewn_islands: std::collections::HashSet<u32> = bundles
        .iter()
        .filter_map(|b| island_of(b.triangle as usize))
        .collect();
    let sewn = |t: usize| island_of(t).is_some_and(|i| sewn_islands.contains(&i));
    let uvs = islands.vertex_uvs(mesh, |i| sewn_islands.contains(&i));
    let in_space: Vec<bool> = uvs.iter().map(Option::is_some).collect();
    let vertex_uv: Vec<DVec2> = uvs.iter().map(|uv| uv.unwrap_or(DVec2::NAN)).collect();
    let nv = mesh.num_vertices();
    let mut edge_count: HashMap<(u32, u32), (u32, [DVec2; 2])> = HashMap::new();
    for t in 0..mesh.triangles.len() {
        if !sewn(t) {
            continue;
        }
        let tri = mesh.triangles[t];
        let uvt = mesh.uv_triangles[t];
        for c in 0..3 {
            let (a, b) = (tri[c], tri[(c + 1) % 3]);
            let key = (a.min(b), a.max(b));
            let seg = [
                mesh.uvs[uvt[c] as usize],
                mesh.uvs[uvt[(c + 1) % 3] as usize],
            ];
            edge_count.entry(key).or_insert((0, seg)).0 += 1;
        }
    }
    // Edges used once inside the sewn islands are their 3D boundary: holes and the outer rim.
    // Seams between islands of the same space are used twice and are not barriers.
    let mut barriers: Vec<(u32, u32, [DVec2; 2])> = edge_count
        .into_iter()
        .filter(|(_, (n, _))| *n == 1)
        .map(|((a, b), (_, seg))| (a, b, seg))
        .collect();
    barriers.sort_by_key(|&(a, b, _)| (a, b));
    let barriers = barriers.into_iter().map(|(_, _, s)| s).collect();

    let bundle_uv = bundles
        .iter()
        .map(|b| {
            let uvt = mesh.uv_triangles[b.triangle as usize];
            let uv = |i: usize| mesh.uvs[uvt[i] as usize];
            uv(0) * b.bary[0] + uv(1) * b.bary[1] + uv(2) * b.bary[2]
        })
        .collect();

    let inside: Vec<u32> = (0..nv as u32).filter(|&v| in_space[v as usize]).collect();
    let proxy = proxies(&mesh.positions, &in_space, &inside);
    Ok(SewingSpace {
        vertex_uv,
        proxy,
        bundle_uv,
        barriers,
    })
}

/// Nearest in-space vertex (3D) for every vertex outside the space, by a uniform grid search.
fn proxies(pos: &[DVec3], in_space: &[bool], inside: &[u32]) -> Vec<u32> {
    let n = pos.len();
    if inside.len() == n || inside.is_empty() {
        return (0..n as u32).collect();
    }
    let (lo, hi) = inside.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), &v| (lo.min(pos[v as usize]), hi.max(pos[v as usize])),
    );
    let ext = (hi - lo).max(DVec3::splat(1e-12));
    let res = ((inside.len() as f64).cbrt().ceil() as usize).clamp(1, 64);
    let cell = ext / res as f64;
    let cell_of = |p: DVec3| -> [usize; 3] {
        let c = ((p - lo) / cell).floor();
        [
            (c.x.max(0.0) as usize).min(res - 1),
            (c.y.max(0.0) as usize).min(res - 1),
            (c.z.max(0.0) as usize).min(res - 1),
        ]
    };
    let mut cells: Vec<Vec<u32>> = vec![Vec::new(); res * res * res];
    for &v in inside {
        let [x, y, z] = cell_of(pos[v as usize]);
        cells[(z * res + y) * res + x].push(v);
    }
    let min_cell = cell.min_element();
    (0..n)
        .into_par_iter()
        .map(|v| {
            if in_space[v] {
                return v as u32;
            }
            let p = pos[v];
            let c = cell_of(p);
            let box_d2 = p.distance_squared(p.clamp(lo, hi));
            let mut best = (f64::INFINITY, u32::MAX);
            // Grow rings until the best found is closer than anything outside the ring.
            for r in 0..res {
                for z in c[2].saturating_sub(r)..=(c[2] + r).min(res - 1) {
                    for y in c[1].saturating_sub(r)..=(c[1] + r).min(res - 1) {
                        for x in c[0].saturating_sub(r)..=(c[0] + r).min(res - 1) {
                            let ring = x.abs_diff(c[0]).max(y.abs_diff(c[1])).max(z.abs_diff(c[2]));
                            if ring != r {
                                continue;
                            }
                            for &u in &cells[(z * res + y) * res + x] {
                                let d = p.distance_squared(pos[u as usize]);
                                if d < best.0 || (d == best.0 && u < best.1) {
                                    best = (d, u);
                                }
                            }
                        }
                    }
                }
                // Every vertex in rings beyond r is at least r cells from q, p's projection on
                // the grid box, and |p - x|^2 >= |p - q|^2 + |q - x|^2 for x in the box.
                let reach = (r as f64) * min_cell;
                if best.1 != u32::MAX && best.0 <= box_d2 + reach * reach {
                    break;
                }
            }
            best.1
        })
        .collect()
}

#[cfg(test)]
mod tests;
