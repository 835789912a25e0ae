//! Overlapping, non-manifold tetrahedra over a bundle's point cloud. Unlike a Delaunay mesh they
//! may overlap, so one bundle position can have several candidate geometries; the production
//! generator builds them from local neighbourhoods and keeps the best-shaped ones.
//!
//! A cloud with fewer than 4 points, or whose points are all coplanar (e.g. shapes that move a
//! bundle only within a plane), yields no tetrahedra: every candidate has zero volume. That is
//! allowed; the solver then falls back to its outside-projection path.

use glam::{DMat3, DVec3};

use crate::geom::closest_point_on_triangle;

/// A tetrahedron: four indices into the cloud's points, sorted ascending.
pub type Tet = [u32; 4];

/// Scale-invariant shape quality in `[0, 1]`: `6·√2·|V| / l_rms³`, where `V` is the volume and
/// `l_rms` the root mean square of the six edge lengths. It is 1 for a regular tetrahedron (the
/// maximum) and 0 for a flat (coplanar) or collapsed one. (This is the "volume–length" measure,
/// not the mean-ratio measure: both vanish together, this one is cheaper.) Non-finite input gives 0.
pub fn tet_quality(p: [DVec3; 4]) -> f64 {
    let e1 = p[1] - p[0];
    let e2 = p[2] - p[0];
    let e3 = p[3] - p[0];
    let volume = e1.dot(e2.cross(e3)).abs() / 6.0;
    let sum_sq = e1.length_squared()
        + e2.length_squared()
        + e3.length_squared()
        + (p[2] - p[1]).length_squared()
        + (p[3] - p[1]).length_squared()
        + (p[3] - p[2]).length_squared();
    let l_rms = (sum_sq / 6.0).sqrt();
    let q = 6.0 * std::f64::consts::SQRT_2 * volume / (l_rms * l_rms * l_rms);
    if q.is_finite() {
        q.clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// Parameters of the tetrahedron generator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TetConfig {
    /// How many nearest neighbours of each point take part in its tetrahedra (`C(k, 3)` per point).
    pub neighbours: usize,
    /// At most this many tetrahedra per bundle (the best-quality ones are kept).
    pub max_tets: usize,
    /// Tetrahedra of lower [`tet_quality`] are dropped; zero-volume ones are always dropped.
    pub min_quality: f64,
    /// Tetrahedra with an edge longer than this (absolute distance) are dropped;
    /// `f64::INFINITY` means no limit.
    pub max_edge: f64,
}

impl Default for TetConfig {
    fn default() -> Self {
        TetConfig {
            neighbours: 10,
            max_tets: 20_000,
            min_quality: 0.02,
            max_edge: f64::INFINITY,
        }
    }
}

/// The filter shared by [`all_tets`] and [`generate_tets`]; returns the quality when accepted.
fn accept(points: &[DVec3], t: &Tet, cfg: &TetConfig) -> Option<f64> {
    let p = t.map(|i| points[i as usize]);
    let max_edge_sq = cfg.max_edge * cfg.max_edge;
    for a in 0..4 {
        for b in (a + 1)..4 {
            let len_sq = p[a].distance_squared(p[b]);
            if len_sq.is_nan() || len_sq > max_edge_sq {
                return None;
            }
        }
    }
    let q = tet_quality(p);
    (q > 0.0 && q >= cfg.min_quality).then_some(q)
}

/// Reference definition: every one of the `C(n, 4)` tetrahedra with positive quality
/// `>= min_quality` and all edges `<= max_edge`, in lexicographic order. Ignores `neighbours`
/// and `max_tets`. O(n⁴): for tests and small clouds only.
pub fn all_tets(points: &[DVec3], cfg: &TetConfig) -> Vec<Tet> {
    let n = points.len() as u32;
    let mut out = Vec::new();
    for a in 0..n {
        for b in (a + 1)..n {
            for c in (b + 1)..n {
                for d in (c + 1)..n {
                    let t = [a, b, c, d];
                    if accept(points, &t, cfg).is_some() {
                        out.push(t);
                    }
                }
            }
        }
    }
    out
}

/// Production generator: for each point, every 4-subset of {point} ∪ its `neighbours` nearest
/// other points that contains the point (`C(k, 3)` per point), deduplicated, filtered as in
/// [`all_tets`], ordered best quality first (ties: lexicographic), truncated to `max_tets`, and
/// returned in lexicographic order. Deterministic; always a subset of [`all_tets`], and equal to
/// it when `neighbours >= n - 1` and `max_tets` is large enough.
///
/// Cost: the neighbour search is a brute-force O(n²) selection (fine for the few hundred to few
/// thousand shapes of a dataset), then O(n·C(k, 3)·log) time and 16·n·C(k, 3) bytes for the
/// candidates (4 MB for n = 2000, k = 10; mind large `neighbours`).
pub fn generate_tets(points: &[DVec3], cfg: &TetConfig) -> Vec<Tet> {
    let n = points.len();
    if n < 4 || cfg.max_tets == 0 {
        return Vec::new();
    }
    let k = cfg.neighbours.min(n - 1);
    let mut candidates: Vec<Tet> = Vec::new();
    let mut others: Vec<(f64, u32)> = Vec::with_capacity(n);
    for (i, &pi) in points.iter().enumerate() {
        others.clear();
        others.extend(
            points
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(j, &pj)| (pi.distance_squared(pj), j as u32)),
        );
        // Ties by index keep the neighbourhood deterministic; NaN distances sort last.
        let by_distance = |a: &(f64, u32), b: &(f64, u32)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
        if k < others.len() {
            others.select_nth_unstable_by(k, by_distance);
            others.truncate(k);
        }
        let nb: Vec<u32> = others.iter().map(|&(_, j)| j).collect();
        for a in 0..nb.len() {
            for b in (a + 1)..nb.len() {
                for c in (b + 1)..nb.len() {
                    let mut t = [i as u32, nb[a], nb[b], nb[c]];
                    t.sort_unstable();
                    candidates.push(t);
                }
            }
        }
    }
    candidates.sort_unstable();
    candidates.dedup();
    let mut scored: Vec<(f64, Tet)> = candidates
        .into_iter()
        .filter_map(|t| accept(points, &t, cfg).map(|q| (q, t)))
        .collect();
    scored.sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    scored.truncate(cfg.max_tets);
    let mut out: Vec<Tet> = scored.into_iter().map(|(_, t)| t).collect();
    out.sort_unstable();
    out
}

/// Inverse of the tet's edge matrix `[v1 - v0, v2 - v0, v3 - v0]`, or `None` when the tet is
/// flat (or not finite). Shared with the grid so both compute bit-identical barycentrics.
pub(crate) fn tet_inverse(t: [DVec3; 4]) -> Option<DMat3> {
    let m = DMat3::from_cols(t[1] - t[0], t[2] - t[0], t[3] - t[0]);
    let det = m.determinant();
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = m.inverse();
    inv.is_finite().then_some(inv)
}

/// Closest point of the solid tetrahedron `t` to `p`, with its barycentric coordinates (all
/// `>= 0`, sum 1). A point inside (all barycentrics `>= 0`) is returned unchanged. Otherwise the
/// closest point lies on a face whose plane separates `p` from the tet (negative barycentric of
/// the opposite vertex), so only those faces are searched. Flat tetrahedra work too: their solid
/// is the union of their faces, all of which are searched.
pub fn closest_point_in_tet(p: DVec3, t: [DVec3; 4]) -> (DVec3, [f64; 4]) {
    closest_point_in_tet_with(p, t, tet_inverse(t).as_ref())
}

/// [`closest_point_in_tet`] with the tet's [`tet_inverse`] already at hand.
pub(crate) fn closest_point_in_tet_with(
    p: DVec3,
    t: [DVec3; 4],
    inv: Option<&DMat3>,
) -> (DVec3, [f64; 4]) {
    // Faces to search, as a bit mask over the omitted vertex.
    let mut faces = 0b1111u8;
    if let Some(inv) = inv {
        let l = *inv * (p - t[0]);
        let b = [1.0 - l.x - l.y - l.z, l.x, l.y, l.z];
        if b.iter().all(|&x| x >= 0.0) {
            return (p, b);
        }
        if b.iter().all(|x| x.is_finite()) {
            faces = (0..4).filter(|&i| b[i] < 0.0).fold(0, |m, i| m | (1 << i));
        }
    }
    // Face f omits vertex f.
    const FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]];
    let mut best = (t[0], [1.0, 0.0, 0.0, 0.0]);
    let mut best_d2 = f64::INFINITY;
    for (f, face) in FACES.iter().enumerate() {
        if faces & (1 << f) == 0 {
            continue;
        }
        let (q, fb) = closest_point_on_triangle(p, t[face[0]], t[face[1]], t[face[2]]);
        let d2 = p.distance_squared(q);
        if d2 < best_d2 {
            let mut b = [0.0; 4];
            for (slot, &w) in face.iter().zip(&fb) {
                b[*slot] = w;
            }
            best = (q, b);
            best_d2 = d2;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use proptest::test_runner::{Config, RngSeed};

    fn regular() -> [DVec3; 4] {
        [
            DVec3::new(1.0, 1.0, 1.0),
            DVec3::new(1.0, -1.0, -1.0),
            DVec3::new(-1.0, 1.0, -1.0),
            DVec3::new(-1.0, -1.0, 1.0),
        ]
    }

    fn config(cases: u32, seed: u64) -> Config {
        Config {
            cases,
            rng_seed: RngSeed::Fixed(seed),
            failure_persistence: None,
            max_global_rejects: cases * 4,
            ..Config::default()
        }
    }

    #[test]
    fn regular_tet_has_quality_one_and_flat_or_collapsed_tets_zero() {
        assert!((tet_quality(regular()) - 1.0).abs() < 1e-14);
        let flat = [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(0.3, 0.3, 0.0)];
        assert_eq!(tet_quality(flat), 0.0);
        assert_eq!(tet_quality([DVec3::ONE; 4]), 0.0);
        assert_eq!(tet_quality([DVec3::NAN, DVec3::X, DVec3::Y, DVec3::Z]), 0.0);
    }

    #[test]
    fn quality_is_invariant_under_similarity_transforms() {
        let t = [
            DVec3::ZERO,
            DVec3::X,
            DVec3::new(0.2, 0.9, 0.0),
            DVec3::new(0.1, 0.3, 0.4),
        ];
        let rot = DMat3::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 0.7);
        let moved = t.map(|p| rot * p * 37.5 + DVec3::new(-3.0, 8.0, 1.0));
        assert!((tet_quality(t) - tet_quality(moved)).abs() < 1e-12);
    }

    #[test]
    fn fewer_than_four_or_coplanar_points_give_no_tets() {
        let cfg = TetConfig {
            min_quality: 0.0,
            ..TetConfig::default()
        };
        assert!(generate_tets(&[DVec3::ZERO, DVec3::X, DVec3::Y], &cfg).is_empty());
        let plane: Vec<DVec3> = (0..12)
            .map(|i| DVec3::new((i % 4) as f64, (i / 4) as f64 * 1.3, 0.0))
            .collect();
        assert!(generate_tets(&plane, &cfg).is_empty());
        assert!(all_tets(&plane, &cfg).is_empty());
    }

    #[test]
    fn max_tets_keeps_the_best_quality_ones() {
        let pts = lcg_points(12, 7);
        let cfg = TetConfig {
            neighbours: 11,
            max_tets: usize::MAX,
            min_quality: 0.0,
            max_edge: f64::INFINITY,
        };
        let all = generate_tets(&pts, &cfg);
        let few = generate_tets(
            &pts,
            &TetConfig {
                max_tets: 10,
                ..cfg
            },
        );
        assert_eq!(few.len(), 10);
        let q = |t: &Tet| tet_quality(t.map(|i| pts[i as usize]));
        let worst_kept = few.iter().map(q).fold(f64::INFINITY, f64::min);
        let best_dropped = all
            .iter()
            .filter(|t| !few.contains(t))
            .map(q)
            .fold(0.0, f64::max);
        assert!(worst_kept >= best_dropped);
        assert!(few.windows(2).all(|w| w[0] < w[1]));
    }

    #[test]
    fn max_edge_drops_long_tets() {
        let pts = lcg_points(10, 3);
        let cfg = TetConfig {
            neighbours: 9,
            max_tets: usize::MAX,
            min_quality: 0.0,
            max_edge: 0.6,
        };
        let tets = generate_tets(&pts, &cfg);
        assert_eq!(tets, all_tets(&pts, &cfg));
        for t in &tets {
            for a in 0..4 {
                for b in 0..4 {
                    assert!(pts[t[a] as usize].distance(pts[t[b] as usize]) <= 0.6);
                }
            }
        }
    }

    #[test]
    fn inside_point_is_its_own_closest_point() {
        let t = regular();
        let p = DVec3::new(0.1, -0.2, 0.05);
        let (q, b) = closest_point_in_tet(p, t);
        assert_eq!(q, p);
        let r = t[0] * b[0] + t[1] * b[1] + t[2] * b[2] + t[3] * b[3];
        assert!(r.distance(p) < 1e-14);
    }

    /// Deterministic pseudo-random points in the unit cube.
    fn lcg_points(n: usize, seed: u64) -> Vec<DVec3> {
        let mut s = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        (0..n).map(|_| DVec3::new(next(), next(), next())).collect()
    }

    /// Exact reference for the closest point: enumerate all 15 faces of the simplex (vertices,
    /// edges, triangles, the solid), project onto each one's affine hull by solving the normal
    /// equations, keep the feasible projections (all barycentrics >= 0), take the nearest.
    fn reference_closest(p: DVec3, t: [DVec3; 4]) -> f64 {
        let mut best = f64::INFINITY;
        for mask in 1u32..16 {
            let idx: Vec<usize> = (0..4).filter(|i| mask & (1 << i) != 0).collect();
            let base = t[idx[0]];
            let e: Vec<DVec3> = idx[1..].iter().map(|&i| t[i] - base).collect();
            let m = e.len();
            // Gram system G mu = E^T (p - base), solved by Gaussian elimination with pivoting.
            let mut g = vec![vec![0.0; m + 1]; m];
            for r in 0..m {
                for c in 0..m {
                    g[r][c] = e[r].dot(e[c]);
                }
                g[r][m] = e[r].dot(p - base);
            }
            let mut ok = true;
            for col in 0..m {
                let piv = (col..m)
                    .max_by(|&a, &b| g[a][col].abs().total_cmp(&g[b][col].abs()))
                    .unwrap();
                if g[piv][col].abs() < 1e-14 {
                    ok = false;
                    break;
                }
                g.swap(col, piv);
                let pivot_row = g[col].clone();
                for (r, row) in g.iter_mut().enumerate() {
                    if r != col {
                        let f = row[col] / pivot_row[col];
                        for (x, &y) in row.iter_mut().zip(&pivot_row).skip(col) {
                            *x -= f * y;
                        }
                    }
                }
            }
            if !ok {
                continue;
            }
            let mu: Vec<f64> = (0..m).map(|r| g[r][m] / g[r][r]).collect();
            let first = 1.0 - mu.iter().sum::<f64>();
            if first < -1e-12 || mu.iter().any(|&x| x < -1e-12) {
                continue;
            }
            let q = base + e.iter().zip(&mu).map(|(v, &w)| *v * w).sum::<DVec3>();
            best = best.min(p.distance(q));
        }
        best
    }

    fn arb_point(r: f64) -> impl Strategy<Value = DVec3> {
        (-r..r, -r..r, -r..r).prop_map(|(x, y, z)| DVec3::new(x, y, z))
    }

    proptest! {
        #![proptest_config(config(1024, 0x07e7_c105))]

        #[test]
        fn closest_point_in_tet_matches_face_enumeration_reference(
            t in [arb_point(1.0), arb_point(1.0), arb_point(1.0), arb_point(1.0)],
            p in arb_point(2.5),
        ) {
            prop_assume!(tet_quality(t) > 0.005);
            let (q, b) = closest_point_in_tet(p, t);
            let d = p.distance(q);
            let reference = reference_closest(p, t);
            prop_assert!((d - reference).abs() <= 1e-9 * (1.0 + reference), "{} vs {}", d, reference);
            prop_assert!(b.iter().all(|&x| x >= 0.0));
            prop_assert!((b.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            let r = t[0] * b[0] + t[1] * b[1] + t[2] * b[2] + t[3] * b[3];
            prop_assert!(r.distance(q) < 1e-12);
        }

        #[test]
        fn interior_barycentric_combination_is_returned_unchanged(
            t in [arb_point(1.0), arb_point(1.0), arb_point(1.0), arb_point(1.0)],
            w in [0.01..1.0f64, 0.01..1.0f64, 0.01..1.0f64, 0.01..1.0f64],
        ) {
            prop_assume!(tet_quality(t) > 0.05);
            let s: f64 = w.iter().sum();
            let p = (t[0] * w[0] + t[1] * w[1] + t[2] * w[2] + t[3] * w[3]) / s;
            let (q, b) = closest_point_in_tet(p, t);
            prop_assert_eq!(q, p);
            for i in 0..4 {
                prop_assert!((b[i] - w[i] / s).abs() < 1e-9);
            }
        }
    }

    proptest! {
        #![proptest_config(config(48, 0x07e7_59e4))]

        #[test]
        fn generated_tets_are_a_subset_of_all_tets_and_equal_with_full_neighbourhoods(
            n in 4usize..16,
            seed in any::<u64>(),
            k in 3usize..8,
            min_quality in 0.0..0.3f64,
            max_edge in 0.3..2.0f64,
        ) {
            let pts = lcg_points(n, seed);
            let cfg = TetConfig { neighbours: k, max_tets: usize::MAX, min_quality, max_edge };
            let all = all_tets(&pts, &cfg);
            let gen = generate_tets(&pts, &cfg);
            prop_assert!(gen.windows(2).all(|w| w[0] < w[1]));
            prop_assert!(gen.iter().all(|t| all.binary_search(t).is_ok()));
            prop_assert!(gen.iter().all(|t| t.windows(2).all(|w| w[0] < w[1])));
            let full = TetConfig { neighbours: n - 1, ..cfg };
            prop_assert_eq!(generate_tets(&pts, &full), all.clone());
            let more = TetConfig { neighbours: n + 5, ..cfg };
            prop_assert_eq!(generate_tets(&pts, &more), all);
        }
    }

    #[test]
    fn generated_tets_cover_a_small_cloud_of_30_points_with_full_neighbourhood() {
        let pts = lcg_points(30, 11);
        let cfg = TetConfig {
            neighbours: 29,
            max_tets: usize::MAX,
            ..TetConfig::default()
        };
        let gen = generate_tets(&pts, &cfg);
        assert_eq!(gen, all_tets(&pts, &cfg));
        assert!(!gen.is_empty());
    }
}
