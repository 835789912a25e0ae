use super::*;
use crate::{FIT_L2, FIT_PENALTY};

/// A window's reach in units where the median spacing is 1.
const REACH: f64 = WINDOW_REACH * LOCAL_LENGTH;

/// Markers on a line one unit apart, two groups `gap` apart: the median spacing is 1, so a
/// window reaches `REACH` units.
fn two_groups(per_group: usize, gap: f64) -> Vec<DVec3> {
    (0..2 * per_group)
        .map(|i| {
            let x = (i % per_group) as f64 + if i < per_group { 0.0 } else { gap };
            DVec3::new(x, 0.0, 0.0)
        })
        .collect()
}

/// Row-major 3B × S matrix from per-shape, per-marker displacements.
fn matrix(displacements: &[Vec<DVec3>]) -> Vec<f64> {
    let (s, b) = (displacements.len(), displacements[0].len());
    let mut a = vec![0.0; 3 * b * s];
    for (k, shape) in displacements.iter().enumerate() {
        for (n, d) in shape.iter().enumerate() {
            for (c, v) in d.to_array().iter().enumerate() {
                a[(3 * n + c) * s + k] = *v;
            }
        }
    }
    a
}

#[test]
fn a_window_holds_exactly_the_markers_within_three_lengths() {
    let rest: Vec<DVec3> = (0..12).map(|i| DVec3::new(i as f64, 0.0, 0.0)).collect();
    let a = matrix(&[rest.iter().map(|_| DVec3::Z).collect()]);
    let fits = LocalFits::new(&a, 1, &rest, FIT_L2, FIT_PENALTY).unwrap();
    // Median nearest distance 1, so the window is every marker within `REACH` units (brute
    // force), and `lengths` spacings wide with `with_length`.
    let within = |reach: f64| -> Vec<usize> {
        (0..12)
            .map(|b| {
                (0..12)
                    .filter(|&m| rest[b].distance(rest[m]) <= reach + 1e-12)
                    .count()
            })
            .collect()
    };
    assert_eq!(fits.window_sizes(), within(REACH));
    for lengths in [0.5, 1.0, 2.0] {
        let wide = LocalFits::with_length(&a, 1, &rest, FIT_L2, FIT_PENALTY, lengths).unwrap();
        assert_eq!(wide.window_sizes(), within(WINDOW_REACH * lengths));
    }
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let e = LocalFits::with_length(&a, 1, &rest, FIT_L2, FIT_PENALTY, bad).unwrap_err();
        assert!(e.to_string().contains("marker spacings"), "{e}");
    }
}

#[test]
fn a_whole_face_scan_split_by_local_fits_matches_each_side_where_the_global_fit_compromises() {
    // One scan moves both groups by 1 in z; the frame has the left group at 1, the right at 0.2.
    let rest = two_groups(5, 100.0);
    let scan: Vec<DVec3> = rest.iter().map(|_| DVec3::Z).collect();
    let a = matrix(&[scan]);
    let fits = LocalFits::new(&a, 1, &rest, FIT_L2, FIT_PENALTY).unwrap();
    let target: Vec<f64> = (0..10)
        .flat_map(|i| [0.0, 0.0, if i < 5 { 1.0 } else { 0.2 }])
        .collect();
    let got = fits.solve(&target, &[0.5]).unwrap();
    assert_eq!(got.kept_start, 0);
    // Closed form of a one-shape ridge fit inside the box, the window's own scale:
    // w = Σ g t / (Σ g (1 + l2)), the window's mean squared column norm being Σ g.
    let weights = correlation_over(&rest, LOCAL_LENGTH);
    for b in 0..10 {
        let (mut num, mut den) = (0.0, 0.0);
        for m in 0..10 {
            let g = weights[b * 10 + m];
            if g >= (-4.5f64).exp() {
                num += g * target[3 * m + 2];
                den += g;
            }
        }
        let want = num / (den * (1.0 + FIT_L2));
        assert!(
            (got.weights[b] - want).abs() < 1e-12,
            "bundle {b}: {} vs {want}",
            got.weights[b]
        );
    }
    assert!((got.weights[0] - 1.0).abs() < 1e-3 && (got.weights[9] - 0.2).abs() < 1e-3);
    // The global fit of the same frame compromises at the mean, 0.6.
    let global = BlendshapeSolver::new(a.clone(), 30, 1, FIT_L2 * 10.0, FIT_PENALTY * 10.0)
        .unwrap()
        .solve(&target)
        .unwrap();
    assert!((global.weights[0] - 0.6).abs() < 1e-3);
}

#[test]
fn local_fits_equal_the_weighted_normal_equations_inside_the_box() {
    // Three shapes, twelve markers on a line: every window's minimum is inside [0, 1], where
    // it solves (AᵀGA + l2 I) w = AᵀG t (solved here by Gaussian elimination).
    let rest: Vec<DVec3> = (0..12).map(|i| DVec3::new(i as f64, 0.0, 0.0)).collect();
    let shapes: Vec<Vec<DVec3>> = (0..3i32)
        .map(|k| {
            rest.iter()
                .map(|p| {
                    let x = p.x / 11.0;
                    DVec3::new(
                        (x * f64::from(k + 1)).sin(),
                        x.powi(k + 1),
                        0.3 * f64::from(k) + x,
                    )
                })
                .collect()
        })
        .collect();
    let a = matrix(&shapes);
    let fits = LocalFits::new(&a, 3, &rest, FIT_L2, FIT_PENALTY).unwrap();
    let truth = [0.3, 0.5, 0.2];
    let target: Vec<f64> = (0..36)
        .map(|r| {
            (0..3).map(|k| a[r * 3 + k] * truth[k]).sum::<f64>() + 1e-3 * ((r * 7 % 5) as f64 - 2.0)
        })
        .collect();
    let got = fits.solve(&target, &[0.0; 3]).unwrap();
    let weights = correlation_over(&rest, LOCAL_LENGTH);
    for b in 0..12 {
        let mut m = [[0.0f64; 4]; 3];
        let mut scale = 0.0;
        for n in 0..12 {
            let g = weights[b * 12 + n];
            if g < (-4.5f64).exp() {
                continue;
            }
            for c in 0..3 {
                let r = 3 * n + c;
                for i in 0..3 {
                    scale += g * a[r * 3 + i] * a[r * 3 + i] / 3.0;
                    for j in 0..3 {
                        m[i][j] += g * a[r * 3 + i] * a[r * 3 + j];
                    }
                    m[i][3] += g * a[r * 3 + i] * target[r];
                }
            }
        }
        for (i, row) in m.iter_mut().enumerate() {
            row[i] += FIT_L2 * scale;
        }
        for p in 0..3 {
            for r in p + 1..3 {
                let f = m[r][p] / m[p][p];
                let pivot = m[p];
                for (x, y) in m[r][p..].iter_mut().zip(&pivot[p..]) {
                    *x -= f * y;
                }
            }
        }
        let mut w = [0.0; 3];
        for i in (0..3).rev() {
            w[i] = (m[i][3] - (i + 1..3).map(|j| m[i][j] * w[j]).sum::<f64>()) / m[i][i];
        }
        for (k, &want) in w.iter().enumerate() {
            assert!(want > 0.0 && want < 1.0);
            let x = got.weights[b * 3 + k];
            assert!(
                (x - want).abs() < 1e-9,
                "bundle {b} shape {k}: {x} vs {want}"
            );
        }
    }
}

#[test]
fn frames_fitted_in_order_from_the_last_frames_fit_equal_each_frame_fitted_alone() {
    // 60 scans mixing 4 directions over 12 markers (the low-rank form with its dual), six
    // frames moving smoothly and far enough that weights reach both ends of the box; frame 3
    // misses a marker (its start: the last fit's weights), frame 4 the same one (its start:
    // the last fit's dual point).
    let rest: Vec<DVec3> = (0..12).map(|i| DVec3::new(i as f64, 0.0, 0.0)).collect();
    let (shapes, base) = (60, 4);
    let dirs: Vec<Vec<DVec3>> = (0..base)
        .map(|j| {
            rest.iter()
                .map(|p| {
                    let x = p.x / 11.0 + j as f64;
                    DVec3::new((3.0 * x).sin(), (2.0 * x).cos(), x * x - 1.0)
                })
                .collect()
        })
        .collect();
    let scans: Vec<Vec<DVec3>> = (0..shapes)
        .map(|k| {
            (0..12)
                .map(|n| {
                    (0..base)
                        .map(|j| dirs[j][n] * (((k * 7 + j * 3) % 11) as f64 / 10.0))
                        .sum()
                })
                .collect()
        })
        .collect();
    let a = matrix(&scans);
    let fits = LocalFits::new(&a, shapes, &rest, FIT_L2, FIT_PENALTY).unwrap();
    assert!(fits
        .windows
        .iter()
        .all(|w| matches!(&w.fit, WindowFit::Boxed(s) if s.low_rank().is_some())));
    let frames = 6;
    let mut targets = Vec::new();
    for f in 0..frames {
        for r in 0..36 {
            let pose = 6.0 * (f as f64 - 2.0);
            targets.push(pose * (a[r * shapes + f] + a[r * shapes + 30]) + 0.05 * (r as f64).sin());
        }
    }
    for f in [3, 4] {
        for c in 0..3 {
            targets[f * 36 + 15 + c] = f64::NAN;
        }
    }
    let starts = vec![0.1; frames * shapes];
    let together = fits.solve(&targets, &starts).unwrap();
    assert_eq!(together.kept_start, 0);
    let (mut low, mut high) = (false, false);
    for f in 0..frames {
        let alone = fits
            .solve(&targets[f * 36..(f + 1) * 36], &starts[..shapes])
            .unwrap();
        let got = &together.weights[f * 12 * shapes..(f + 1) * 12 * shapes];
        for (x, y) in got.iter().zip(&alone.weights) {
            assert!((x - y).abs() < 1e-8, "frame {f}: {x} vs {y}");
            low |= *y < 0.0;
            high |= *y > 1.0;
        }
    }
    let lo = together
        .weights
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min);
    let hi = together
        .weights
        .iter()
        .cloned()
        .fold(f64::NEG_INFINITY, f64::max);
    assert!(
        low && high,
        "the frames reach both ends of the box: {lo} {hi}"
    );
}

#[test]
fn a_window_without_a_present_marker_keeps_its_start_and_says_so() {
    let rest = two_groups(4, 100.0);
    let a = matrix(&[rest.iter().map(|_| DVec3::Z).collect()]);
    let fits = LocalFits::new(&a, 1, &rest, FIT_L2, FIT_PENALTY).unwrap();
    // The right group missing in frame 0; everything present in frame 1.
    let mut target = vec![0.5; 48];
    for v in &mut target[12..24] {
        *v = f64::NAN;
    }
    let got = fits.solve(&target, &[0.25, 0.25]).unwrap();
    assert_eq!(got.kept_start, 4);
    assert!(got.weights[4..8].iter().all(|&w| w == 0.25));
    // A window with some markers missing fits the present ones: the left group's own.
    assert!((got.weights[0] - got.weights[8]).abs() < 1e-12);
}

#[test]
fn wrong_sizes_and_non_finite_input_are_errors_that_say_what() {
    let rest = two_groups(3, 10.0);
    let a = matrix(&[rest.iter().map(|_| DVec3::Z).collect()]);
    let e = LocalFits::new(&a[1..], 1, &rest, FIT_L2, FIT_PENALTY).unwrap_err();
    assert!(e.to_string().contains("18×1"), "{e}");
    let fits = LocalFits::new(&a, 1, &rest, FIT_L2, FIT_PENALTY).unwrap();
    let e = fits.solve(&[0.0; 17], &[0.0]).unwrap_err();
    assert!(e.to_string().contains("6 markers"), "{e}");
    let e = fits.solve(&[0.0; 18], &[0.0, 0.0]).unwrap_err();
    assert!(e.to_string().contains("start"), "{e}");
    let mut bad = vec![0.0; 18];
    bad[4] = f64::INFINITY;
    assert!(fits.solve(&bad, &[0.0]).is_err());
    let mut nan_rest = rest.clone();
    nan_rest[0].x = f64::NAN;
    assert!(LocalFits::new(&a, 1, &nan_rest, FIT_L2, FIT_PENALTY).is_err());
}

/// Sewing rows (CSR) of `v` vertices over `b` bundles: vertex i sewn to `1 + i % most`
/// bundles `(i + step e) % b`, entry e weighing `weight[0] + weight[1] e`.
fn sewing_rows(
    v: usize,
    b: usize,
    most: usize,
    step: usize,
    weight: [f64; 2],
) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
    let (mut indptr, mut indices, mut data) = (vec![0usize], Vec::new(), Vec::new());
    for i in 0..v {
        for e in 0..1 + i % most {
            indices.push((i + step * e) % b);
            data.push(weight[0] + weight[1] * e as f64);
        }
        indptr.push(indices.len());
    }
    (indptr, indices, data)
}

#[test]
fn the_blend_of_local_fits_is_each_vertexs_sewn_weights_on_its_shapes_by_brute_force() {
    // 700 vertices (two parallel tasks), 5 bundles, 11 shapes; each vertex sewn to 1–3 bundles.
    let (v, b, q) = (700usize, 5usize, 11usize);
    let value = |i: usize, k: usize| ((i * 31 + k * 17) % 97) as f64 / 97.0 - 0.5;
    let neutral: Vec<DVec3> = (0..v)
        .map(|i| DVec3::new(value(i, 1), value(i, 2), value(i, 3)))
        .collect();
    let shapes: Vec<f32> = (0..3 * v * q).map(|i| value(i, 5) as f32).collect();
    let weights: Vec<f64> = (0..b * q).map(|i| value(i, 7)).collect();
    let (indptr, indices, data) = sewing_rows(v, b, 3, 2, [0.2, 0.1]);
    let sewing = SewingRows {
        indptr: &indptr,
        indices: &indices,
        data: &data,
    };
    let mut out = vec![DVec3::ZERO; v];
    blend_local(&neutral, &shapes, sewing, &weights, &mut out).unwrap();
    for i in 0..v {
        let mut want = neutral[i];
        for e in indptr[i]..indptr[i + 1] {
            for j in 0..q {
                let w = data[e] * weights[indices[e] * q + j];
                let at = |d: usize| f64::from(shapes[(3 * i + d) * q + j]);
                want += w * DVec3::new(at(0), at(1), at(2));
            }
        }
        assert!((out[i] - want).length() < 1e-12, "vertex {i}");
    }
    // Sizes that do not fit, and a bundle out of range, are errors that say so.
    let short = SewingRows {
        indptr: &indptr[..v],
        ..sewing
    };
    let e = blend_local(&neutral, &shapes, short, &weights, &mut out).unwrap_err();
    assert!(e.to_string().contains("sewing rows"), "{e}");
    let e = blend_local(&neutral, &shapes, sewing, &weights[1..], &mut out).unwrap_err();
    assert!(e.to_string().contains("bundles"), "{e}");
    let e = blend_local(&neutral, &shapes[1..], sewing, &weights, &mut out).unwrap_err();
    assert!(e.to_string().contains("vertices"), "{e}");
    let few = &weights[..3 * q];
    let e = blend_local(&neutral, &shapes, sewing, few, &mut out).unwrap_err();
    assert!(e.to_string().contains("sewing rows"), "{e}");
}

#[test]
fn frames_blended_together_are_each_frame_blended_alone_bit_for_bit_on_both_builds() {
    // 1,100 vertices (three blocks), 4 bundles, 13 shapes (a tail past dot8's lanes), 5 frames.
    let (v, b, q, f) = (1100usize, 4usize, 13usize, 5usize);
    let value = |i: usize, k: usize| ((i * 37 + k * 13) % 101) as f64 / 101.0 - 0.5;
    let neutral: Vec<DVec3> = (0..v)
        .map(|i| DVec3::new(value(i, 1), value(i, 2), value(i, 3)))
        .collect();
    let shapes: Vec<f32> = (0..3 * v * q).map(|i| value(i, 5) as f32).collect();
    let weights: Vec<f64> = (0..f * b * q).map(|i| value(i, 7) * 1.7).collect();
    let (indptr, indices, data) = sewing_rows(v, b, 4, 1, [0.1, 0.07]);
    let sewing = SewingRows {
        indptr: &indptr,
        indices: &indices,
        data: &data,
    };
    let bits = |x: &[DVec3]| -> Vec<[u64; 3]> {
        x.iter().map(|p| p.to_array().map(f64::to_bits)).collect()
    };
    let (together, baseline) = crate::simd::both_builds(|| {
        let mut out = vec![DVec3::ZERO; f * v];
        blend_local_frames(&neutral, &shapes, sewing, &weights, &mut out).unwrap();
        bits(&out)
    });
    assert_eq!(together, baseline);
    for k in 0..f {
        let mut alone = vec![DVec3::ZERO; v];
        blend_local(
            &neutral,
            &shapes,
            sewing,
            &weights[k * b * q..(k + 1) * b * q],
            &mut alone,
        )
        .unwrap();
        assert_eq!(bits(&alone), together[k * v..(k + 1) * v], "frame {k}");
    }
    let mut ragged = vec![DVec3::ZERO; f * v - 1];
    let e = blend_local_frames(&neutral, &shapes, sewing, &weights, &mut ragged).unwrap_err();
    assert!(e.to_string().contains("whole frames"), "{e}");
}

#[test]
fn unbounded_windows_solve_in_closed_form_the_minimum_the_iteration_reaches() {
    // Without a penalty a window's fit is the ridge fit alone (`WindowFit::Ridge`); the
    // reference is each window's active-set solver at penalty 0 over the same rows, frames
    // with and without missing markers, weights far outside [0, 1].
    let rest: Vec<DVec3> = (0..12)
        .map(|i| DVec3::new(i as f64, 0.5 * (i % 3) as f64, 0.0))
        .collect();
    let shapes: Vec<Vec<DVec3>> = (0..5i32)
        .map(|k| {
            rest.iter()
                .map(|p| {
                    let x = p.x / 11.0;
                    DVec3::new(
                        (x * f64::from(k + 2)).cos(),
                        x.powi(k % 3 + 1),
                        p.y * f64::from(k),
                    )
                })
                .collect()
        })
        .collect();
    let a = matrix(&shapes);
    let fits = LocalFits::new(&a, 5, &rest, FIT_L2, 0.0).unwrap();
    assert!(fits
        .windows
        .iter()
        .all(|w| matches!(w.fit, WindowFit::Ridge(_))));
    let frames = 3;
    let mut targets = vec![0.0; frames * 36];
    for (i, t) in targets.iter_mut().enumerate() {
        *t = 3.0 * ((i * 13 % 17) as f64 / 17.0 - 0.5);
    }
    for &(f, m) in &[(1usize, 4usize), (2, 0), (2, 7)] {
        for c in 0..3 {
            targets[f * 36 + 3 * m + c] = f64::NAN;
        }
    }
    let got = fits.solve(&targets, &vec![0.0; frames * 5]).unwrap();
    assert_eq!(got.kept_start, 0);
    for (b, w) in fits.windows.iter().enumerate() {
        // The window's rows and ridge as `with_length` makes them.
        let mut rows = Vec::new();
        for (&m, &g) in w.markers.iter().zip(&w.root_weights) {
            for r in 3 * m..3 * m + 3 {
                rows.extend(a[r * 5..(r + 1) * 5].iter().map(|x| x * g));
            }
        }
        let l2 = FIT_L2 * fit_scale(&rows, 5);
        let solver = BlendshapeSolver::new(rows, 3 * w.markers.len(), 5, l2, 0.0).unwrap();
        for f in 0..frames {
            let mut target = Vec::new();
            for (&m, &g) in w.markers.iter().zip(&w.root_weights) {
                target.extend(
                    targets[f * 36 + 3 * m..f * 36 + 3 * m + 3]
                        .iter()
                        .map(|t| t * g),
                );
            }
            let want = solver.solve(&target).unwrap().weights;
            for (k, x) in want.iter().enumerate() {
                let g = got.weights[(f * 12 + b) * 5 + k];
                assert!(
                    (g - x).abs() <= 1e-9 * (1.0 + x.abs()),
                    "window {b} frame {f}: {g} vs {x}"
                );
            }
        }
    }
}
