//! Surface distances for the "holes must not leak" rule: a bundle may weight a vertex only if
//! the path over the surface between them is not much longer than the straight line. Across
//! the mouth slit or an eye, the surface path detours around the hole's corner, while near the
//! corner (where the lips really join) it does not. Distances are shortest paths along mesh
//! edges (Dijkstra), bounded by a radius so each bundle explores only its neighbourhood.

use crate::hash::FastMap;
use crate::mesh::{Mesh, SurfacePoint};
use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap};
use std::sync::{Arc, Mutex};

/// Vertex adjacency of a set of triangles, with edge lengths (CSR).
#[derive(Debug, Clone)]
pub struct EdgeGraph {
    start: Vec<u32>,
    next: Vec<(u32, f64)>,
}

impl EdgeGraph {
    /// The graph of the edges of `triangles[t]` for every `t` with `keep(t)`.
    pub fn new(mesh: &Mesh, keep: impl Fn(usize) -> bool) -> Self {
        let n = mesh.num_vertices();
        let mut edges: Vec<(u32, u32)> = Vec::new();
        for (t, tri) in mesh.triangles.iter().enumerate() {
            if !keep(t) {
                continue;
            }
            for c in 0..3 {
                let (a, b) = (tri[c], tri[(c + 1) % 3]);
                edges.push((a, b));
                edges.push((b, a));
            }
        }
        edges.sort_unstable();
        edges.dedup();
        let mut start = vec![0u32; n + 1];
        for &(a, _) in &edges {
            start[a as usize + 1] += 1;
        }
        for i in 0..n {
            start[i + 1] += start[i];
        }
        let p = &mesh.positions;
        let next = edges
            .iter()
            .map(|&(a, b)| (b, p[a as usize].distance(p[b as usize])))
            .collect();
        EdgeGraph { start, next }
    }

    /// Shortest edge-path distances from a surface point to every vertex within `radius`.
    pub fn distances_from(
        &self,
        mesh: &Mesh,
        from: &SurfacePoint,
        radius: f64,
    ) -> FastMap<u32, f64> {
        let origin = from.position(mesh);
        let mut dist: FastMap<u32, f64> = FastMap::default();
        let mut heap = BinaryHeap::new();
        for &v in &mesh.triangles[from.triangle as usize] {
            let d = origin.distance(mesh.positions[v as usize]);
            heap.push(Item(d, v));
        }
        while let Some(Item(d, v)) = heap.pop() {
            if d > radius || dist.contains_key(&v) {
                continue;
            }
            dist.insert(v, d);
            let (s, e) = (self.start[v as usize], self.start[v as usize + 1]);
            for &(u, len) in &self.next[s as usize..e as usize] {
                if !dist.contains_key(&u) {
                    heap.push(Item(d + len, u));
                }
            }
        }
        dist
    }
}

/// Distances from one source to every vertex within `radius` ([`EdgeGraph::distances_from`]).
#[derive(Debug, Clone)]
pub struct Field {
    /// The radius the field was computed to.
    pub radius: f64,
    /// Vertex → shortest edge-path distance, for every vertex within `radius`.
    pub distances: FastMap<u32, f64>,
}

/// Distance fields by source, kept across calls: a field computed to radius R answers every
/// radius ≤ R exactly (Dijkstra settles a vertex by its shortest path alone, so a vertex's
/// distance does not depend on how far the search went), and a vertex beyond the asked
/// radius is just farther than it. Sewing plans for new sets of missing bundles ask the same
/// neighbouring bundles again and again.
#[derive(Debug, Default)]
pub struct FieldCache {
    fields: Mutex<HashMap<u32, Arc<Field>>>,
}

impl FieldCache {
    /// The field of `source` to at least `radius`: the cached one when it reaches that far,
    /// else `compute(r)` for `r = max(radius, 1.5 × the cached radius)` (growing in steps, so a
    /// source asked a little farther each time is not recomputed each time), then cached.
    pub fn field(
        &self,
        source: u32,
        radius: f64,
        compute: impl FnOnce(f64) -> FastMap<u32, f64>,
    ) -> Arc<Field> {
        let cached = self
            .fields
            .lock()
            .ok()
            .and_then(|f| f.get(&source).cloned());
        if let Some(f) = &cached {
            if f.radius >= radius {
                return f.clone();
            }
        }
        let r = cached.map_or(radius, |f| radius.max(1.5 * f.radius));
        let field = Arc::new(Field {
            radius: r,
            distances: compute(r),
        });
        if let Ok(mut fields) = self.fields.lock() {
            let keep = fields.get(&source).is_some_and(|f| f.radius >= r);
            if !keep {
                fields.insert(source, field.clone());
            }
        }
        field
    }

    /// Number of cached fields (for tests).
    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.fields.lock().map_or(0, |f| f.len())
    }

    /// True when nothing is cached.
    #[cfg(test)]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Min-heap item (distance, vertex).
struct Item(f64, u32);
impl PartialEq for Item {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for Item {}
impl PartialOrd for Item {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Item {
    fn cmp(&self, o: &Self) -> Ordering {
        o.0.total_cmp(&self.0).then(o.1.cmp(&self.1))
    }
}

/// Whether the surface path `path` between two points `straight` apart is a detour around a
/// hole: longer than `ratio` times the straight line, plus `slack` for mesh-edge zigzag at
/// short range.
pub fn is_detour(path: f64, straight: f64, ratio: f64, slack: f64) -> bool {
    path > ratio * straight + slack
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec2, DVec3};

    /// A 2D strip mesh in the plane with a slit cut between rows: grid n×n with the middle
    /// row's vertices duplicated so the slit separates upper and lower halves for columns
    /// 1..n-2 while the ends stay joined.
    fn grid(n: usize) -> Mesh {
        let mut positions = Vec::new();
        for y in 0..n {
            for x in 0..n {
                positions.push(DVec3::new(x as f64, y as f64, 0.0));
            }
        }
        let mut triangles = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let a = (y * n + x) as u32;
                triangles.push([a, a + 1, a + n as u32 + 1]);
                triangles.push([a, a + n as u32 + 1, a + n as u32]);
            }
        }
        Mesh {
            positions,
            triangles,
            uvs: vec![DVec2::ZERO],
            uv_triangles: vec![],
        }
    }

    #[test]
    fn edge_path_distances_match_manhattan_diagonal_closed_form_on_a_grid() {
        let m = grid(6);
        let g = EdgeGraph::new(&m, |_| true);
        let from = SurfacePoint {
            triangle: 0,
            bary: [1.0, 0.0, 0.0],
        };
        let d = g.distances_from(&m, &from, f64::INFINITY);
        // Shortest path on this triangulation: diagonal steps (sqrt 2) then straight ones.
        for y in 0..6usize {
            for x in 0..6usize {
                let (lo, hi) = (x.min(y) as f64, x.max(y) as f64);
                let want = lo * 2f64.sqrt() + (hi - lo);
                assert!((d[&((y * 6 + x) as u32)] - want).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn radius_bounds_the_search() {
        let m = grid(6);
        let g = EdgeGraph::new(&m, |_| true);
        let from = SurfacePoint {
            triangle: 0,
            bary: [1.0, 0.0, 0.0],
        };
        let d = g.distances_from(&m, &from, 2.0);
        assert!(d.values().all(|&x| x <= 2.0));
        assert!(d.contains_key(&2) && !d.contains_key(&3));
    }

    #[test]
    fn a_slit_turns_close_points_into_a_detour() {
        // Remove the triangles of the middle band except at both ends: a slit.
        let n = 7;
        let m = grid(n);
        let g = EdgeGraph::new(&m, |t| {
            let (cell, _) = (t / 2, t % 2);
            let (x, y) = (cell % (n - 1), cell / (n - 1));
            !(y == 3 && (1..n - 2).contains(&x))
        });
        let below = SurfacePoint {
            triangle: (2 * (n - 1) + 3) as u32 * 2,
            bary: [1.0, 0.0, 0.0],
        };
        let d = g.distances_from(&m, &below, f64::INFINITY);
        let above = (5 * n + 3) as u32;
        let straight_d = below.position(&m).distance(m.positions[above as usize]);
        assert!(
            is_detour(d[&above], straight_d, 2.0, 0.0),
            "{} vs {straight_d}",
            d[&above]
        );
    }
}
