//! Tests of the jaw skinning: the blended map and its exact inverse against an independent
//! rotation formula, frames, bins, and the pose fit recovering known poses.

use super::*;
use proptest::prelude::*;

/// Rodrigues' formula, written out independently of glam's rotation constructors.
fn axis_angle(axis: [f64; 3], angle: f64) -> [[f64; 3]; 3] {
    let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    let (x, y, z) = (axis[0] / n, axis[1] / n, axis[2] / n);
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]
}

fn matmul(a: [[f64; 3]; 3], b: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, e) in row.iter_mut().enumerate() {
            *e = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    m
}

fn apply(m: [[f64; 3]; 3], p: DVec3) -> DVec3 {
    let p = [p.x, p.y, p.z];
    let r: Vec<f64> = m
        .iter()
        .map(|row| row[0] * p[0] + row[1] * p[1] + row[2] * p[2])
        .collect();
    DVec3::new(r[0], r[1], r[2])
}

/// Points and poses (open, lateral, forward) of the closed-form rigid-motion tests.
const RIGID_POINTS: [DVec3; 4] = [
    DVec3::new(0.0, -6.0, 9.0),
    DVec3::new(3.0, -4.0, 8.0),
    DVec3::new(-2.5, -2.0, 7.5),
    DVec3::new(1.0, 2.0, -3.0),
];
const RIGID_POSES: [(f64, f64, f64); 3] = [(0.4, 0.0, 0.0), (0.0, -0.2, 0.0), (0.3, 0.15, 0.7)];

fn rig(weights: Vec<f64>) -> JawRig {
    JawRig::new(DVec3::new(0.0, -1.5, 3.0), weights).unwrap()
}

#[test]
fn weight_one_vertices_move_by_the_closed_form_rigid_motion() {
    let r = rig(vec![1.0; 4]);
    let pts = RIGID_POINTS;
    for (open, lateral, forward) in RIGID_POSES {
        let theta = JawParams {
            open,
            lateral,
            forward,
        };
        let m = matmul(
            axis_angle([0.0, 1.0, 0.0], lateral),
            axis_angle([1.0, 0.0, 0.0], open),
        );
        let mut out = vec![DVec3::ZERO; pts.len()];
        r.skin(&pts, theta, &mut out).unwrap();
        let affine = JawRig::transform(theta, r.pivot);
        for (p, q) in pts.iter().zip(&out) {
            let expected = apply(m, *p - r.pivot) + r.pivot + DVec3::new(0.0, 0.0, forward);
            assert!((*q - expected).length() < 1e-12, "{q} vs {expected}");
            assert!((affine.transform_point3(*p) - expected).length() < 1e-12);
        }
    }
}

#[test]
fn positive_open_moves_the_chin_down_and_back_and_positive_lateral_towards_plus_x() {
    let r = rig(vec![1.0]);
    let chin = DVec3::new(0.0, -6.0, 8.0);
    let opened = r.skin_point(chin, 1.0, JawParams::from_array([0.3, 0.0, 0.0]));
    assert!(opened.y < chin.y && opened.z < chin.z);
    let lateral = r.skin_point(chin, 1.0, JawParams::from_array([0.0, 0.1, 0.0]));
    assert!(lateral.x > chin.x);
    let forward = r.skin_point(chin, 1.0, JawParams::from_array([0.0, 0.0, 0.5]));
    assert!((forward - chin - DVec3::new(0.0, 0.0, 0.5)).length() < 1e-15);
}

#[test]
fn weight_zero_and_rest_pose_leave_points_bit_identical() {
    let r = rig(vec![0.0, 0.7]);
    let pts = [DVec3::new(1.3, -4.1, 7.7), DVec3::new(-0.3, -5.9, 8.2)];
    let mut out = vec![DVec3::ZERO; 2];
    r.skin(&pts, JawParams::from_array([0.4, 0.1, 0.3]), &mut out)
        .unwrap();
    assert_eq!(out[0], pts[0]);
    assert_ne!(out[1], pts[1]);
    r.skin(&pts, JawParams::ZERO, &mut out).unwrap();
    assert_eq!(out, pts.to_vec());
    r.unskin(&pts, JawParams::ZERO, &mut out).unwrap();
    assert_eq!(out, pts.to_vec());
}

#[test]
fn partial_weight_is_the_linear_blend_of_skull_and_jaw() {
    let r = rig(vec![0.3]);
    let p = DVec3::new(0.5, -5.0, 8.0);
    let theta = JawParams::from_array([0.35, -0.1, 0.4]);
    let jaw = JawRig::transform(theta, r.pivot).transform_point3(p);
    let expected = 0.7 * p + 0.3 * jaw;
    assert!((r.skin_point(p, 0.3, theta) - expected).length() < 1e-12);
}

#[test]
fn unskinned_displacements_reskin_to_the_shape() {
    let weights = vec![0.0, 0.25, 0.5, 1.0];
    let r = rig(weights);
    let neutral = vec![
        DVec3::new(0.0, 2.0, 9.0),
        DVec3::new(1.0, -3.0, 9.5),
        DVec3::new(-1.0, -4.0, 9.0),
        DVec3::new(0.0, -6.0, 8.5),
    ];
    let theta = JawParams::from_array([0.4, 0.05, 0.2]);
    let disp: Vec<f32> = vec![
        0.1, 0.0, 0.0, 0.0, -0.5, -0.2, 0.02, -1.0, -0.4, 0.0, -2.0, -1.2,
    ];
    let star = r.unskin_displacements(&neutral, &disp, theta).unwrap();
    for v in 0..4 {
        let s = DVec3::new(
            f64::from(star[3 * v]),
            f64::from(star[3 * v + 1]),
            f64::from(star[3 * v + 2]),
        );
        let back = r.skin_point(neutral[v] + s, r.weights[v], theta) - neutral[v];
        let d = DVec3::new(
            f64::from(disp[3 * v]),
            f64::from(disp[3 * v + 1]),
            f64::from(disp[3 * v + 2]),
        );
        // f32 storage of s* bounds the error, not the inversion.
        assert!((back - d).length() < 1e-5, "vertex {v}: {back} vs {d}");
    }
    let all = r
        .unskin_shapes(&neutral, &[disp.clone(), disp].concat(), &[theta; 2])
        .unwrap();
    assert_eq!(&all[..12], &star[..]);
    assert_eq!(&all[12..], &star[..]);
}

#[test]
fn a_pure_jaw_shape_unskins_to_zero_on_fully_weighted_vertices() {
    let r = rig(vec![1.0, 1.0]);
    let neutral = vec![DVec3::new(0.0, -6.0, 8.5), DVec3::new(2.0, -5.0, 8.0)];
    let theta = JawParams::from_array([0.43, 0.0, 0.0]);
    let mut skinned = vec![DVec3::ZERO; 2];
    r.skin(&neutral, theta, &mut skinned).unwrap();
    let disp: Vec<f32> = skinned
        .iter()
        .zip(&neutral)
        .flat_map(|(s, n)| {
            let d = *s - *n;
            [d.x as f32, d.y as f32, d.z as f32]
        })
        .collect();
    let star = r.unskin_displacements(&neutral, &disp, theta).unwrap();
    assert!(star.iter().all(|x| x.abs() < 1e-5), "{star:?}");
}

#[test]
fn invalid_rigs_and_inputs_are_rejected_with_a_named_element() {
    let err = JawRig::new(DVec3::ZERO, vec![0.0, 1.2]).unwrap_err();
    assert!(err.to_string().contains("vertex 1"), "{err}");
    let err = JawRig::new(DVec3::ZERO, vec![f64::NAN]).unwrap_err();
    assert!(err.to_string().contains("vertex 0"), "{err}");
    assert!(JawRig::new(DVec3::new(f64::NAN, 0.0, 0.0), vec![]).is_err());
    let r = rig(vec![0.5, 0.5]);
    let mut out = vec![DVec3::ZERO; 1];
    assert!(r.skin(&[DVec3::ZERO], JawParams::ZERO, &mut out).is_err());
    let mut out = vec![DVec3::ZERO; 2];
    let bad = JawParams::from_array([4.0, 0.0, 0.0]);
    assert!(r.skin(&[DVec3::ZERO; 2], bad, &mut out).is_err());
    let nan = JawParams::from_array([0.0, f64::NAN, 0.0]);
    assert!(r.unskin(&[DVec3::ZERO; 2], nan, &mut out).is_err());
    assert!(r
        .unskin_displacements(&[DVec3::ZERO; 2], &[0.0; 5], JawParams::ZERO)
        .is_err());
    assert!(r.interpolate_weight([0, 1, 2], [0.2, 0.3, 0.5]).is_err());
}

#[test]
fn bundle_weight_is_the_barycentric_blend_of_vertex_weights() {
    let r = rig(vec![0.0, 0.5, 1.0]);
    let w = r.interpolate_weight([0, 1, 2], [0.2, 0.3, 0.5]).unwrap();
    assert!((w - (0.15 + 0.5)).abs() < 1e-15);
}

fn mat(m: [[f64; 3]; 3]) -> DMat3 {
    DMat3::from_cols_array_2d(&[
        [m[0][0], m[1][0], m[2][0]],
        [m[0][1], m[1][1], m[2][1]],
        [m[0][2], m[1][2], m[2][2]],
    ])
}

fn tilted_rig(weights: Vec<f64>, frame: [[f64; 3]; 3]) -> JawRig {
    JawRig::with_frame(DVec3::new(0.0, -1.5, 3.0), weights, mat(frame)).unwrap()
}

#[test]
fn weight_one_vertices_in_a_tilted_frame_rotate_about_the_frame_axes_by_rodrigues() {
    let f = axis_angle([0.3, -0.5, 1.0], 0.4);
    let r = tilted_rig(vec![1.0; 4], f);
    // The frame's columns: the open axis, the lateral axis and the forward direction.
    let col = |j: usize| [f[0][j], f[1][j], f[2][j]];
    let pts = RIGID_POINTS;
    for (open, lateral, forward) in RIGID_POSES {
        let theta = JawParams {
            open,
            lateral,
            forward,
        };
        // Open about the frame's first axis, then lateral about its second (both world
        // axes through the pivot), then forward along its third.
        let m = matmul(axis_angle(col(1), lateral), axis_angle(col(0), open));
        let shift = DVec3::from_array(col(2)) * forward;
        let mut out = vec![DVec3::ZERO; pts.len()];
        r.skin(&pts, theta, &mut out).unwrap();
        let affine = r.rigid_transform(theta);
        for (p, q) in pts.iter().zip(&out) {
            let expected = apply(m, *p - r.pivot) + r.pivot + shift;
            assert!((*q - expected).length() < 1e-12, "{q} vs {expected}");
            assert!((affine.transform_point3(*p) - expected).length() < 1e-12);
            assert!((r.skin_point(*p, 1.0, theta) - expected).length() < 1e-12);
        }
    }
}

#[test]
fn identity_frame_is_bit_identical_to_the_frame_less_blend() {
    // The blend as it was before rigs had a frame, written out here.
    fn old_skin(pivot: DVec3, theta: JawParams, p: DVec3, w: f64) -> DVec3 {
        let m = theta.rotation() - DMat3::IDENTITY;
        let d = p - pivot;
        let row = |r: glam::DVec3| r.z.mul_add(d.z, r.y.mul_add(d.y, r.x * d.x));
        let t = m.transpose();
        let moved = DVec3::new(row(t.x_axis), row(t.y_axis), row(t.z_axis));
        p + w * (moved + theta.translation())
    }
    fn old_unskin(pivot: DVec3, theta: JawParams, y: DVec3, w: f64) -> DVec3 {
        if w == 0.0 {
            return y;
        }
        let m = DMat3::IDENTITY + (theta.rotation() - DMat3::IDENTITY) * w;
        let rhs = y - pivot - w * theta.translation();
        let inv = m.inverse();
        let mut q = inv * rhs;
        q += inv * (rhs - m * q);
        pivot + q
    }
    let weights = vec![0.0, 0.2, 0.5, 0.8, 1.0, 1.0];
    let neutral = vec![
        DVec3::new(0.0, 2.0, 9.0),
        DVec3::new(1.0, -3.0, 9.5),
        DVec3::new(-1.0, -4.0, 9.0),
        DVec3::new(0.0, -6.0, 8.5),
        DVec3::new(2.0, -5.5, 8.0),
        DVec3::new(-3.0, -1.0, 6.0),
    ];
    let plain = JawRig::new(DVec3::new(0.0, -1.5, 3.0), weights.clone()).unwrap();
    let framed =
        JawRig::with_frame(DVec3::new(0.0, -1.5, 3.0), weights.clone(), DMat3::IDENTITY).unwrap();
    assert_eq!(plain, framed);
    let disp: Vec<f32> = (0..18).map(|i| 0.05 * (i as f32 - 9.0)).collect();
    for theta in [
        JawParams::from_array([0.4, 0.05, 0.2]),
        JawParams::from_array([-0.1, -0.3, -0.7]),
    ] {
        let mut skinned = vec![DVec3::ZERO; 6];
        framed.skin(&neutral, theta, &mut skinned).unwrap();
        let mut back = vec![DVec3::ZERO; 6];
        framed.unskin(&skinned, theta, &mut back).unwrap();
        let map = framed.vertex_map(Some(theta), Some(theta), 6).unwrap();
        for v in 0..6 {
            let (p, w) = (neutral[v], weights[v]);
            let s = old_skin(plain.pivot, theta, p, w);
            assert_eq!(skinned[v], s, "skin, vertex {v}");
            assert_eq!(back[v], old_unskin(plain.pivot, theta, s, w), "unskin {v}");
            assert_eq!(
                map.apply(v, s),
                old_skin(plain.pivot, theta, old_unskin(plain.pivot, theta, s, w), w)
            );
        }
        let star = framed.unskin_displacements(&neutral, &disp, theta).unwrap();
        for v in 0..6 {
            let s = DVec3::new(
                f64::from(disp[3 * v]),
                f64::from(disp[3 * v + 1]),
                f64::from(disp[3 * v + 2]),
            );
            let d = old_unskin(plain.pivot, theta, neutral[v] + s, weights[v]) - neutral[v];
            assert_eq!(
                &star[3 * v..3 * v + 3],
                &[d.x as f32, d.y as f32, d.z as f32]
            );
        }
    }
}

#[test]
fn a_tilted_frame_at_rest_pose_or_weight_zero_leaves_points_bit_identical() {
    let r = tilted_rig(vec![0.0, 0.6], axis_angle([1.0, 2.0, -0.5], 0.7));
    let pts = [DVec3::new(1.3, -4.1, 7.7), DVec3::new(-0.3, -5.9, 8.2)];
    let mut out = vec![DVec3::ZERO; 2];
    r.skin(&pts, JawParams::ZERO, &mut out).unwrap();
    assert_eq!(out, pts.to_vec());
    r.unskin(&pts, JawParams::ZERO, &mut out).unwrap();
    assert_eq!(out, pts.to_vec());
    r.skin(&pts, JawParams::from_array([0.3, 0.1, 0.2]), &mut out)
        .unwrap();
    assert_eq!(out[0], pts[0]);
}

#[test]
fn invalid_frames_are_rejected_naming_the_problem() {
    let ok = mat(axis_angle([0.2, 1.0, 0.3], 1.1));
    let with = |f: DMat3| JawRig::with_frame(DVec3::ZERO, vec![0.5], f);
    assert!(with(ok).is_ok());
    // Within the tolerance: a frame rounded to ~1e-12 is accepted.
    assert!(with(ok * (1.0 + 1e-12)).is_ok());
    let cases = [
        (ok * 1.001, "orthonormal"),
        (
            ok + DMat3::from_cols(DVec3::ZERO, DVec3::X * 1e-6, DVec3::ZERO),
            "orthonormal",
        ),
        (
            DMat3::from_cols(DVec3::X, DVec3::X, DVec3::Z),
            "orthonormal",
        ),
        (DMat3::ZERO, "orthonormal"),
        (
            DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0)),
            "reflection",
        ),
        (-ok, "reflection"),
        (
            DMat3::from_cols(DVec3::new(f64::NAN, 0.0, 0.0), DVec3::Y, DVec3::Z),
            "finite",
        ),
        (
            DMat3::from_cols(DVec3::X, DVec3::Y, DVec3::Z * f64::INFINITY),
            "finite",
        ),
    ];
    for (f, want) in cases {
        let e = with(f).unwrap_err();
        assert!(matches!(e, LgiError::Input(_)), "{f:?}: {e:?}");
        assert!(e.to_string().contains("jaw frame"), "{e}");
        assert!(e.to_string().contains(want), "{f:?}: {e}");
    }
}

/// Skinning a point and unskinning it (and the reverse) gives it back to 1e-12 of its
/// scale; returns that scale for the caller's further checks.
fn point_round_trips(r: &JawRig, p: DVec3, w: f64, theta: JawParams) -> Result<f64, TestCaseError> {
    let scale = 1.0 + p.length() + r.pivot.length();
    let back = r.unskin_point(r.skin_point(p, w, theta), w, theta);
    prop_assert!((back - p).length() <= 1e-12 * scale, "{back} vs {p}");
    let fwd = r.skin_point(r.unskin_point(p, w, theta), w, theta);
    prop_assert!((fwd - p).length() <= 1e-12 * scale, "{fwd} vs {p}");
    Ok(scale)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, rng_seed: proptest::test_runner::RngSeed::Fixed(0x7f3), ..ProptestConfig::default() })]
    #[test]
    fn unskin_inverts_skin_to_1e12_relative_in_a_random_frame(
        ax in -1f64..1.0, ay in -1f64..1.0, az in 0.1f64..1.0,
        angle in -3.1f64..3.1,
        open in -40f64..40.0,
        lateral in -15f64..15.0,
        forward in -2f64..2.0,
        w in 0f64..=1.0,
        x in -8f64..8.0, y in -9f64..9.0, z in -2f64..12.0,
    ) {
        let theta = JawParams { open: open.to_radians(), lateral: lateral.to_radians(), forward };
        let r = tilted_rig(vec![w], axis_angle([ax, ay, az], angle));
        let p = DVec3::new(x, y, z);
        let scale = point_round_trips(&r, p, w, theta)?;
        let mut out = [DVec3::ZERO];
        r.skin(&[p], theta, &mut out).unwrap();
        let mut back2 = [DVec3::ZERO];
        r.unskin(&out, theta, &mut back2).unwrap();
        prop_assert!((back2[0] - p).length() <= 1e-12 * scale);
        // The per-vertex map from θ to the rest pose undoes the skinning too.
        let map = r.vertex_map(Some(theta), None, 1).unwrap();
        prop_assert!((map.apply(0, out[0]) - p).length() <= 1e-12 * scale);
        // And the blend is the linear blend of skull and the frame's rigid motion.
        let lbs = (1.0 - w) * p + w * r.rigid_transform(theta).transform_point3(p);
        prop_assert!((out[0] - lbs).length() <= 1e-12 * scale, "{} vs {lbs}", out[0]);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, rng_seed: proptest::test_runner::RngSeed::Fixed(0x1a3), ..ProptestConfig::default() })]
    #[test]
    fn unskin_inverts_skin_to_1e12_relative(
        open in -40f64..40.0,
        lateral in -15f64..15.0,
        forward in -2f64..2.0,
        w in 0f64..=1.0,
        x in -8f64..8.0, y in -9f64..9.0, z in -2f64..12.0,
    ) {
        let theta = JawParams { open: open.to_radians(), lateral: lateral.to_radians(), forward };
        let r = rig(vec![w]);
        let p = DVec3::new(x, y, z);
        let scale = point_round_trips(&r, p, w, theta)?;
        let mut out = [DVec3::ZERO];
        r.skin_weighted(&[p], &[w], theta, &mut out).unwrap();
        let mut back2 = [DVec3::ZERO];
        r.unskin_weighted(&out, &[w], theta, &mut back2).unwrap();
        prop_assert!((back2[0] - p).length() <= 1e-12 * scale);
    }
}

/// A blob of points in a box below and in front of the pivot (a seeded LCG): 150 rigidly on
/// the jaw (weight 1), 150 partly (weights in [0.05, 0.95]), 100 on the skull (weight 0).
fn blob(seed: u64) -> (Vec<DVec3>, Vec<f64>) {
    let mut s = seed;
    let mut uniform = move |lo: f64, hi: f64| {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        lo + (hi - lo) * ((s >> 11) as f64 / (1u64 << 53) as f64)
    };
    let points = (0..400)
        .map(|_| DVec3::new(uniform(-5.0, 5.0), uniform(-8.0, 2.0), uniform(5.0, 10.0)))
        .collect();
    let weights = (0..400)
        .map(|i| match i {
            0..150 => 1.0,
            150..300 => uniform(0.05, 0.95),
            _ => 0.0,
        })
        .collect();
    (points, weights)
}

/// The blob's points skinned to `theta` by `r`, each with its weight.
fn skinned(r: &JawRig, points: &[DVec3], weights: &[f64], theta: JawParams) -> Vec<DVec3> {
    let mut out = vec![DVec3::ZERO; points.len()];
    r.skin_weighted(points, weights, theta, &mut out).unwrap();
    out
}

#[test]
fn the_pose_fit_recovers_a_known_pose_from_partially_weighted_points() {
    let (points, weights) = blob(3);
    let theta = JawParams::from_array([0.3, 0.08, -0.4]);
    for frame in [DMat3::IDENTITY, mat(axis_angle([0.3, -0.5, 1.0], 0.15))] {
        let r = JawRig::with_frame(DVec3::new(0.3, -1.2, 2.5), weights.clone(), frame).unwrap();
        let targets = skinned(&r, &points, &weights, theta);
        let (p, t, w) = (&points[150..300], &targets[150..300], &weights[150..300]);
        let got = r
            .fit_pose(p, t, Some(w), JawParams::ZERO, None, 50)
            .unwrap();
        for (a, b) in got.to_array().iter().zip(theta.to_array()) {
            assert!((a - b).abs() <= 1e-10, "{got:?} vs {theta:?}");
        }
        // Robust weights change nothing on exact targets.
        let robust = r.fit_pose(p, t, Some(w), JawParams::ZERO, Some(1.345), 50);
        let robust = robust.unwrap().to_array();
        assert!(robust
            .iter()
            .zip(theta.to_array())
            .all(|(a, b)| (a - b).abs() <= 1e-10));
    }
}

#[test]
fn the_robust_pose_fit_discounts_outliers_that_pull_the_plain_fit() {
    let (points, weights) = blob(8);
    let r = rig(weights.clone());
    let theta = JawParams::from_array([0.25, -0.06, 0.2]);
    let mut targets = skinned(&r, &points[..150], &weights[..150], theta);
    for t in targets.iter_mut().step_by(10) {
        *t += DVec3::new(0.8, -1.5, 0.6);
    }
    let error = |huber: Option<f64>| {
        let got = r
            .fit_pose(&points[..150], &targets, None, JawParams::ZERO, huber, 50)
            .unwrap();
        let d = got.to_array();
        let t = theta.to_array();
        (0..3).map(|c| (d[c] - t[c]).abs()).fold(0.0, f64::max)
    };
    let (plain, robust) = (error(None), error(Some(1.345)));
    assert!(robust < 0.2 * plain, "robust {robust:e}, plain {plain:e}");
}

#[test]
fn the_pose_fit_checks_its_arguments_and_stops_on_a_singular_system() {
    let r = rig(vec![1.0; 4]);
    let p = [DVec3::X, DVec3::Y, DVec3::Z];
    let e = r.fit_pose(&p, &p[..2], None, JawParams::ZERO, None, 50);
    assert!(e.unwrap_err().to_string().contains("targets"));
    let e = r.fit_pose(&p, &p, Some(&[1.0]), JawParams::ZERO, None, 50);
    assert!(e.unwrap_err().to_string().contains("weights"));
    let bad = JawParams::from_array([4.0, 0.0, 0.0]);
    assert!(r.fit_pose(&p, &p, None, bad, None, 50).is_err());
    // No points constrain nothing: the start comes back.
    let start = JawParams::from_array([0.1, 0.2, 0.3]);
    assert_eq!(r.fit_pose(&[], &[], None, start, None, 50).unwrap(), start);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, rng_seed: proptest::test_runner::RngSeed::Fixed(0x5e7), ..ProptestConfig::default() })]
    #[test]
    fn the_pose_fit_recovers_random_poses_in_random_frames(
        ax in -1f64..1.0, ay in -1f64..1.0, az in 0.1f64..1.0,
        angle in -3.1f64..3.1,
        open in -35f64..35.0,
        lateral in -12f64..12.0,
        forward in -1.5f64..1.5,
        seed in 0u64..1000,
    ) {
        let (points, weights) = blob(seed);
        let frame = mat(axis_angle([ax, ay, az], angle));
        let r = JawRig::with_frame(DVec3::new(0.3, -1.2, 2.5), weights.clone(), frame).unwrap();
        let theta = JawParams { open: open.to_radians(), lateral: lateral.to_radians(), forward };
        let targets = skinned(&r, &points, &weights, theta);
        let got = r.fit_pose(&points, &targets, Some(&weights), JawParams::ZERO, Some(1.345), 50).unwrap();
        for (a, b) in got.to_array().iter().zip(theta.to_array()) {
            prop_assert!((a - b).abs() <= 1e-9, "{:?} vs {:?}", got, theta);
        }
    }
}

#[test]
fn skinning_in_place_is_the_parallel_skin_bit_for_bit_and_checks_its_length() {
    let (points, weights) = blob(0x51d);
    let r = tilted_rig(weights, axis_angle([0.2, 1.0, -0.3], 0.4));
    for theta in [
        JawParams::ZERO,
        JawParams::from_array([0.3, 0.1, 0.2]),
        JawParams::from_array([-0.1, -0.05, 0.4]),
    ] {
        let mut out = vec![DVec3::ZERO; points.len()];
        r.skin(&points, theta, &mut out).unwrap();
        let mut in_place = points.clone();
        r.skin_in_place(&mut in_place, theta).unwrap();
        assert_eq!(in_place, out);
    }
    let err = r
        .skin_in_place(&mut points[..3].to_vec(), JawParams::ZERO)
        .unwrap_err()
        .to_string();
    assert!(err.contains("3 points, 400 weights"), "{err}");
}
