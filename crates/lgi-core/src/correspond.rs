//! Correspondences of marker rest positions to the neutral surface: the closest surface point as
//! (triangle, barycentric), found with an obvhs BVH and an exact f64 best-first nearest search so
//! the answer is bit-identical to brute force over all triangles (ties go to the lowest triangle).

use crate::error::{LgiError, Result};
use crate::geom::closest_point_on_triangle;
use crate::mesh::{Mesh, SurfacePoint};
use glam::{DVec3, Vec3A};
use obvhs::aabb::Aabb;
use obvhs::bvh2::builder::build_bvh2;
use obvhs::BvhBuildParams;
use rayon::prelude::*;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// A BVH node in f64, converted once from obvhs's f32 `Bvh2` so queries need no casts.
#[derive(Debug, Clone, Copy)]
struct Node {
    lo: DVec3,
    hi: DVec3,
    /// Inner node: index of the first child (the second is `first + 1`). Leaf: first slot.
    first: u32,
    /// 0 for inner nodes, number of triangles for leaves.
    count: u32,
}

/// Comparisons of squared distances against box bounds allow this relative slack, so the f64
/// rounding of the bound and of the point–triangle distance can never prune a triangle that brute
/// force would pick (including exact ties).
const REL_SLACK: f64 = 1e-9;

/// Boxes are grown by this fraction of their largest absolute coordinate: the absolute
/// counterpart of `REL_SLACK` for points that lie on or very near a box.
const BOX_PAD: f64 = 1e-9;

/// Coordinates beyond this overflow the f32 BVH; far beyond any facial data set.
const MAX_COORD: f64 = 1e30;

/// BVH over a mesh's triangles answering exact closest-point queries. `Send + Sync`: share one
/// between threads.
#[derive(Debug, Clone)]
pub struct SurfaceIndex {
    nodes: Vec<Node>,
    /// Triangle corners in BVH leaf order (slot order), for locality during queries.
    corners: Vec<[DVec3; 3]>,
    /// Original triangle index of each slot.
    ids: Vec<u32>,
}

/// Largest f32 `<= x` (x finite, within f32 range): box bounds must not shrink when rounded.
fn f32_down(x: f64) -> f32 {
    let f = x as f32;
    if f64::from(f) <= x {
        f
    } else if f == 0.0 {
        -f32::from_bits(1)
    } else if f > 0.0 {
        f32::from_bits(f.to_bits() - 1)
    } else {
        f32::from_bits(f.to_bits() + 1)
    }
}

/// Smallest f32 `>= x`.
fn f32_up(x: f64) -> f32 {
    -f32_down(-x)
}

/// Squared distance from `p` to the box, a lower bound for anything inside it.
#[inline]
fn box_distance_squared(p: DVec3, lo: DVec3, hi: DVec3) -> f64 {
    let d = (lo - p).max(p - hi).max(DVec3::ZERO);
    d.length_squared()
}

/// Heap entry ordered so that `BinaryHeap` (a max-heap) pops the smallest bound first; ties on
/// the node index keep the visiting order deterministic.
#[derive(Debug, Clone, Copy)]
struct Entry {
    bound: f64,
    node: u32,
}

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .bound
            .total_cmp(&self.bound)
            .then_with(|| other.node.cmp(&self.node))
    }
}

impl SurfaceIndex {
    /// Builds the BVH over `mesh`'s triangles. Errors if the mesh is invalid (see
    /// [`Mesh::validate`]) or has coordinates beyond `1e30`.
    pub fn new(mesh: &Mesh) -> Result<Self> {
        mesh.validate("surface mesh")?;
        if let Some(v) = mesh
            .positions
            .iter()
            .position(|p| p.abs().max_element() > MAX_COORD)
        {
            return Err(LgiError::Dataset(format!(
                "surface mesh: vertex {v} has a coordinate beyond {} {}",
                crate::text::num(MAX_COORD),
                crate::text::point(mesh.positions[v])
            )));
        }
        let tris: Vec<[DVec3; 3]> = (0..mesh.triangles.len())
            .map(|t| mesh.triangle(t))
            .collect();
        // Rounded outwards so every f32 box really contains its f64 triangle.
        let aabbs: Vec<Aabb> = tris
            .iter()
            .map(|[a, b, c]| {
                let lo = a.min(*b).min(*c);
                let hi = a.max(*b).max(*c);
                Aabb::new(
                    Vec3A::new(f32_down(lo.x), f32_down(lo.y), f32_down(lo.z)),
                    Vec3A::new(f32_up(hi.x), f32_up(hi.y), f32_up(hi.z)),
                )
            })
            .collect();
        let mut build_time = std::time::Duration::ZERO;
        let bvh = build_bvh2(&aabbs, BvhBuildParams::medium_build(), &mut build_time);

        let nodes: Vec<Node> = bvh
            .nodes
            .iter()
            .map(|n| {
                let b = n.aabb();
                let lo = DVec3::new(b.min.x.into(), b.min.y.into(), b.min.z.into());
                let hi = DVec3::new(b.max.x.into(), b.max.y.into(), b.max.z.into());
                let pad = BOX_PAD * lo.abs().max(hi.abs()).max_element();
                Node {
                    lo: lo - DVec3::splat(pad),
                    hi: hi + DVec3::splat(pad),
                    first: n.first_index,
                    count: n.prim_count,
                }
            })
            .collect();
        // Internal consistency of the third-party tree, checked once so queries can index freely.
        let ok = !nodes.is_empty()
            && bvh.primitive_indices.len() == tris.len()
            && bvh
                .primitive_indices
                .iter()
                .all(|&i| (i as usize) < tris.len())
            && nodes.iter().all(|n| {
                if n.count == 0 {
                    (n.first as usize) + 1 < nodes.len()
                } else {
                    (n.first as usize) + (n.count as usize) <= tris.len()
                }
            });
        if !ok {
            return Err(LgiError::Dataset(format!(
                "surface mesh: BVH construction over {} triangles produced an inconsistent tree",
                tris.len()
            )));
        }
        let corners = bvh
            .primitive_indices
            .iter()
            .map(|&i| tris[i as usize])
            .collect();
        Ok(SurfaceIndex {
            nodes,
            corners,
            ids: bvh.primitive_indices,
        })
    }

    /// Number of triangles indexed.
    pub fn num_triangles(&self) -> usize {
        self.ids.len()
    }

    /// Closest point of the surface to `p` and its distance. Exactly the answer of brute force
    /// over all triangles with [`closest_point_on_triangle`] (smallest squared distance; ties go
    /// to the lowest triangle index). A non-finite `p` gives triangle 0 and a NaN distance.
    pub fn closest(&self, p: DVec3) -> (SurfacePoint, f64) {
        self.closest_with(p, &mut BinaryHeap::new())
    }

    /// [`SurfaceIndex::closest`] for many points, in parallel; results in the order of `points`.
    pub fn closest_many(&self, points: &[DVec3]) -> Vec<(SurfacePoint, f64)> {
        points
            .par_iter()
            .map_init(BinaryHeap::new, |heap, &p| self.closest_with(p, heap))
            .collect()
    }

    /// Best-first search: nodes are visited in order of their box's lower bound, so the search
    /// stops as soon as the nearest unvisited box is farther than the best triangle so far.
    fn closest_with(&self, p: DVec3, heap: &mut BinaryHeap<Entry>) -> (SurfacePoint, f64) {
        if !p.is_finite() {
            return (
                SurfacePoint {
                    triangle: 0,
                    bary: [1.0, 0.0, 0.0],
                },
                f64::NAN,
            );
        }
        heap.clear();
        let mut best_d2 = f64::INFINITY;
        let mut best_id = u32::MAX;
        let mut best_bary = [1.0, 0.0, 0.0];
        let mut limit = f64::INFINITY;
        heap.push(Entry {
            bound: 0.0,
            node: 0,
        });
        while let Some(Entry { bound, node }) = heap.pop() {
            if bound > limit {
                break;
            }
            let n = self.nodes[node as usize];
            if n.count > 0 {
                let start = n.first as usize;
                for slot in start..start + n.count as usize {
                    let [a, b, c] = self.corners[slot];
                    let (q, bary) = closest_point_on_triangle(p, a, b, c);
                    let d2 = p.distance_squared(q);
                    let id = self.ids[slot];
                    if d2 < best_d2 || (d2 == best_d2 && id < best_id) {
                        best_d2 = d2;
                        best_id = id;
                        best_bary = bary;
                        limit = best_d2 * (1.0 + REL_SLACK);
                    }
                }
            } else {
                for child in [n.first, n.first + 1] {
                    let c = self.nodes[child as usize];
                    let bound = box_distance_squared(p, c.lo, c.hi);
                    if bound <= limit {
                        heap.push(Entry { bound, node: child });
                    }
                }
            }
        }
        (
            SurfacePoint {
                triangle: best_id,
                bary: best_bary,
            },
            best_d2.sqrt(),
        )
    }
}

/// Correspondences for marker rest positions: each marker's closest point on `mesh` and its
/// distance to it, in marker order.
///
/// Errors: [`LgiError::MarkerOffSurface`] for the first marker farther than `tolerance`
/// (absolute, in data units); [`LgiError::Input`] naming the index of the first non-finite
/// marker, or for a negative/NaN tolerance; mesh errors from [`SurfaceIndex::new`].
pub fn correspond(
    mesh: &Mesh,
    markers: &[DVec3],
    tolerance: f64,
) -> Result<Vec<(SurfacePoint, f64)>> {
    if tolerance.is_nan() || tolerance < 0.0 {
        return Err(LgiError::Input(format!(
            "marker tolerance must be a non-negative number, got {tolerance}"
        )));
    }
    if let Some(i) = markers.iter().position(|m| !m.is_finite()) {
        return Err(LgiError::Input(format!(
            "marker {i} has a non-finite rest position {}",
            crate::text::point(markers[i])
        )));
    }
    let index = SurfaceIndex::new(mesh)?;
    let found = index.closest_many(markers);
    if let Some((i, &(_, distance))) = found.iter().enumerate().find(|(_, (_, d))| *d > tolerance) {
        return Err(LgiError::MarkerOffSurface {
            index: i,
            distance,
            tolerance,
        });
    }
    Ok(found)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Independent reference: every triangle, smallest squared distance, lowest index on ties.
    fn brute_force(mesh: &Mesh, p: DVec3) -> (SurfacePoint, f64) {
        let mut best = (u32::MAX, f64::INFINITY, [0.0; 3]);
        for t in 0..mesh.triangles.len() {
            let [a, b, c] = mesh.triangle(t);
            let (q, bary) = closest_point_on_triangle(p, a, b, c);
            let d2 = p.distance_squared(q);
            if d2 < best.1 {
                best = (t as u32, d2, bary);
            }
        }
        (
            SurfacePoint {
                triangle: best.0,
                bary: best.2,
            },
            best.1.sqrt(),
        )
    }

    fn assert_same(mesh: &Mesh, got: (SurfacePoint, f64), want: (SurfacePoint, f64), p: DVec3) {
        let scale = want.1.max(1e-300);
        assert!(
            (got.1 - want.1).abs() <= 1e-12 * scale,
            "distance {} vs brute force {} at {p:?}",
            got.1,
            want.1
        );
        assert_eq!(got.0, want.0, "surface point differs at {p:?}");
        assert!(got.0.position(mesh).distance(want.0.position(mesh)) <= 1e-12 * (1.0 + scale));
    }

    /// A `n x n` grid of quads (2 triangles each) over [0,1]^2 with height noise.
    fn grid_mesh(n: usize, heights: &[f64]) -> Mesh {
        let mut positions = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let k = (j * (n + 1) + i) % heights.len();
                positions.push(DVec3::new(
                    i as f64 / n as f64,
                    j as f64 / n as f64,
                    0.05 * heights[k],
                ));
            }
        }
        let mut triangles = Vec::new();
        let w = (n + 1) as u32;
        for j in 0..n as u32 {
            for i in 0..n as u32 {
                let a = j * w + i;
                triangles.push([a, a + 1, a + w + 1]);
                triangles.push([a, a + w + 1, a + w]);
            }
        }
        Mesh {
            positions,
            triangles,
            ..Default::default()
        }
    }

    /// A UV sphere of radius `r` (poles are single vertices).
    fn sphere_mesh(r: f64, stacks: u32, slices: u32) -> Mesh {
        let mut positions = vec![DVec3::new(0.0, 0.0, r)];
        for s in 1..stacks {
            let th = std::f64::consts::PI * s as f64 / stacks as f64;
            for k in 0..slices {
                let ph = std::f64::consts::TAU * k as f64 / slices as f64;
                positions.push(r * DVec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()));
            }
        }
        positions.push(DVec3::new(0.0, 0.0, -r));
        let south = positions.len() as u32 - 1;
        let ring = |s: u32, k: u32| 1 + (s - 1) * slices + (k % slices);
        let mut triangles = Vec::new();
        for k in 0..slices {
            triangles.push([0, ring(1, k), ring(1, k + 1)]);
            triangles.push([south, ring(stacks - 1, k + 1), ring(stacks - 1, k)]);
        }
        for s in 1..stacks - 1 {
            for k in 0..slices {
                let (a, b) = (ring(s, k), ring(s, k + 1));
                let (c, d) = (ring(s + 1, k), ring(s + 1, k + 1));
                triangles.push([a, c, d]);
                triangles.push([a, d, b]);
            }
        }
        Mesh {
            positions,
            triangles,
            ..Default::default()
        }
    }

    fn coord() -> impl Strategy<Value = f64> {
        -1.0f64..1.0
    }

    fn point() -> impl Strategy<Value = DVec3> {
        (coord(), coord(), coord()).prop_map(|(x, y, z)| DVec3::new(x, y, z))
    }

    fn soup() -> impl Strategy<Value = Mesh> {
        prop::collection::vec((point(), point(), point()), 1..120).prop_map(|tris| {
            let mut positions = Vec::new();
            let mut triangles = Vec::new();
            for (i, (a, b, c)) in tris.into_iter().enumerate() {
                positions.extend([a, b, c]);
                let i = 3 * i as u32;
                triangles.push([i, i + 1, i + 2]);
            }
            Mesh {
                positions,
                triangles,
                ..Default::default()
            }
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

        #[test]
        fn bvh_closest_equals_brute_force_on_random_triangle_soups(
            mesh in soup(),
            queries in prop::collection::vec((point(), 0.0f64..30.0), 1..40),
        ) {
            let index = SurfaceIndex::new(&mesh).unwrap();
            for (q, scale) in queries {
                let p = q * scale;
                assert_same(&mesh, index.closest(p), brute_force(&mesh, p), p);
            }
        }

        #[test]
        fn bvh_closest_stays_exact_far_from_the_origin_where_f32_boxes_round(
            mesh in soup(),
            offset in prop_oneof![Just(1.0e5), Just(-3.3e6), 1.0e3f64..1.0e7],
            queries in prop::collection::vec((point(), 0.0f64..2.0), 1..40),
        ) {
            // Triangles of size ~1e-2 at 1e5..1e7: an f32 ulp there is as large as the triangles,
            // so boxes rounded to nearest would prune the true answer.
            let shift = DVec3::new(offset, -0.5 * offset, 0.25 * offset);
            let mesh = Mesh {
                positions: mesh.positions.iter().map(|p| shift + *p * 1e-2).collect(),
                ..mesh
            };
            let index = SurfaceIndex::new(&mesh).unwrap();
            for (q, scale) in queries {
                let p = shift + q * (1e-2 * scale);
                assert_same(&mesh, index.closest(p), brute_force(&mesh, p), p);
            }
        }

        #[test]
        fn bvh_closest_equals_brute_force_on_perturbed_grid(
            n in 23usize..32,
            heights in prop::collection::vec(-1.0f64..1.0, 7..50),
            queries in prop::collection::vec(
                (0.0f64..1.0, 0.0f64..1.0, prop_oneof![-0.02f64..0.02, -3.0f64..3.0]), 1..30),
        ) {
            // 2 n^2 = 1058..1922 triangles.
            let mesh = grid_mesh(n, &heights);
            let index = SurfaceIndex::new(&mesh).unwrap();
            for (x, y, z) in queries {
                let p = DVec3::new(x * 1.4 - 0.2, y * 1.4 - 0.2, z);
                assert_same(&mesh, index.closest(p), brute_force(&mesh, p), p);
            }
        }

        #[test]
        fn vertices_and_edge_midpoints_map_to_themselves_at_zero_distance(
            n in 2usize..12,
            heights in prop::collection::vec(-1.0f64..1.0, 3..20),
        ) {
            // Exact ties between neighbouring triangles: the lowest index must win.
            let mesh = grid_mesh(n, &heights);
            let index = SurfaceIndex::new(&mesh).unwrap();
            for t in 0..mesh.triangles.len() {
                let [a, b, _] = mesh.triangle(t);
                for p in [a, b, (a + b) * 0.5] {
                    let got = index.closest(p);
                    assert_same(&mesh, got, brute_force(&mesh, p), p);
                    assert!(got.1 <= 1e-14);
                }
            }
        }
    }

    #[test]
    fn sphere_points_project_radially_onto_the_tessellated_sphere() {
        let r = 2.0;
        let mesh = sphere_mesh(r, 24, 48);
        let index = SurfaceIndex::new(&mesh).unwrap();
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        // Chord sagitta bounds how far the tessellation lies inside the sphere.
        let sag = r * (1.0 - (std::f64::consts::PI / 24.0).cos());
        for _ in 0..500 {
            let dir = DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize();
            let rho = 0.5 + 4.0 * next();
            let p = dir * rho;
            let got = index.closest(p);
            assert_same(&mesh, got, brute_force(&mesh, p), p);
            let q = got.0.position(&mesh);
            assert!(q.length() <= r + 1e-12 && q.length() >= r - sag - 1e-12);
            if rho > r + sag {
                assert!((got.1 - (rho - q.length())).abs() <= sag + 1e-12);
            }
            assert!(got.0.bary.iter().all(|&b| b >= -1e-12));
            assert!((got.0.bary.iter().sum::<f64>() - 1.0).abs() <= 1e-12);
        }
    }

    #[test]
    fn evaluate_follows_a_deformed_mesh_with_the_same_topology() {
        let mesh = sphere_mesh(1.0, 8, 16);
        let index = SurfaceIndex::new(&mesh).unwrap();
        let (sp, _) = index.closest(DVec3::new(0.3, 0.8, 0.9));
        let moved: Vec<DVec3> = mesh.positions.iter().map(|p| *p * 3.0 + DVec3::X).collect();
        let want = sp.position(&mesh) * 3.0 + DVec3::X;
        assert!(sp.evaluate(&mesh.triangles, &moved).distance(want) < 1e-12);
        let bad = SurfacePoint {
            triangle: 10_000,
            bary: [1.0, 0.0, 0.0],
        };
        assert!(bad.position(&mesh).is_nan());
    }

    #[test]
    fn correspond_reports_the_first_off_surface_marker_by_index() {
        let mesh = sphere_mesh(1.0, 12, 24);
        let markers = [
            DVec3::new(0.0, 0.0, 1.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(0.0, 3.0, 0.0),
            DVec3::new(0.0, 0.0, 5.0),
        ];
        match correspond(&mesh, &markers, 0.1) {
            Err(LgiError::MarkerOffSurface {
                index,
                distance,
                tolerance,
            }) => {
                assert_eq!(index, 2);
                assert!((distance - 2.0).abs() < 1e-9);
                assert_eq!(tolerance, 0.1);
            }
            other => panic!("expected MarkerOffSurface, got {other:?}"),
        }
        let ok = correspond(&mesh, &markers[..2], 0.1).unwrap();
        assert_eq!(ok.len(), 2);
        assert!(ok.iter().all(|(_, d)| *d < 1e-12));
    }

    #[test]
    fn correspond_rejects_non_finite_markers_and_bad_tolerance() {
        let mesh = sphere_mesh(1.0, 6, 8);
        let markers = [DVec3::ZERO, DVec3::new(0.0, f64::NAN, 0.0)];
        match correspond(&mesh, &markers, 1.0) {
            Err(LgiError::Input(msg)) => assert!(msg.contains("marker 1"), "{msg}"),
            other => panic!("expected Input error, got {other:?}"),
        }
        let inf = [DVec3::new(f64::INFINITY, 0.0, 0.0)];
        assert!(matches!(
            correspond(&mesh, &inf, 1.0),
            Err(LgiError::Input(_))
        ));
        assert!(matches!(
            correspond(&mesh, &[DVec3::ZERO], f64::NAN),
            Err(LgiError::Input(_))
        ));
        assert!(correspond(&mesh, &[], 0.0).unwrap().is_empty());
    }

    #[test]
    fn index_rejects_invalid_meshes_and_survives_non_finite_queries() {
        assert!(SurfaceIndex::new(&Mesh::default()).is_err());
        let huge = Mesh {
            positions: vec![DVec3::ZERO, DVec3::X, DVec3::splat(1e31)],
            triangles: vec![[0, 1, 2]],
            ..Default::default()
        };
        assert!(matches!(
            SurfaceIndex::new(&huge),
            Err(LgiError::Dataset(_))
        ));
        let one = Mesh {
            positions: vec![DVec3::ZERO, DVec3::X, DVec3::Y],
            triangles: vec![[0, 1, 2]],
            ..Default::default()
        };
        let index = SurfaceIndex::new(&one).unwrap();
        assert_eq!(index.num_triangles(), 1);
        assert!(index.closest(DVec3::NAN).1.is_nan());
        let (sp, d) = index.closest(DVec3::new(0.25, 0.25, 2.0));
        assert_eq!(sp.triangle, 0);
        assert!((d - 2.0).abs() < 1e-15);
    }

    #[test]
    fn outward_rounding_never_shrinks_a_bound() {
        for x in [
            0.1,
            -0.1,
            1e-40,
            -1e-40,
            0.0,
            3.0,
            16_777_217.0,
            -1e30,
            1e30,
        ] {
            assert!(f64::from(f32_down(x)) <= x, "{x}");
            assert!(f64::from(f32_up(x)) >= x, "{x}");
        }
    }

    #[test]
    fn surface_index_is_send_and_sync() {
        fn check<T: Send + Sync>() {}
        check::<SurfaceIndex>();
    }
}
