//! Tests of the blendshape fit: the active-set solution against slow gradient descent, the
//! low-rank path against the dense one, the Newton iteration's end at the box's edge, the
//! dual's warm starts, derivatives against finite differences, and bad inputs.

use super::newton::Steps;
use super::*;
use crate::linalg::{cholesky, cholesky_solve};

pub(super) fn rnd(seed: &mut u64) -> f64 {
    *seed = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
}

// Brute force reference: projected gradient descent with a tiny fixed step, many steps.
fn gradient_descent(sol: &BlendshapeSolver, t: &[f64]) -> Vec<f64> {
    let s = sol.num_shapes();
    let mut w = vec![0.0; s];
    for _ in 0..200_000 {
        let mut g = vec![0.0; s];
        for (r, &tr) in t.iter().enumerate() {
            let row = &sol.a[r * s..(r + 1) * s];
            let res: f64 = row.iter().zip(&w).map(|(a, b)| a * b).sum::<f64>() - tr;
            for (gi, a) in g.iter_mut().zip(row) {
                *gi += 2.0 * res * a;
            }
        }
        for i in 0..s {
            let out = w[i].min(0.0) + (w[i] - 1.0).max(0.0);
            g[i] += 2.0 * (sol.l2 * w[i] + sol.penalty * out);
            w[i] -= 2e-3 * g[i];
        }
    }
    w
}

#[test]
fn active_set_solution_matches_slow_gradient_descent() {
    for seed in 0..5u64 {
        let mut s = seed;
        let (rows, shapes) = (12, 4);
        let a: Vec<f64> = (0..rows * shapes).map(|_| rnd(&mut s)).collect();
        let t: Vec<f64> = (0..rows).map(|_| 3.0 * rnd(&mut s)).collect();
        let sol = BlendshapeSolver::new(a, rows, shapes, 1e-3, 5.0).unwrap();
        let got = sol.solve(&t).unwrap();
        let want = gradient_descent(&sol, &t);
        for (g, w) in got.weights.iter().zip(&want) {
            assert!(
                (g - w).abs() < 1e-6,
                "seed {seed}: {:?} vs {want:?}",
                got.weights
            );
        }
        assert!(got.objective <= sol.objective(&want, &t) + 1e-12);
    }
}

/// 12 shapes that are combinations of 3 (an augmented dataset's in-betweens and sums)
/// over 30 rows: rank 3, so the solver takes the low-rank path.
fn augmented(seed: u64) -> (Vec<f64>, usize, usize) {
    let (rows, base, shapes) = (30, 3, 12);
    let mut s = seed;
    let b: Vec<f64> = (0..rows * base).map(|_| rnd(&mut s)).collect();
    let mix: Vec<f64> = (0..shapes * base)
        .map(|i| {
            if i % base == (i / base) % base {
                1.0
            } else {
                0.6 * rnd(&mut s)
            }
        })
        .collect();
    let a = (0..rows * shapes)
        .map(|i| {
            let (r, k) = (i / shapes, i % shapes);
            (0..base).map(|j| b[r * base + j] * mix[k * base + j]).sum()
        })
        .collect();
    (a, rows, shapes)
}

#[test]
fn the_low_rank_path_equals_the_dense_path_and_gradient_descent() {
    for seed in 0..4u64 {
        let (a, rows, shapes) = augmented(seed);
        let sol = BlendshapeSolver::new(a, rows, shapes, 1e-2, 5.0).unwrap();
        assert_eq!(sol.low_rank(), Some(3), "seed {seed}");
        let dense = sol.dense_only().unwrap();
        let mut s = seed + 100;
        let mut t: Vec<f64> = (0..rows).map(|_| 2.0 * rnd(&mut s)).collect();
        for missing in [vec![], vec![4, 5, 6], vec![0, 1, 2, 27, 28, 29]] {
            for &m in &missing {
                t[m] = f64::NAN;
            }
            let got = sol.solve(&t).unwrap();
            let want = dense.solve(&t).unwrap();
            let slow = gradient_descent(
                &sol,
                &t.iter()
                    .map(|x| if x.is_nan() { 0.0 } else { *x })
                    .collect::<Vec<_>>(),
            );
            for ((g, w), d) in got.weights.iter().zip(&want.weights).zip(&slow) {
                assert!((g - w).abs() < 1e-9, "seed {seed} {missing:?}: {g} vs {w}");
                if missing.is_empty() {
                    assert!((g - d).abs() < 1e-6, "seed {seed}: {g} vs descent {d}");
                }
            }
            assert!((got.objective - want.objective).abs() < 1e-9 * (1.0 + want.objective));
        }
    }
}

/// The Newton iteration's end where the box's soft penalty holds a weight within
/// round-off of an edge: a shape that no row sees keeps weight 0, and a piece solved with
/// round-off (the low-rank path with a small ridge: 1e-12 seen on ICT) puts it on either
/// side of 0 from step to step, so the candidate's sides never agree with the iterate's
/// (before: "did not converge in 100 iterations"). It must end at the minimum once the
/// objective stops moving.
#[test]
fn a_weight_crossing_the_box_edge_by_round_off_still_ends_at_the_minimum() {
    let (rows, shapes) = (6, 4);
    let mut s = 3;
    let mut a: Vec<f64> = (0..rows * shapes).map(|_| rnd(&mut s)).collect();
    for r in 0..rows {
        a[r * shapes + 3] = 0.0;
    }
    let t: Vec<f64> = (0..rows).map(|_| 2.0 * rnd(&mut s)).collect();
    let sol = BlendshapeSolver::new(a, rows, shapes, 1e-3, 5.0).unwrap();
    let want = sol.solve(&t).unwrap();
    assert_eq!(want.weights[3], 0.0);
    let mut atr = vec![0.0; shapes];
    for (r, &x) in t.iter().enumerate() {
        for (o, v) in atr.iter_mut().zip(&sol.a[r * shapes..(r + 1) * shapes]) {
            *o += v * x;
        }
    }
    let gram = sol.gram(&[true; 6]);
    let piece = |clamped: &[bool], rhs: &[f64], _| -> Result<Vec<f64>> {
        let mut h = gram.clone();
        for (i, &c) in clamped.iter().enumerate() {
            if c {
                h[i * shapes + i] += sol.penalty;
            }
        }
        let mut cand = cholesky_solve(shapes, &cholesky(shapes, h)?, rhs);
        // Always on the other side of the edge from the iterate.
        cand[3] = if clamped[3] { 1e-13 } else { -1e-13 };
        Ok(cand)
    };
    let products = |_: &[f64], w: &[f64], d: &[f64]| -> (f64, f64) {
        let (mut ad_aw, mut ad_ad) = (0.0, 0.0);
        for r in 0..rows {
            let row = &sol.a[r * shapes..(r + 1) * shapes];
            let ad: f64 = row.iter().zip(d).map(|(a, b)| a * b).sum();
            let aw: f64 = row.iter().zip(w).map(|(a, b)| a * b).sum();
            ad_aw += ad * aw;
            ad_ad += ad * ad;
        }
        (ad_aw, ad_ad)
    };
    let (got, _) = sol
        .newton(
            &atr,
            &[],
            None,
            Steps {
                piece,
                products,
                objective: |w: &[f64]| sol.objective(w, &t),
                stepped: |_: &[f64], _: &[f64], _, _: &[f64]| {},
            },
        )
        .unwrap();
    assert!(got.iterations < 10, "{} steps", got.iterations);
    for (g, w) in got.weights.iter().zip(&want.weights) {
        assert!(
            (g - w).abs() < 1e-12,
            "{:?} vs {:?}",
            got.weights,
            want.weights
        );
    }
}

/// 240 shapes over 30 rows, every one a random positive mix of 6 (like scans of one face):
/// most weights end clamped by the box (a fit of many scans), and the first steps clamp and
/// free many at once, so the low-rank path sums its free weights' products afresh as well as
/// updating them one by one; it must still land on the dense path's minimum.
#[test]
fn a_fit_that_clamps_most_of_many_shapes_equals_the_dense_path() {
    let (rows, shapes) = (30, 240);
    for seed in 0..3u64 {
        let (sol, mut t) = scans(seed);
        assert_eq!(sol.low_rank(), Some(6), "seed {seed}");
        let dense = sol.dense_only().unwrap();
        let mut s = seed + 90;
        let dirs: Vec<Vec<f64>> = vec![(0..rows).map(|_| rnd(&mut s)).collect()];
        for missing in [vec![], vec![2, 9, 17]] {
            for &m in &missing {
                t[m] = f64::NAN;
            }
            let (got, gd) = sol
                .solve_with_derivatives(&t, &dirs, FitStart::Cold)
                .unwrap();
            let (want, wd) = dense
                .solve_with_derivatives(&t, &dirs, FitStart::Cold)
                .unwrap();
            let clamped = want
                .weights
                .iter()
                .filter(|w| !(0.0..=1.0).contains(*w))
                .count();
            assert!(2 * clamped > shapes, "seed {seed}: only {clamped} clamped");
            assert!(
                got.iterations > 2,
                "seed {seed}: {} iterations",
                got.iterations
            );
            for (g, w) in got.weights.iter().zip(&want.weights) {
                assert!((g - w).abs() < 1e-9, "seed {seed} {missing:?}: {g} vs {w}");
            }
            for (g, w) in gd[0].iter().zip(&wd[0]) {
                assert!((g - w).abs() < 1e-7, "seed {seed} {missing:?}: {g} vs {w}");
            }
            let rel = (got.objective - want.objective).abs() / (1.0 + want.objective);
            assert!(
                rel < 1e-9,
                "seed {seed}: {} vs {}",
                got.objective,
                want.objective
            );
        }
    }
}

/// A `rows × shapes` matrix (row-major) whose columns mix `base` random columns, the
/// mixing weights drawn (by [`rnd`] from `seed`) plus `offset` (0.5: positive mixes, like
/// scans of one face).
pub(super) fn mixes(
    rows: usize,
    base: usize,
    shapes: usize,
    offset: f64,
    seed: &mut u64,
) -> Vec<f64> {
    let b: Vec<f64> = (0..rows * base).map(|_| rnd(seed)).collect();
    let mix: Vec<f64> = (0..shapes * base).map(|_| rnd(seed) + offset).collect();
    (0..rows * shapes)
        .map(|i| {
            let (r, k) = (i / shapes, i % shapes);
            (0..base).map(|j| b[r * base + j] * mix[k * base + j]).sum()
        })
        .collect()
}

#[test]
fn the_low_rank_forms_gram_columns_are_the_whole_gram_matrixs_bits_less_the_ridge() {
    let (rows, shapes) = (17, 40);
    let mut seed = 11u64;
    let a = mixes(rows, 5, shapes, 0.3, &mut seed);
    let l2 = 1e-3 * 0.37;
    let sol = BlendshapeSolver::new(a, rows, shapes, l2, 10.0).unwrap();
    assert!(
        sol.low_rank().is_some(),
        "a rank-5 matrix takes the low-rank form"
    );
    let gram = sol.gram(&vec![true; rows]);
    let diag = sol.plain_gram_diagonal();
    for p in 0..shapes {
        let col = sol.plain_gram_column(p);
        for i in 0..shapes {
            let want = if i == p {
                gram[i * shapes + p] - l2
            } else {
                gram[i * shapes + p]
            };
            assert_eq!(col[i].to_bits(), want.to_bits(), "column {p}, row {i}");
        }
        assert_eq!(diag[p].to_bits(), (gram[p * shapes + p] - l2).to_bits());
    }
}

/// 240 positive mixes of 6 shapes over 30 rows (scans of one face: most weights end
/// clamped) and a target.
fn scans(seed: u64) -> (BlendshapeSolver, Vec<f64>) {
    let (rows, base, shapes) = (30, 6, 240);
    let mut s = seed + 40;
    let a = mixes(rows, base, shapes, 0.5, &mut s);
    let t = (0..rows).map(|_| 3.0 * rnd(&mut s)).collect();
    (
        BlendshapeSolver::new(a, rows, shapes, 1e-3, 10.0).unwrap(),
        t,
    )
}

#[test]
fn the_dual_from_a_nearby_fits_dual_point_lands_on_the_dense_minimum() {
    for seed in 0..3u64 {
        let (sol, t) = scans(seed);
        let dense = sol.dense_only().unwrap();
        let mut s = seed + 7;
        for missing in [vec![], vec![3, 11, 25]] {
            let mut t = t.clone();
            for &m in &missing {
                t[m] = f64::NAN;
            }
            // A nearby fit of the same frame: the target moved by 5 % of its scale.
            let near: Vec<f64> = t.iter().map(|x| x + 0.15 * rnd(&mut s)).collect();
            let nearby = sol.solve(&near).unwrap();
            assert_eq!(nearby.dual.len(), 6, "seed {seed} {missing:?}");
            let from = |dual: &[f64]| {
                sol.solve_with_derivatives(
                    &t,
                    &[],
                    FitStart::Nearby {
                        weights: &nearby.weights,
                        dual,
                    },
                )
                .unwrap()
                .0
            };
            let got = from(&nearby.dual);
            let want = dense.solve(&t).unwrap();
            let cold = sol.solve(&t).unwrap();
            // A dual point of another length is not the frame's: the dual starts at 0.
            let other = from(&nearby.dual[1..]);
            for (((g, c), o), w) in got
                .weights
                .iter()
                .zip(&cold.weights)
                .zip(&other.weights)
                .zip(&want.weights)
            {
                for (x, what) in [(g, "nearby"), (c, "cold"), (o, "other")] {
                    assert!(
                        (x - w).abs() < 1e-9,
                        "seed {seed} {missing:?} {what}: {x} vs {w}"
                    );
                }
            }
            assert_eq!(other.iterations, cold.iterations);
            // Started nearby it takes fewer steps than from 0.
            assert!(
                got.iterations <= cold.iterations,
                "seed {seed} {missing:?}: {} vs {} from 0",
                got.iterations,
                cold.iterations
            );
        }
    }
}

#[test]
fn derivatives_equal_finite_differences_of_the_solution_on_both_paths() {
    for (a, rows, shapes) in [augmented(7), {
        let mut s = 11u64;
        (((0..30 * 5).map(|_| rnd(&mut s)).collect()), 30, 5)
    }] {
        let sol = BlendshapeSolver::new(a, rows, shapes, 1e-2, 5.0).unwrap();
        let mut s = 3u64;
        let mut t: Vec<f64> = (0..rows).map(|_| 2.0 * rnd(&mut s)).collect();
        t[4] = f64::NAN;
        let dirs: Vec<Vec<f64>> = (0..2)
            .map(|_| (0..rows).map(|_| rnd(&mut s)).collect())
            .collect();
        let (base, dw) = sol
            .solve_with_derivatives(&t, &dirs, FitStart::Cold)
            .unwrap();
        // Started at the solution, the iteration ends at once, on the same weights: one
        // primal step (the low-rank path first takes one dual step from the solution's
        // dual point, which the primal step confirms).
        let (again, _) = sol
            .solve_with_derivatives(&t, &[], FitStart::Weights(&base.weights))
            .unwrap();
        let steps = if sol.low_rank().is_some() { 2 } else { 1 };
        assert_eq!(again.iterations, steps);
        for (a, b) in again.weights.iter().zip(&base.weights) {
            assert!((a - b).abs() < 1e-12);
        }
        for (d, dwd) in dirs.iter().zip(&dw) {
            let h = 1e-7;
            let moved: Vec<f64> = t.iter().zip(d).map(|(a, b)| a + h * b).collect();
            let w = sol.solve(&moved).unwrap().weights;
            for ((x1, x0), g) in w.iter().zip(&base.weights).zip(dwd) {
                assert!(((x1 - x0) / h - g).abs() < 1e-5, "{} vs {g}", (x1 - x0) / h);
            }
        }
    }
}

#[test]
fn weights_inside_the_box_are_the_plain_least_squares_solution() {
    let a = vec![1.0, 0.0, 0.0, 1.0, 1.0, 1.0];
    let sol = BlendshapeSolver::new(a, 3, 2, 0.0, 10.0).unwrap();
    let got = sol.solve(&[0.3, 0.6, 0.9]).unwrap();
    assert!((got.weights[0] - 0.3).abs() < 1e-12 && (got.weights[1] - 0.6).abs() < 1e-12);
    assert_eq!(got.iterations, 1);
}

#[test]
fn missing_rows_are_dropped_and_bad_inputs_are_errors() {
    let a = vec![1.0, 0.0, 0.0, 1.0, 1.0, 1.0];
    let sol = BlendshapeSolver::new(a, 3, 2, 0.0, 0.0).unwrap();
    let got = sol.solve(&[0.2, f64::NAN, 0.7]).unwrap();
    assert!((got.weights[0] - 0.2).abs() < 1e-12 && (got.weights[1] - 0.5).abs() < 1e-12);
    assert!(sol.solve(&[0.0, 1.0]).is_err());
    assert!(sol.solve(&[0.0, f64::INFINITY, 1.0]).is_err());
    assert!(BlendshapeSolver::new(vec![1.0, 1.0], 1, 2, 0.0, 0.0).is_err());
    assert!(BlendshapeSolver::new(vec![1.0, 1.0], 1, 2, -1.0, 0.0).is_err());
}

#[test]
fn the_gram_of_present_rows_is_their_products_summed_in_row_order_on_both_builds() {
    let (rows, shapes) = (23usize, 11usize);
    let mut s = 7u64;
    let a: Vec<f64> = (0..rows * shapes).map(|_| rnd(&mut s) - 0.5).collect();
    let sol = BlendshapeSolver::new(a.clone(), rows, shapes, 1e-3, 5.0).unwrap();
    let present: Vec<bool> = (0..rows).map(|r| r % 4 != 1).collect();
    let bits = |g: Vec<f64>| g.into_iter().map(f64::to_bits).collect::<Vec<_>>();
    let (fast, baseline) = crate::simd::both_builds(|| bits(sol.gram(&present)));
    assert_eq!(fast, baseline);
    for i in 0..shapes {
        for j in 0..shapes {
            let (lo, hi) = (i.max(j), i.min(j));
            let mut want = 0.0;
            for r in (0..rows).filter(|&r| present[r]) {
                want += a[r * shapes + lo] * a[r * shapes + hi];
            }
            if i == j {
                want += sol.l2;
            }
            assert_eq!(f64::from_bits(fast[i * shapes + j]), want, "({i}, {j})");
        }
    }
}
