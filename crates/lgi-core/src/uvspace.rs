//! The UV space where the pieces are sewn: the UV islands that carry bundles, one chart UV per
//! vertex (seams resolved), the hole boundaries of those islands as barriers (mouth, eyes), and
//! a proxy for every vertex outside them (teeth, eyeballs, back of the head), which copies the
//! weights of its nearest sewn vertex in 3D. UV atlases often stack unrelated parts on top of
//! each other (ICT's eyeballs share the face's UV tile), so UV distance alone is not enough.

use crate::error::{LgiError, Result};
use crate::mesh::{Mesh, SurfacePoint};
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
    pub barriers: Vec<[DVec2; 2]>,
}

impl SewingSpace {
    /// Whether vertex `v` is sewn in UV (not proxied).
    pub fn contains(&self, v: usize) -> bool {
        self.proxy[v] as usize == v
    }
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let p = parent[x as usize];
        parent[x as usize] = parent[p as usize];
        x = p;
    }
    x
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
    // UV islands: connected components of UV indices through the UV triangles.
    let mut parent: Vec<u32> = (0..mesh.uvs.len() as u32).collect();
    for t in &mesh.uv_triangles {
        let a = find(&mut parent, t[0]);
        for &c in &t[1..] {
            let b = find(&mut parent, c);
            if a != b {
                parent[b as usize] = a;
            }
        }
    }
    let island_of = |parent: &mut Vec<u32>, t: usize| find(parent, mesh.uv_triangles[t][0]);
    let mut sewn_islands = std::collections::HashSet::new();
    for b in bundles {
        sewn_islands.insert(island_of(&mut parent, b.triangle as usize));
    }
    let nv = mesh.num_vertices();
    let mut vertex_uv = vec![DVec2::NAN; nv];
    let mut in_space = vec![false; nv];
    let mut edge_count: HashMap<(u32, u32), (u32, [DVec2; 2])> = HashMap::new();
    for t in 0..mesh.triangles.len() {
        if !sewn_islands.contains(&island_of(&mut parent, t)) {
            continue;
        }
        let tri = mesh.triangles[t];
        let uvt = mesh.uv_triangles[t];
        for c in 0..3 {
            let v = tri[c] as usize;
            if !in_space[v] {
                in_space[v] = true;
                vertex_uv[v] = mesh.uvs[uvt[c] as usize];
            }
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
mod tests {
    use super::*;

    #[test]
    fn proxies_equal_brute_force_nearest() {
        let mut s = 7u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let pos: Vec<DVec3> = (0..600)
            .map(|_| DVec3::new(rnd(), rnd(), rnd() * 0.3))
            .collect();
        let in_space: Vec<bool> = pos.iter().map(|p| p.x < 0.6).collect();
        let inside: Vec<u32> = (0..600).filter(|&v| in_space[v as usize]).collect();
        let got = proxies(&pos, &in_space, &inside);
        for v in 0..600 {
            if in_space[v] {
                assert_eq!(got[v] as usize, v);
                continue;
            }
            let want = inside
                .iter()
                .copied()
                .min_by(|&a, &b| {
                    pos[v]
                        .distance_squared(pos[a as usize])
                        .total_cmp(&pos[v].distance_squared(pos[b as usize]))
                        .then(a.cmp(&b))
                })
                .unwrap();
            assert_eq!(got[v], want, "vertex {v}");
        }
    }
}
