//! Tests of the blend against its slower equivalents: by columns, over shape spans, and the
//! fused sewing against the staged pass, bit for bit.

use super::*;
use proptest::prelude::*;

/// A seeded uniform [0, 1) generator, with `nv` random neutral positions and `ns` random
/// shapes drawn from it (the generator is returned to draw the rest of a case).
fn random_shapes(seed: u64, nv: usize, ns: usize) -> (impl FnMut() -> f64, Vec<DVec3>, Vec<f32>) {
    let mut state = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let mut next = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64) / ((1u64 << 53) as f64)
    };
    let x0: Vec<DVec3> = (0..nv)
        .map(|_| DVec3::new(next(), next(), next()))
        .collect();
    let displacements: Vec<f32> = (0..ns * nv * 3).map(|_| (next() - 0.5) as f32).collect();
    (next, x0, displacements)
}

/// `nv` rows of random weights over `nb` bundles, each bundle in a row with probability
/// `density`.
fn random_weights(
    next: &mut impl FnMut() -> f64,
    nv: usize,
    nb: usize,
    density: f64,
) -> SparseWeights {
    let mut weights = SparseWeights::empty(nb);
    for _ in 0..nv {
        let cols: Vec<u32> = (0..nb as u32).filter(|_| next() < density).collect();
        let vals: Vec<f64> = cols.iter().map(|_| next() + 0.01).collect();
        weights.push_row(&cols, &vals);
    }
    weights
}

proptest! {
    /// The blend read column by column within blocks equals the blend vertex by vertex bit
    /// for bit: partial last blocks, empty rows, bundles without a piece and bundles on
    /// the shared fit (also a fit at the neutral, which has no shape terms: that used to
    /// index an empty block of fit displacements).
    #[test]
    fn blend_by_columns_equals_blend_bit_for_bit(
        nv in 1usize..1300,
        seed in 0u64..1000,
        with_fit in proptest::bool::ANY,
        neutral_fit in proptest::bool::ANY,
    ) {
        let (nb, ns) = (7usize, 5usize);
        let (mut next, x0, displacements) = random_shapes(seed, nv, ns);
        let weights = random_weights(&mut next, nv, nb, 0.4);
        let mut pieces = Pieces { start: vec![0], ..Pieces::default() };
        for b in 0..nb {
            if b % 3 != 1 {
                for _ in 0..1 + b % 4 {
                    pieces.shapes.push((next() * (ns + 1) as f64) as u32 % (ns as u32 + 1));
                    pieces.weights.push(next());
                }
            }
            pieces.start.push(pieces.shapes.len() as u32);
        }
        if with_fit {
            pieces.fit = (0..nb).map(|b| b % 3 == 2).collect();
            // A fit at the neutral has no shape terms at all.
            (pieces.fit_shapes, pieces.fit_weights) = match neutral_fit {
                true => (vec![0], vec![1.0]),
                false => (vec![1, 3, 4], vec![0.3, -0.2, 0.7]),
            };
        }
        let mut rows = vec![DVec3::ZERO; nv];
        blend(&x0, &displacements, &weights, &pieces, &mut rows);
        let mut by_columns = vec![DVec3::ZERO; nv];
        let columns = weights.block_columns(BLEND_BLOCK);
        blend_by_columns(&x0, &displacements, &weights, &columns, &pieces, &mut by_columns);
        for (v, (a, b)) in rows.iter().zip(&by_columns).enumerate() {
            prop_assert_eq!(a.to_array().map(f64::to_bits), b.to_array().map(f64::to_bits), "vertex {}", v);
        }
    }

    /// The global fit's displacement summed over blocks, four shapes a pass and only
    /// where the shapes move (their [`ShapeSpans`]), equals the fit summed vertex by
    /// vertex over every shape bit for bit: shapes still in whole blocks or moving in a
    /// few runs, -0.0 entries, 0–11 fit terms (whole quads and a remainder), partial last
    /// blocks, in the row blend and by columns.
    #[test]
    fn fit_summed_over_spans_equals_the_fit_vertex_by_vertex_bit_for_bit(
        nv in 1usize..1300,
        seed in 0u64..1000,
        num_terms in 0usize..12,
    ) {
        let (nb, ns) = (5usize, 12usize);
        let (mut next, x0, mut displacements) = random_shapes(seed, nv, ns);
        // Each shape moves in a few runs of vertices and is still (+0.0 or -0.0) elsewhere.
        for k in 0..ns {
            let runs: Vec<(usize, usize)> = (0..(next() * 3.0) as usize)
                .map(|_| {
                    let a = (next() * nv as f64) as usize;
                    (a, (a + 1 + (next() * 300.0) as usize).min(nv))
                })
                .collect();
            for v in 0..nv {
                if !runs.iter().any(|&(a, b)| (a..b).contains(&v)) {
                    let z = if next() < 0.5 { 0.0 } else { -0.0 };
                    displacements[(k * nv + v) * 3..(k * nv + v) * 3 + 3].fill(z);
                }
            }
        }
        let weights = random_weights(&mut next, nv, nb, 0.5);
        let mut pieces = Pieces { start: vec![0], ..Pieces::default() };
        for b in 0..nb {
            if b % 2 == 0 {
                pieces.shapes.push(1 + b as u32);
                pieces.weights.push(next());
            }
            pieces.start.push(pieces.shapes.len() as u32);
        }
        pieces.fit = (0..nb).map(|b| b % 2 == 1 || b == 4).collect();
        for _ in 0..num_terms {
            pieces.fit_shapes.push(1 + (next() * ns as f64) as u32 % ns as u32);
            pieces.fit_weights.push(next() * 2.0 - 0.5);
        }
        let spans = ShapeSpans::new(&displacements, nv, BLEND_BLOCK);
        let input = BlendInput::new(&x0, &displacements, &weights, &pieces);
        let reference: Vec<DVec3> = (0..nv).map(|v| input.vertex(v)).collect();
        let input = input.with_spans(Some(&spans));
        let columns = weights.block_columns(BLEND_BLOCK);
        for by_columns in [None, Some(&columns)] {
            let mut out = vec![DVec3::ZERO; nv];
            blend_with(&input, by_columns, &mut out);
            for (v, (a, b)) in reference.iter().zip(&out).enumerate() {
                prop_assert_eq!(a.to_array().map(f64::to_bits), b.to_array().map(f64::to_bits), "vertex {}, by columns {}", v, by_columns.is_some());
            }
        }
    }

    /// The fused sewing, vertex by vertex and by column within blocks (blend, map and
    /// corrections), equals the staged blend, map and residual pass bit for bit, with one
    /// round and with the second (refinement) round forced; a missing bundle, partial
    /// last blocks and empty rows included.
    #[test]
    fn fused_sewing_by_columns_equals_the_staged_pass_bit_for_bit(
        nv in 3usize..1300,
        seed in 0u64..1000,
    ) {
        let (nb, ns, missing) = (7usize, 5usize, 4u32);
        let (mut next, x0, displacements) = random_shapes(seed, nv, ns);
        let present: Vec<u32> = (0..nb as u32).filter(|&b| b != missing).collect();
        let mut weights = SparseWeights::empty(nb);
        for _ in 0..nv {
            let cols: Vec<u32> =
                present.iter().copied().filter(|_| next() < 0.5).collect();
            let vals: Vec<f64> = cols.iter().map(|_| next() + 0.01).collect();
            let sum: f64 = vals.iter().sum();
            weights.push_row(&cols, &vals.iter().map(|w| w / sum).collect::<Vec<_>>());
        }
        let triangles: Vec<[u32; 3]> = (0..nb)
            .map(|_| {
                let a = (next() * nv as f64) as u32 % nv as u32;
                [a, (a + 1) % nv as u32, (a + 2) % nv as u32]
            })
            .collect();
        let bundles: Vec<SurfacePoint> = (0..nb as u32)
            .map(|t| {
                let (u, v) = (next() * 0.5, next() * 0.5);
                SurfacePoint { triangle: t, bary: [1.0 - u - v, u, v] }
            })
            .collect();
        let targets: Vec<DVec3> = (0..nb).map(|_| DVec3::new(next(), next(), next())).collect();
        let mut pieces = Pieces { start: vec![0], ..Pieces::default() };
        for b in 0..nb {
            for _ in 0..1 + b % 4 {
                pieces.shapes.push((next() * (ns + 1) as f64) as u32 % (ns as u32 + 1));
                pieces.weights.push(next());
            }
            pieces.start.push(pieces.shapes.len() as u32);
        }
        let Ok(pass) = ResidualPass::new(&triangles, &bundles, (&weights).into(), &present) else {
            // A singular random system: nothing to compare.
            return Ok(());
        };
        let map = |v: usize, p: DVec3| p * 1.5 + DVec3::splat(v as f64 * 1e-3);
        let columns = weights.block_columns(BLEND_BLOCK);
        let bits = |v: &[DVec3]| -> Vec<[u64; 3]> {
            v.iter().map(|p| p.to_array().map(f64::to_bits)).collect()
        };
        for tolerance in [f64::INFINITY, -1.0] {
            let mut staged = vec![DVec3::ZERO; nv];
            blend(&x0, &displacements, &weights, &pieces, &mut staged);
            for (v, x) in staged.iter_mut().enumerate() {
                *x = map(v, *x);
            }
            pass.apply(&triangles, &bundles, &weights, &targets, tolerance, &mut staged);
            let at = BundleTargets { triangles: &triangles, bundles: &bundles, targets: &targets, tolerance };
            let input = BlendInput::new(&x0, &displacements, &weights, &pieces);
            for by_columns in [None, Some(&columns)] {
                let mut fused = vec![DVec3::ZERO; nv];
                pass.sew(&input, by_columns, map, &at, &mut fused);
                prop_assert_eq!(bits(&fused), bits(&staged), "tolerance {}, by columns {}", tolerance, by_columns.is_some());
            }
        }
    }
}

/// The fit blend's kernels give the same bits from their AVX2 builds as from the baseline ones
/// (no multiply-add fusion either way), over lengths with and without a vector remainder.
#[test]
fn the_fit_blends_kernels_take_the_same_bits_with_or_without_avx2() {
    for len in [1usize, 5, 512, 1001] {
        let rows: Vec<Vec<f32>> = (0..4)
            .map(|k| {
                (0..3 * len)
                    .map(|i| ((i * 7 + k * 13) % 17) as f32 * 0.37 - 2.9)
                    .collect()
            })
            .collect();
        let a = [0.3, -1.7, 2.2e-3, 0.9];
        let bits = |v: Vec<f64>| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let (fast, baseline) = crate::simd::both_builds(|| {
            let mut f: Vec<f64> = (0..3 * len).map(|i| i as f64 * 0.1).collect();
            add_four_scaled(&mut f, [&rows[0], &rows[1], &rows[2], &rows[3]], a);
            add_scaled(&mut f, &rows[1], -0.61, 0, len);
            bits(f)
        });
        assert_eq!(fast, baseline);
    }
}
