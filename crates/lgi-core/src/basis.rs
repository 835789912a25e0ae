//! A basis of a dataset's shapes made of some of the shapes themselves, with every other shape
//! as a combination of them: an augmented dataset's in-betweens and pair sums are exact
//! combinations of its scanned shapes (ICT-300: 300 shapes, 57 independent). The global fit
//! spreads its weights over all of them; re-expressed over the basis, sewing the fit reads 57
//! shapes at a vertex instead of 300, with the same mesh to f32 round-off.

use rayon::prelude::*;
use std::cell::RefCell;

/// A shape whose squared residual against the basis is at most this fraction of its own
/// squared norm (relative rms 1e-6) counts as a combination of the basis.
const COMBINATION_TOLERANCE: f64 = 1e-12;

/// Coordinates per block of the Gram matrix: 300 shapes' rows of one block, widened to f64,
/// take 1.2 MB; [`TILE`] rows of them (128 KB) stay in the core's cache while the pairs are
/// taken.
const BLOCK: usize = 512;
/// The blocks are summed in at most this many contiguous groups, one parallel task each.
const GROUPS: usize = 32;

/// Rows `j` of a block's pairs taken together, so that their rows (f64) stay in the core's
/// cache while every later row `i` meets them.
const TILE: usize = 32;

// The pairs' sums (`crate::linalg::dot8`): the inputs are f32 values widened to f64 once per
// block (exact), not once per pair (the Gram of ICT-300 took seconds with one chain).
use crate::linalg::dot8 as dot;

/// Sums `add(wide, len, part)` over the blocks of coordinates into a vector of `size` f64:
/// `wide` holds every shape's values of one block widened to f64 (row k at `k * BLOCK`, `len`
/// values). Contiguous groups of blocks are summed in parallel, each in order, and the groups
/// in order: the same sums whatever the thread count (a parallel reduce's tree is not fixed).
fn blockwise(
    displacements: &[f32],
    s: usize,
    n: usize,
    size: usize,
    add: impl Fn(&[f64], usize, &mut [f64]) + Sync,
) -> Vec<f64> {
    let blocks = n.div_ceil(BLOCK);
    let per_group = blocks.div_ceil(GROUPS).max(1);
    let groups: Vec<Vec<f64>> = (0..blocks.div_ceil(per_group))
        .into_par_iter()
        .map(|g| {
            let mut part = vec![0.0f64; size];
            let mut wide = vec![0.0f64; s * BLOCK];
            for c in g * per_group..((g + 1) * per_group).min(blocks) {
                let (lo, hi) = (c * BLOCK, ((c + 1) * BLOCK).min(n));
                for k in 0..s {
                    let row = &displacements[k * n + lo..k * n + hi];
                    for (w, x) in wide[k * BLOCK..k * BLOCK + hi - lo].iter_mut().zip(row) {
                        *w = *x as f64;
                    }
                }
                add(&wide, hi - lo, &mut part);
            }
            part
        })
        .collect();
    let mut sum = vec![0.0f64; size];
    for g in &groups {
        sum.iter_mut().zip(g).for_each(|(x, y)| *x += y);
    }
    sum
}

/// The lower triangle (j ≤ i) of the Gram matrix `G[i s + j] = Σ_v d_i(v) d_j(v)` of the `s`
/// shapes of `n` values each in `displacements` (f64 sums; the upper triangle is zero).
fn gram(displacements: &[f32], s: usize, n: usize) -> Vec<f64> {
    blockwise(displacements, s, n, s * s, |wide, len, gram| {
        let row = |k: usize| &wide[k * BLOCK..k * BLOCK + len];
        // Every pair j ≤ i once per block, in tiles of j: each pair's sum is the same
        // whatever the order of the pairs.
        for j0 in (0..s).step_by(TILE) {
            for i in j0..s {
                for j in j0..(j0 + TILE).min(i + 1) {
                    gram[i * s + j] += dot(row(i), row(j));
                }
            }
        }
    })
}

/// The Gram matrix's columns `cols` (`cols.len() × s`, column c's entry i at `c s + i`) and
/// its diagonal (s), each entry the same sum, bit for bit, as [`gram`]'s (the product of two
/// values commutes exactly, so pair (i, j) summed either way round is the same).
fn gram_columns(displacements: &[f32], s: usize, n: usize, cols: &[usize]) -> Vec<f64> {
    let m = cols.len();
    blockwise(displacements, s, n, m * s, |wide, len, part| {
        let row = |k: usize| &wide[k * BLOCK..k * BLOCK + len];
        for (c, &p) in cols.iter().enumerate() {
            for i in 0..s {
                part[c * s + i] += dot(row(i), row(p));
            }
        }
    })
}

/// The Gram matrix's diagonal, each entry [`gram`]'s sum bit for bit.
fn gram_diagonal(displacements: &[f32], s: usize, n: usize) -> Vec<f64> {
    blockwise(displacements, s, n, s, |wide, len, part| {
        for (k, d) in part.iter_mut().enumerate() {
            let row = &wide[k * BLOCK..k * BLOCK + len];
            *d += dot(row, row);
        }
    })
}

/// A pivoted Cholesky of a Gram matrix given by its diagonal and a source of columns: the
/// pivot is the shape least explained (relative to its own norm) by the pivots so far, or
/// the least explained of those whose column is `made` already when that is within
/// [`PREFER_MADE`] of it, and it stops when every shape is explained. Returns the pivots and
/// the factor's columns (S each). `column(p, left, pivots)` is asked once per pivot, in
/// pivot order.
fn pivoted_cholesky(
    norm: &[f64],
    made: impl Fn(usize) -> bool,
    mut column: impl FnMut(usize, &[f64], &[usize]) -> Vec<f64>,
) -> (Vec<usize>, Vec<Vec<f64>>) {
    let s = norm.len();
    let mut left = norm.to_vec();
    let mut factor: Vec<Vec<f64>> = Vec::new(); // columns of L, S each
    let mut pivots = Vec::new();
    loop {
        let (p, worst) = (0..s)
            .filter(|k| !pivots.contains(k))
            .map(|k| (k, explained_left(&left, norm, k)))
            .fold((usize::MAX, 0.0f64), |b, x| if x.1 > b.1 { x } else { b });
        if p == usize::MAX || worst.is_nan() || worst <= COMBINATION_TOLERANCE {
            break;
        }
        let (ready, ready_left) = (0..s)
            .filter(|&k| made(k) && !pivots.contains(&k))
            .map(|k| (k, explained_left(&left, norm, k)))
            .fold((usize::MAX, 0.0f64), |b, x| if x.1 > b.1 { x } else { b });
        let p = if !made(p) && ready != usize::MAX && ready_left >= PREFER_MADE * worst {
            ready
        } else {
            p
        };
        let at_p = column(p, &left, &pivots);
        let root = left[p].sqrt();
        let col: Vec<f64> = (0..s)
            .map(|i| (at_p[i] - factor.iter().map(|c| c[i] * c[p]).sum::<f64>()) / root)
            .collect();
        for (l, c) in left.iter_mut().zip(&col) {
            *l -= c * c;
        }
        left[p] = 0.0;
        factor.push(col);
        pivots.push(p);
    }
    (pivots, factor)
}

/// What is left of shape k's squared norm once the pivots explain it, relative to the norm.
fn explained_left(left: &[f64], norm: &[f64], k: usize) -> f64 {
    if norm[k] > 0.0 {
        left[k] / norm[k]
    } else {
        0.0
    }
}

/// Blocks of coordinates, evenly spread, whose Gram matrix predicts the pivots (a few
/// thousand coordinates: a 2,000-scan dataset's whole Gram matrix takes ~20 s, these ~1 s).
const SAMPLE_BLOCKS: usize = 8;
/// Columns made together when a pivot was not predicted: the shapes least explained so far.
const MISS_BATCH: usize = 32;
/// A shape whose column is made is taken as the pivot before the least explained one when
/// what is left of it is at least this fraction of the worst (a pivot that far from the
/// largest keeps the factor well conditioned).
const PREFER_MADE: f64 = 0.1;

/// The basis and every shape's coefficients over it.
#[derive(Debug, Clone)]
pub struct ShapeBasis {
    /// 0-based indices of the basis shapes.
    pub shapes: Vec<usize>,
    /// `S × q`: shape k is `Σ_j coefficients[k q + j] · shapes[j]` (a basis shape: its unit).
    coefficients: Vec<f64>,
}

impl ShapeBasis {
    /// The basis of `displacements` (`S × V × 3`, shape-major), or `None` when no shape is a
    /// combination of the others.
    pub fn find(displacements: &[f32], num_shapes: usize) -> Option<ShapeBasis> {
        let s = num_shapes;
        if s < 2 || displacements.len() % s != 0 {
            return None;
        }
        let n = displacements.len() / s;
        // The pivots of a sample of the coordinates first: a shape that is a combination of
        // others is one on any coordinates, so a sample where no shape is one (scans) settles
        // it, and otherwise its pivots are the columns of the whole Gram matrix to make (one
        // pass over the data for all of them, instead of the whole matrix's S² / 2 pairs).
        let blocks = n.div_ceil(BLOCK);
        let predicted = if blocks > 2 * SAMPLE_BLOCKS {
            let mut sample = Vec::with_capacity(s * SAMPLE_BLOCKS * BLOCK);
            for k in 0..s {
                for b in 0..SAMPLE_BLOCKS {
                    let lo = (b * blocks / SAMPLE_BLOCKS) * BLOCK;
                    sample.extend_from_slice(&displacements[k * n + lo..k * n + lo + BLOCK]);
                }
            }
            let m = SAMPLE_BLOCKS * BLOCK;
            let g = gram(&sample, s, m);
            let norm: Vec<f64> = (0..s).map(|k| g[k * s + k]).collect();
            let at = |i: usize, j: usize| if j <= i { g[i * s + j] } else { g[j * s + i] };
            let (pivots, _) = pivoted_cholesky(
                &norm,
                |_| true,
                |p, _, _| (0..s).map(|i| at(i, p)).collect(),
            );
            if pivots.len() == s {
                return None;
            }
            pivots
        } else {
            (0..s).collect()
        };
        let norm = gram_diagonal(displacements, s, n);
        let made: RefCell<Vec<Option<Vec<f64>>>> = RefCell::new(vec![None; s]);
        let make = |cols: &[usize]| {
            let values = gram_columns(displacements, s, n, cols);
            let mut made = made.borrow_mut();
            for (c, &p) in cols.iter().enumerate() {
                made[p] = Some(values[c * s..(c + 1) * s].to_vec());
            }
        };
        make(&predicted);
        let is_made = |k: usize| made.borrow()[k].is_some();
        let (pivots, factor) = pivoted_cholesky(&norm, is_made, |p, left, pivots| {
            if !is_made(p) {
                let mut next: Vec<usize> = (0..s)
                    .filter(|&k| !is_made(k) && !pivots.contains(&k))
                    .collect();
                next.sort_by(|&a, &b| {
                    explained_left(left, &norm, b).total_cmp(&explained_left(left, &norm, a))
                });
                next.truncate(MISS_BATCH);
                if !next.contains(&p) {
                    next.push(p);
                }
                make(&next);
            }
            let taken = made.borrow_mut()[p].take();
            taken.unwrap_or_else(|| gram_columns(displacements, s, n, &[p]))
        });
        Self::from_factor(pivots, &factor, s)
    }

    /// The basis of a pivoted Cholesky's pivots and factor columns, `None` when every one of
    /// the `s` shapes is a pivot.
    fn from_factor(pivots: Vec<usize>, factor: &[Vec<f64>], s: usize) -> Option<ShapeBasis> {
        let q = pivots.len();
        if q == s {
            return None;
        }
        // Shape k's coefficients solve L_PPᵀ c = L_k (L_PP: the pivots' rows of the factor,
        // lower triangular in pivot order).
        let mut coefficients = vec![0.0; s * q];
        for k in 0..s {
            let out = &mut coefficients[k * q..(k + 1) * q];
            if let Some(j) = pivots.iter().position(|&p| p == k) {
                out[j] = 1.0;
                continue;
            }
            for j in (0..q).rev() {
                let mut x = factor[j][k];
                for (m, o) in out.iter().enumerate().skip(j + 1) {
                    x -= factor[j][pivots[m]] * o;
                }
                out[j] = x / factor[j][pivots[j]];
            }
        }
        Some(ShapeBasis {
            shapes: pivots,
            coefficients,
        })
    }

    /// A basis as saved ([`ShapeBasis::shapes`] and [`ShapeBasis::coefficients`]) for a dataset
    /// of `num_shapes` shapes; `None` unless the basis shapes are distinct and in range, fewer
    /// than all, and the coefficients `S × q` finite.
    pub fn from_saved(
        shapes: Vec<usize>,
        coefficients: Vec<f64>,
        num_shapes: usize,
    ) -> Option<ShapeBasis> {
        let q = shapes.len();
        let mut seen = vec![false; num_shapes];
        let distinct = shapes
            .iter()
            .all(|&k| k < num_shapes && !std::mem::replace(&mut seen[k], true));
        let fits =
            coefficients.len() == num_shapes * q && coefficients.iter().all(|c| c.is_finite());
        (q > 0 && q < num_shapes && distinct && fits).then_some(ShapeBasis {
            shapes,
            coefficients,
        })
    }

    /// Every shape's coefficients over the basis shapes (S × q, row-major, shape k's row:
    /// `Σ_j c[k q + j] · shapes[j]` is shape k).
    pub fn coefficients(&self) -> &[f64] {
        &self.coefficients
    }

    /// Weights over every shape (S) as weights over the basis shapes (S, zero elsewhere): the
    /// same combination of displacements.
    pub fn map(&self, weights: &[f64]) -> Vec<f64> {
        let q = self.shapes.len();
        let mut out = vec![0.0; weights.len()];
        for (k, &w) in weights.iter().enumerate() {
            if w != 0.0 {
                for (j, &c) in self.coefficients[k * q..(k + 1) * q].iter().enumerate() {
                    out[self.shapes[j]] += w * c;
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `count` linearly independent shapes of `n` values: shape k is sin((k + k0) · i · step).
    fn independent_shapes(count: usize, n: usize, k0: usize, step: f32) -> Vec<Vec<f32>> {
        (0..count)
            .map(|k| {
                (0..n)
                    .map(|i| ((i * (k + k0)) as f32 * step).sin())
                    .collect()
            })
            .collect()
    }

    /// `Σ a_i b_i` summed plainly in f64, and `Σ |a_i b_i|` (the scale of its round-off).
    fn plain_dot(a: &[f32], b: &[f32]) -> (f64, f64) {
        let products = a.iter().zip(b).map(|(x, y)| *x as f64 * *y as f64);
        (products.clone().sum(), products.map(f64::abs).sum())
    }

    #[test]
    fn gram_matches_plain_sums_over_several_tiles_and_a_partial_block() {
        // 2.5 tiles of shapes, 3 blocks of coordinates and a partial one.
        let (s, n) = (TILE * 2 + TILE / 2, 3 * BLOCK + 17);
        let shapes = independent_shapes(s, n, 1, 0.003);
        let flat: Vec<f32> = shapes.iter().flatten().copied().collect();
        let g = gram(&flat, s, n);
        for i in 0..s {
            for j in 0..s {
                let (plain, scale) = plain_dot(&shapes[i], &shapes[j]);
                let expect = if j <= i { plain } else { 0.0 };
                assert!(
                    (g[i * s + j] - expect).abs() <= 1e-12 * scale.max(1.0),
                    "({i}, {j}): {} vs {expect}",
                    g[i * s + j]
                );
            }
        }
    }

    #[test]
    fn combinations_are_found_and_mapped_weights_give_the_same_displacement() {
        // 3 independent shapes over 40 values, then an in-between and two pair sums.
        let n = 40;
        let base = independent_shapes(3, n, 2, 0.37);
        let mut shapes = base.clone();
        shapes.push(base[1].iter().map(|x| 0.5 * x).collect());
        shapes.push(base[0].iter().zip(&base[2]).map(|(a, b)| a + b).collect());
        shapes.push(base[1].iter().zip(&base[2]).map(|(a, b)| a + b).collect());
        let flat: Vec<f32> = shapes.iter().flatten().copied().collect();
        let basis = ShapeBasis::find(&flat, shapes.len()).unwrap();
        assert_eq!(basis.shapes.len(), 3);
        let w = [0.2, 0.0, 0.7, 0.4, 0.3, 0.9];
        let mapped = basis.map(&w);
        for (k, &m) in mapped.iter().enumerate() {
            assert!(m == 0.0 || basis.shapes.contains(&k));
        }
        let sum = |w: &[f64]| -> Vec<f64> {
            (0..n)
                .map(|i| w.iter().zip(&shapes).map(|(a, s)| a * s[i] as f64).sum())
                .collect()
        };
        for (a, b) in sum(&w).iter().zip(sum(&mapped)) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
        // Independent shapes have no basis smaller than themselves.
        let flat: Vec<f32> = base.iter().flatten().copied().collect();
        assert!(ShapeBasis::find(&flat, 3).is_none());
    }

    /// The basis found from a sample's pivots and the whole Gram matrix's columns made on
    /// demand explains every shape, and here (the least explained shape always a pivot) has
    /// the bits of the one found from the whole Gram matrix, also though the sample misses
    /// shapes: shapes that move only coordinates between the sampled blocks.
    #[test]
    fn the_basis_from_sampled_pivots_explains_every_shape_and_equals_the_whole_gram_one() {
        let n = 40 * BLOCK + 77;
        let mut base = independent_shapes(6, n, 5, 0.0071);
        // Local shapes: zero except in block 2 (not sampled: blocks 0, 5, 10, ... are).
        for k in 0..3 {
            base.push(
                (0..n)
                    .map(|i| {
                        if (2 * BLOCK..3 * BLOCK).contains(&i) {
                            ((i * (k + 2)) as f32 * 0.013).cos()
                        } else {
                            0.0
                        }
                    })
                    .collect(),
            );
        }
        let mut shapes = base.clone();
        for (a, b, x) in [(0, 6, 0.5f32), (3, 7, -1.0), (1, 2, 0.25), (8, 5, 2.0)] {
            shapes.push(
                base[a]
                    .iter()
                    .zip(&base[b])
                    .map(|(p, q)| p + x * q)
                    .collect(),
            );
        }
        let s = shapes.len();
        let flat: Vec<f32> = shapes.iter().flatten().copied().collect();
        let found = ShapeBasis::find(&flat, s).unwrap();
        let g = gram(&flat, s, n);
        let at = |i: usize, j: usize| if j <= i { g[i * s + j] } else { g[j * s + i] };
        let norm: Vec<f64> = (0..s).map(|k| at(k, k)).collect();
        assert_eq!(
            norm.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
            gram_diagonal(&flat, s, n)
                .iter()
                .map(|x| x.to_bits())
                .collect::<Vec<_>>()
        );
        let (pivots, factor) = pivoted_cholesky(
            &norm,
            |_| true,
            |p, _, _| (0..s).map(|i| at(i, p)).collect(),
        );
        let whole = ShapeBasis::from_factor(pivots, &factor, s).unwrap();
        assert_eq!(found.shapes.len(), 9);
        assert_eq!(found.shapes, whole.shapes);
        let bits = |b: &ShapeBasis| {
            b.coefficients
                .iter()
                .map(|c| c.to_bits())
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(&found), bits(&whole));
        let q = found.shapes.len();
        for (k, shape) in shapes.iter().enumerate() {
            let c = &found.coefficients[k * q..(k + 1) * q];
            let (mut err, mut norm) = (0.0f64, 0.0f64);
            for (i, &x) in shape.iter().enumerate() {
                let y: f64 = (0..q)
                    .map(|j| c[j] * shapes[found.shapes[j]][i] as f64)
                    .sum();
                err += (y - x as f64).powi(2);
                norm += (x as f64).powi(2);
            }
            assert!(err <= 1e-10 * norm, "shape {k}: {err} of {norm}");
        }
        // A sample where no shape is a combination of the others settles it: no basis.
        let flat: Vec<f32> = base[..6].iter().flatten().copied().collect();
        assert!(ShapeBasis::find(&flat, 6).is_none());
    }

    #[test]
    fn the_basis_is_the_same_bits_with_any_thread_count_and_dot_matches_a_plain_sum() {
        // 71 blocks of coordinates (more than GROUPS, so a group sums several): 4 independent
        // shapes, then combinations of them.
        let n = 70 * BLOCK + 123;
        let base = independent_shapes(4, n, 3, 0.011);
        let mut shapes = base.clone();
        shapes.push(
            base[0]
                .iter()
                .zip(&base[3])
                .map(|(a, b)| 0.3 * a + b)
                .collect(),
        );
        shapes.push(base[2].iter().map(|x| -0.5 * x).collect());
        let flat: Vec<f32> = shapes.iter().flatten().copied().collect();
        let in_pool = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| ShapeBasis::find(&flat, shapes.len()).unwrap())
        };
        let one = in_pool(1);
        assert_eq!(one.shapes.len(), 4);
        for threads in [2, 3, 7] {
            let other = in_pool(threads);
            assert_eq!(other.shapes, one.shapes, "{threads} threads");
            let bits = |b: &ShapeBasis| {
                b.coefficients
                    .iter()
                    .map(|c| c.to_bits())
                    .collect::<Vec<_>>()
            };
            assert_eq!(bits(&other), bits(&one), "{threads} threads");
        }
        for len in [0, 5, 8, 13, 4096] {
            let (a, b) = (&shapes[0][..len], &shapes[4][..len]);
            let (plain, scale) = plain_dot(a, b);
            let wide = |r: &[f32]| r.iter().map(|&x| x as f64).collect::<Vec<_>>();
            assert!(
                (dot(&wide(a), &wide(b)) - plain).abs() <= 1e-14 * scale.max(1.0),
                "len {len}"
            );
        }
    }
}
