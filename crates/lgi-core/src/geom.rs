//! Small exact geometric kernels in f64 shared by several modules: closest points on triangles
//! and barycentric coordinates. Kept here so every caller agrees on the same predicates.

use glam::DVec3;

/// Closest point of triangle `abc` to `p` and its barycentric coordinates `(u, v, w)` with
/// `point = u a + v b + w c`, `u + v + w = 1`, all `>= 0` (Ericson, Real-Time Collision
/// Detection, §5.1.5). Degenerate triangles fall back to the closest edge point.
pub fn closest_point_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> (DVec3, [f64; 3]) {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, [1.0, 0.0, 0.0]);
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + ab * v, [1.0 - v, v, 0.0]);
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac * w, [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, [0.0, 1.0 - w, w]);
    }
    let sum = va + vb + vc;
    if sum.abs() <= f64::MIN_POSITIVE || !sum.is_finite() {
        // Degenerate (collinear) triangle: the best of its three edges.
        return closest_on_degenerate(p, a, b, c);
    }
    let denom = 1.0 / sum;
    let v = vb * denom;
    let w = vc * denom;
    (a + ab * v + ac * w, [1.0 - v - w, v, w])
}

fn closest_on_segment(p: DVec3, a: DVec3, b: DVec3) -> (DVec3, f64) {
    let ab = b - a;
    let len2 = ab.length_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + ab * t, t)
}

fn closest_on_degenerate(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> (DVec3, [f64; 3]) {
    let (q0, t0) = closest_on_segment(p, a, b);
    let (q1, t1) = closest_on_segment(p, b, c);
    let (q2, t2) = closest_on_segment(p, c, a);
    let cands = [
        (q0, [1.0 - t0, t0, 0.0]),
        (q1, [0.0, 1.0 - t1, t1]),
        (q2, [t2, 0.0, 1.0 - t2]),
    ];
    let mut best = cands[0];
    for c in &cands[1..] {
        if p.distance_squared(c.0) < p.distance_squared(best.0) {
            best = *c;
        }
    }
    best
}

/// Barycentric interpolation of three values.
pub fn interpolate3(values: [DVec3; 3], bary: [f64; 3]) -> DVec3 {
    values[0] * bary[0] + values[1] * bary[1] + values[2] * bary[2]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute_closest(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
        // Dense sampling of the triangle: an independent (approximate) reference.
        let n = 200;
        let mut best = f64::INFINITY;
        for i in 0..=n {
            for j in 0..=(n - i) {
                let u = i as f64 / n as f64;
                let v = j as f64 / n as f64;
                let q = a + (b - a) * u + (c - a) * v;
                best = best.min(p.distance(q));
            }
        }
        best
    }

    #[test]
    fn closest_point_matches_dense_sampling_and_barycentrics_reconstruct_it() {
        let a = DVec3::new(0.0, 0.0, 0.0);
        let b = DVec3::new(1.0, 0.2, 0.0);
        let c = DVec3::new(0.3, 1.0, 0.1);
        for p in [
            DVec3::new(0.3, 0.3, 1.0),
            DVec3::new(-1.0, -1.0, 0.0),
            DVec3::new(2.0, 0.0, 0.5),
            DVec3::new(0.0, 2.0, -0.5),
            DVec3::new(1.0, 1.0, 0.0),
        ] {
            let (q, bary) = closest_point_on_triangle(p, a, b, c);
            let d = p.distance(q);
            assert!((d - brute_closest(p, a, b, c)).abs() < 1e-2);
            assert!(d <= brute_closest(p, a, b, c) + 1e-12);
            assert!(interpolate3([a, b, c], bary).distance(q) < 1e-12);
            assert!(bary.iter().all(|&x| x >= -1e-12));
        }
    }

    #[test]
    fn degenerate_triangle_gives_closest_edge_point() {
        let a = DVec3::ZERO;
        let b = DVec3::X;
        let c = DVec3::X * 2.0;
        let (q, _) = closest_point_on_triangle(DVec3::new(1.5, 1.0, 0.0), a, b, c);
        assert!(q.distance(DVec3::new(1.5, 0.0, 0.0)) < 1e-12);
    }
}
