//! Tests of the low-rank path: the few-free Woodbury solve against the whole system, the
//! dual's end against the dense normal equations (passes in double or single precision), and
//! the kernels' bits (AVX2 against baseline builds, mirrored updates against full ones).

use super::super::tests::{mixes, rnd};
use super::dual::SmallFree;
use super::kernels::columns_times_single;
use super::*;
use crate::linalg::{cholesky, cholesky_solve};
use proptest::prelude::*;

/// [`LowRank::new`] from a whole Gram matrix (S × S).
fn from_gram(
    a: &[f64],
    rows: usize,
    shapes: usize,
    gram: &[f64],
    l2: f64,
) -> Result<Option<LowRank>> {
    let diag: Vec<f64> = (0..shapes).map(|i| gram[i * shapes + i]).collect();
    let column = |p: usize| (0..shapes).map(|i| gram[i * shapes + p]).collect();
    LowRank::new(a, rows, shapes, &diag, column, l2)
}

/// The Woodbury solve over a few free weights equals the r × r system it stands for,
/// `(I + held WᵀW + c Σ_free w_i w_iᵀ) x = rhs`, on a complete frame (rows whitened once
/// for the matrix) and on one with rows missing (whitened as needed), twice each (the
/// second time from what the first kept).
#[test]
fn the_few_free_solve_equals_the_whole_system() {
    let (rows, shapes) = (40, 60);
    let mut seed = 9u64;
    // 60 shapes mixing 12: rank 12 < 30, the low-rank form.
    let a = mixes(rows, 12, shapes, 0.0, &mut seed);
    let mut rnd = || rnd(&mut seed);
    let lr = from_gram(&a, rows, shapes, &gram_of(&a, rows, shapes), 1e-3)
        .unwrap()
        .unwrap();
    let r = lr.rank();
    assert_eq!(r, 12);
    let (held, c) = (0.05, 900.0);
    let mut t: Vec<f64> = (0..rows).map(|_| rnd()).collect();
    for missing in [vec![], vec![0, 13, 27]] {
        for &m in &missing {
            t[m] = f64::NAN;
        }
        let (frame, _) = lr.frame(&t);
        let mut small = SmallFree::default();
        for in_box in [vec![3usize, 17, 40, 41], vec![3, 8, 17, 59]] {
            let rhs: Vec<f64> = (0..r).map(|_| rnd()).collect();
            let got = frame
                .solve_few_free(&in_box, &rhs, held, c, &mut small)
                .unwrap();
            let mut n: Vec<f64> = frame.wtw.iter().map(|x| x * held).collect();
            for i in 0..r {
                n[i * r + i] += 1.0;
            }
            for &k in &in_box {
                let w = &frame.w[k * r..(k + 1) * r];
                for i in 0..r {
                    for j in 0..r {
                        n[i * r + j] += c * w[i] * w[j];
                    }
                }
            }
            let want = cholesky_solve(r, &cholesky(r, n).unwrap(), &rhs);
            for (g, w) in got.iter().zip(&want) {
                assert!(
                    (g - w).abs() < 1e-9 * (1.0 + w.abs()),
                    "{missing:?}: {g} vs {w}"
                );
            }
        }
    }
}

/// The dual's end, for a matrix of 200 positive mixes of 5 shapes over 24 rows, complete
/// and with rows missing: weights on the pieces of the minimum, so the primal step on
/// their piece lands on them (the one step the solver then takes), within 1e-9 of the
/// dense normal equations' solution on that piece (1e-5 with the dual's passes in single
/// precision, as a large W takes them), and that step's weights within 1e-9 either way.
#[test]
fn the_dual_ends_on_the_minimums_pieces_with_passes_in_double_or_single_precision() {
    let (rows, base, shapes) = (24, 5, 200);
    let mut seed = 5u64;
    let a = mixes(rows, base, shapes, 0.5, &mut seed);
    let mut rnd = || rnd(&mut seed);
    let gram = gram_of(&a, rows, shapes);
    let (l2, penalty) = (1e-3, 10.0);
    let double = from_gram(&a, rows, shapes, &gram, l2).unwrap().unwrap();
    assert!(
        double.wt32.is_none(),
        "a small W keeps its passes in double precision"
    );
    let single = double.clone().with_single_passes();
    let t: Vec<f64> = (0..rows).map(|_| 3.0 * rnd()).collect();
    let cases = [vec![], vec![1, 2, 20]]
        .into_iter()
        .flat_map(|m| [(m.clone(), &double), (m, &single)]);
    for (missing, lr) in cases {
        // The dual's own weights carry its passes' rounding; the piece's solve does not.
        let dual_tolerance = if lr.wt32.is_some() { 1e-5 } else { 1e-9 };
        let mut t = t.clone();
        for &m in &missing {
            t[m] = f64::NAN;
        }
        let (mut frame, atr) = lr.frame(&t);
        let end = frame
            .dual(DualStart::Zero, l2, penalty, 100)
            .unwrap()
            .unwrap();
        let (w, steps) = (end.weights, end.steps);
        assert!(steps >= 2, "{missing:?}: {steps} steps");
        let clamped: Vec<bool> = w.iter().map(|x| !(0.0..=1.0).contains(x)).collect();
        assert!(clamped.iter().filter(|&&c| c).count() > shapes / 2);
        let mut rhs = atr.clone();
        for (r, x) in rhs.iter_mut().zip(&w) {
            if *x > 1.0 {
                *r += penalty;
            }
        }
        let cand = frame.piece(&clamped, &rhs, l2, penalty).unwrap();
        // The dense normal equations on that piece over the present rows.
        let mut m = vec![0.0; shapes * shapes];
        for r in (0..rows).filter(|&r| !t[r].is_nan()) {
            let row = &a[r * shapes..(r + 1) * shapes];
            for i in 0..shapes {
                for j in 0..shapes {
                    m[i * shapes + j] += row[i] * row[j];
                }
            }
        }
        for i in 0..shapes {
            m[i * shapes + i] += l2 + if clamped[i] { penalty } else { 0.0 };
        }
        let dense = cholesky_solve(shapes, &cholesky(shapes, m).unwrap(), &rhs);
        for ((x, c), d) in w.iter().zip(&cand).zip(&dense) {
            assert_eq!(!(0.0..=1.0).contains(c), !(0.0..=1.0).contains(x));
            assert!(
                (x - d).abs() < dual_tolerance && (c - d).abs() < 1e-9,
                "{x} {c} {d}"
            );
        }
    }
}

/// The fit's kernels give the same bits from their AVX2 builds as from the baseline ones
/// (no multiply-add fusion either way), on sizes with and without a vector remainder.
#[test]
fn the_fits_kernels_take_the_same_bits_with_or_without_avx2() {
    let mut seed = 11u64;
    for (n, r) in [(2000, 135), (301, 55), (7, 3)] {
        let m: Vec<f64> = (0..n * r).map(|_| rnd(&mut seed)).collect();
        let y: Vec<f64> = (0..r).map(|_| rnd(&mut seed)).collect();
        let single_m = single(&m);
        let bits = |v: Vec<f64>| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let (fast, baseline) = crate::simd::both_builds(|| bits(columns_times(&m, n, &y)));
        assert_eq!(fast, baseline);
        let (fast, baseline) =
            crate::simd::both_builds(|| bits(columns_times_single(&single_m, n, &y)));
        assert_eq!(fast, baseline);
        let terms: Vec<(f64, &[f64])> = m
            .chunks_exact(r)
            .take(70)
            .enumerate()
            .map(|(i, x)| (if i % 3 == 0 { -1.0 } else { 1.0 }, x))
            .collect();
        let (fast, baseline) = crate::simd::both_builds(|| {
            let mut sum = vec![0.5; r * r];
            add_outer_products(&mut sum, r, &terms);
            bits(sum)
        });
        assert_eq!(fast, baseline);
    }
}

proptest! {
    /// Rank-one updates made on and above the diagonal and then mirrored equal the same
    /// updates made on every entry, bit for bit (what the frame's K and clamped sum rely on).
    #[test]
    fn upper_updates_mirrored_equal_full_updates_bit_for_bit(
        r in 1usize..40,
        updates in proptest::collection::vec((proptest::bool::ANY, proptest::collection::vec(-3.0f64..3.0, 40)), 1..80),
    ) {
        let mut full = vec![0.0f64; r * r];
        for i in 0..r {
            full[i * r + i] = 1.0;
        }
        let mut upper = full.clone();
        for (plus, x) in &updates {
            let sign = if *plus { 1.0 } else { -1.0 };
            let x = &x[..r];
            for a in 0..r {
                for b in 0..r {
                    full[a * r + b] += sign * x[a] * x[b];
                }
            }
        }
        let terms: Vec<(f64, &[f64])> = updates
            .iter()
            .map(|(plus, x)| (if *plus { 1.0 } else { -1.0 }, &x[..r]))
            .collect();
        add_outer_products(&mut upper, r, &terms);
        let bits = |m: &[f64]| m.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        mirror_upper(&mut upper, r);
        prop_assert_eq!(bits(&upper), bits(&full));
    }
}
