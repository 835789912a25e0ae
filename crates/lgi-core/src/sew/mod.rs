//! Sewing: every vertex blends the bundles' chosen local geometries with its natural-neighbour
//! weights, `x(v) = x0(v) + Σ_i W_vi Σ_j α_ij s_{k_ij}(v)`; then a residual pass spreads what
//! is left at the bundles with the same weights, solving the small B×B system exactly so that
//! every bundle's surface position matches its target. Which weights a frame uses (its plan,
//! per set of present bundles) is [`plan`]'s job.

use crate::choose::Choice;
use crate::error::Result;
use crate::geom::interpolate3;
use crate::linalg::Lu;
use crate::mesh::SurfacePoint;
use crate::simd::with_avx2;
use crate::sparse::{BlockColumns, SparseWeights, WeightRows};
use glam::DVec3;
use rayon::prelude::*;

pub(crate) mod context;
mod memo;
pub mod plan;
mod spans;

pub use plan::{SewGeometry, SewPlan, SewPlans};
pub use spans::ShapeSpans;

/// Vertices per parallel task of the blend, and rows per block of its [`BlockColumns`]: large
/// enough to amortise scheduling, small enough to balance.
pub const BLEND_BLOCK: usize = 512;

/// Each bundle's piece of geometry as a sparse shape-weight vector (shape id 0 = neutral):
/// a choice's 4 weights, or more after temporal smoothing, or the frame's global fit, which is
/// stored once for every bundle that took it (the sewing then reads it once per vertex).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Pieces {
    /// Bundle b's entries are `start[b]..start[b + 1]` (none for a bundle that took the fit).
    pub start: Vec<u32>,
    /// Shape ids.
    pub shapes: Vec<u32>,
    /// Weights (convex per bundle).
    pub weights: Vec<f64>,
    /// Per bundle: its piece is the frame's global fit (empty when no bundle's is).
    pub fit: Vec<bool>,
    /// The global fit's shape ids (its nonzero weights).
    pub fit_shapes: Vec<u32>,
    /// The global fit's weights.
    pub fit_weights: Vec<f64>,
}

impl Pieces {
    /// One bundle's entries.
    pub fn bundle(&self, b: usize) -> (&[u32], &[f64]) {
        if self.takes_fit(b) {
            return (&self.fit_shapes, &self.fit_weights);
        }
        let (s, e) = (self.start[b] as usize, self.start[b + 1] as usize);
        (&self.shapes[s..e], &self.weights[s..e])
    }

    /// True when bundle `b`'s piece is the frame's global fit.
    pub fn takes_fit(&self, b: usize) -> bool {
        self.fit.get(b).copied().unwrap_or(false)
    }

    /// The pieces of per-bundle choices (a missing bundle has no entries).
    pub fn from_choices(choices: &[Option<Choice>]) -> Pieces {
        Pieces::from_choices_with_fit(choices, &[])
    }

    /// As [`from_choices`](Self::from_choices), a bundle that took the frame's global fit
    /// getting the fit's weights `fit` (per shape id; empty when no bundle took it).
    pub fn from_choices_with_fit(choices: &[Option<Choice>], fit: &[f64]) -> Pieces {
        let mut p = Pieces {
            start: vec![0],
            ..Pieces::default()
        };
        if choices.iter().any(|c| c.is_some_and(|c| c.fit)) {
            p.fit = choices.iter().map(|c| c.is_some_and(|c| c.fit)).collect();
            for (k, &w) in fit.iter().enumerate() {
                if w != 0.0 {
                    p.fit_shapes.push(k as u32);
                    p.fit_weights.push(w);
                }
            }
        }
        for c in choices {
            if let Some(c) = c.filter(|c| !c.fit) {
                for j in 0..4 {
                    if c.weights[j] != 0.0 {
                        p.shapes.push(c.shapes[j]);
                        p.weights.push(c.weights[j]);
                    }
                }
            }
            p.start.push(p.shapes.len() as u32);
        }
        p
    }
}

/// Blends the pieces: writes `x0 + Σ_i W_vi Σ_j α_ij s_k(v)` into `out`.
/// `displacements` is the dataset's `S × V × 3` (shape id k ≥ 1 reads shape k − 1).
pub fn blend(
    x0: &[DVec3],
    displacements: &[f32],
    weights: &SparseWeights,
    pieces: &Pieces,
    out: &mut [DVec3],
) {
    blend_with(
        &BlendInput::new(x0, displacements, weights, pieces),
        None,
        out,
    );
}

/// [`blend`] read column by column within blocks of vertices (`columns`, from the same
/// `weights` with blocks of [`BLEND_BLOCK`] rows): the same sums in the same order, so the
/// same bits.
pub fn blend_by_columns(
    x0: &[DVec3],
    displacements: &[f32],
    weights: &SparseWeights,
    columns: &BlockColumns,
    pieces: &Pieces,
    out: &mut [DVec3],
) {
    let input = BlendInput::new(x0, displacements, weights, pieces);
    blend_with(&input, Some(columns), out);
}

/// The blend of `input` into `out`, block by block, by column where `columns` are given.
fn blend_with(input: &BlendInput<'_>, columns: Option<&BlockColumns>, out: &mut [DVec3]) {
    out.par_chunks_mut(BLEND_BLOCK)
        .enumerate()
        .for_each(|(c, chunk)| {
            let base = c * BLEND_BLOCK;
            match columns {
                Some(columns) => {
                    chunk.copy_from_slice(&input.summed_by_columns(c, base, chunk.len(), columns))
                }
                None => {
                    let block = input.block(base, chunk.len());
                    for (o, x) in chunk.iter_mut().enumerate() {
                        *x = block.vertex(o);
                    }
                }
            }
        });
}

with_avx2! {
/// `f += a s` over the entries of vertices `lo..hi` (as many as both have).
fn add_scaled(f: &mut [f64], s: &[f32], a: f64, lo: usize, hi: usize) {
    if let (Some(f), Some(s)) = (f.get_mut(3 * lo..3 * hi), s.get(3 * lo..3 * hi)) {
        for (f, s) in f.iter_mut().zip(s) {
            *f += a * *s as f64;
        }
    }
}
}

with_avx2! {
/// `f += a₀ s₀ + a₁ s₁ + a₂ s₂ + a₃ s₃`, each entry adding the four in order (the bits of four
/// [`add_scaled`] passes), loaded and stored once.
fn add_four_scaled(f: &mut [f64], s: [&[f32]; 4], a: [f64; 4]) {
    for ((((f, x0), x1), x2), x3) in f.iter_mut().zip(s[0]).zip(s[1]).zip(s[2]).zip(s[3]) {
        *f = *f + a[0] * *x0 as f64 + a[1] * *x1 as f64 + a[2] * *x2 as f64 + a[3] * *x3 as f64;
    }
}
}

/// What the blend of one frame reads (see [`blend`]), with each bundle's piece flattened to
/// (offset of the shape's row in `displacements`, weight) terms, the neutral left out; the
/// global fit's terms once, for the bundles that took it.
pub struct BlendInput<'a> {
    x0: &'a [DVec3],
    displacements: &'a [f32],
    weights: WeightRows<'a>,
    start: Vec<u32>,
    terms: Vec<(usize, f64)>,
    /// Per bundle: its piece is `fit_terms` (empty when no bundle's is).
    fit: Vec<bool>,
    fit_terms: Vec<(usize, f64)>,
    /// Where each shape of `displacements` moves, per block (`None`: everywhere).
    spans: Option<&'a ShapeSpans>,
}

impl<'a> BlendInput<'a> {
    /// `x0` (V) neutral positions of the space the pieces live in, `displacements` its
    /// `S × V × 3` shapes (shape id k ≥ 1 reads shape k − 1), `weights` V × B.
    pub fn new(
        x0: &'a [DVec3],
        displacements: &'a [f32],
        weights: impl Into<WeightRows<'a>>,
        pieces: &Pieces,
    ) -> Self {
        let weights = weights.into();
        let nv = x0.len();
        let flatten = |shapes: &[u32], alphas: &[f64], terms: &mut Vec<(usize, f64)>| {
            for (&k, &a) in shapes.iter().zip(alphas) {
                if k != 0 {
                    terms.push(((k as usize - 1) * nv * 3, a));
                }
            }
        };
        let mut start = Vec::with_capacity(pieces.start.len());
        let mut terms = Vec::with_capacity(pieces.shapes.len());
        start.push(0);
        for b in 0..pieces.start.len().saturating_sub(1) {
            if !pieces.takes_fit(b) {
                let (shapes, alphas) = pieces.bundle(b);
                flatten(shapes, alphas, &mut terms);
            }
            start.push(terms.len() as u32);
        }
        let mut fit_terms = Vec::with_capacity(pieces.fit_shapes.len());
        flatten(&pieces.fit_shapes, &pieces.fit_weights, &mut fit_terms);
        BlendInput {
            x0,
            displacements,
            weights,
            start,
            terms,
            fit: pieces.fit.clone(),
            fit_terms,
            spans: None,
        }
    }

    /// This input, its fit summed only where its shapes move: `spans` must be those of
    /// `displacements` ([`ShapeSpans::new`]); the same bits, fewer reads.
    pub fn with_spans(mut self, spans: Option<&'a ShapeSpans>) -> Self {
        self.spans = spans;
        self
    }

    /// One vertex of [`blend`]: `x0 + Σ_i W_vi Σ_j α_ij s_k(v)`. The bundles that took the
    /// global fit share its terms: their weights are summed and the fit is read once.
    #[inline]
    pub fn vertex(&self, v: usize) -> DVec3 {
        self.vertex_with(v, || {
            let mut f = [0.0f64; 3];
            for &(offset, a) in &self.fit_terms {
                if let Some(s) = self.displacements.get(offset + 3 * v..offset + 3 * v + 3) {
                    for c in 0..3 {
                        f[c] += a * s[c] as f64;
                    }
                }
            }
            f
        })
    }

    /// [`vertex`](Self::vertex) for the vertices `base..base + len` at once: the fit's
    /// displacement (dozens of shapes with every bundle on it) is summed shape by shape over
    /// the whole block, streaming each shape's rows, rather than vertex by vertex; the same
    /// operations in the same order, so the same bits.
    pub fn block(&self, base: usize, len: usize) -> Block<'_, 'a> {
        let mut fit = Vec::new();
        let any =
            !self.fit_terms.is_empty() && (base..base + len).any(|v| self.fit_weight(v) != 0.0);
        if any {
            fit = vec![0.0f64; 3 * len];
            // Each term's rows over the block, where its shape moves (a term out of range
            // adds nothing).
            let spans = self
                .spans
                .filter(|s| base % s.block() == 0 && len <= s.block());
            let nv = self.x0.len().max(1);
            let rows = |&(offset, a): &(usize, f64)| {
                let (lo, hi) = spans
                    .and_then(|s| s.span(offset / (3 * nv), base / s.block()))
                    .map_or((0, len), |(lo, hi)| (lo.min(len), hi.min(len)));
                let at = offset + 3 * base;
                let rows = self.displacements.get(at..at + 3 * len).unwrap_or(&[]);
                (rows, a, lo, hi.max(lo))
            };
            // Four terms per pass over the span of their spans: each entry still adds them
            // one by one in the terms' order (the same bits), but is loaded and stored once.
            let mut quads = self.fit_terms.chunks_exact(4);
            for quad in &mut quads {
                let t = [
                    rows(&quad[0]),
                    rows(&quad[1]),
                    rows(&quad[2]),
                    rows(&quad[3]),
                ];
                let moving = t.iter().filter(|t| t.2 < t.3);
                let lo = moving.clone().map(|t| t.2).min().unwrap_or(0);
                let hi = moving.map(|t| t.3).max().unwrap_or(0);
                let part = |s: &'a [f32]| s.get(3 * lo..3 * hi);
                match (part(t[0].0), part(t[1].0), part(t[2].0), part(t[3].0)) {
                    (Some(s0), Some(s1), Some(s2), Some(s3)) => {
                        let a = [t[0].1, t[1].1, t[2].1, t[3].1];
                        add_four_scaled(&mut fit[3 * lo..3 * hi], [s0, s1, s2, s3], a);
                    }
                    _ => {
                        for (s, a, lo, hi) in t {
                            add_scaled(&mut fit, s, a, lo, hi);
                        }
                    }
                }
            }
            for term in quads.remainder() {
                let (s, a, lo, hi) = rows(term);
                add_scaled(&mut fit, s, a, lo, hi);
            }
        }
        Block {
            input: self,
            base,
            fit,
        }
    }

    /// [`vertex`](Self::vertex) of the vertices `base..base + len` (block `c` of `columns`),
    /// summed bundle by bundle and shape by shape over the block: each shape's rows are read
    /// as one stream instead of a dozen interleaved ones per vertex. Every vertex still adds
    /// its terms in its row's order (bundles ascending, then each piece's terms), so the bits
    /// are [`vertex`](Self::vertex)'s.
    pub fn summed_by_columns(
        &self,
        c: usize,
        base: usize,
        len: usize,
        columns: &BlockColumns,
    ) -> Vec<DVec3> {
        if !columns.covers(c, base, len) {
            // Not this block's rows: vertex by vertex (the same bits).
            return (base..base + len).map(|v| self.vertex(v)).collect();
        }
        let mut d = vec![[0.0f64; 3]; len];
        let mut fit_weight = if self.fit.is_empty() {
            Vec::new()
        } else {
            vec![0.0f64; len]
        };
        let mut streams: Vec<(&[f32], f64)> = Vec::new();
        for (b, rows, vals) in columns.columns(c) {
            let b = b as usize;
            if self.fit.get(b).copied().unwrap_or(false) {
                for (&r, &w) in rows.iter().zip(vals) {
                    if let Some(f) = fit_weight.get_mut(r as usize) {
                        *f += w;
                    }
                }
                continue;
            }
            let (s, e) = (self.start[b] as usize, self.start[b + 1] as usize);
            // Each term's rows over the block, bounds-checked once.
            streams.clear();
            streams.extend(self.terms[s..e].iter().map(|&(offset, a)| {
                let at = offset + 3 * base;
                (self.displacements.get(at..at + 3 * len).unwrap_or(&[]), a)
            }));
            for (&r, &w) in rows.iter().zip(vals) {
                let r = r as usize;
                let Some(d) = d.get_mut(r) else { continue };
                let mut x = *d;
                for &(block, a) in &streams {
                    if let Some(s) = block.get(3 * r..3 * r + 3) {
                        let f = w * a;
                        x[0] += f * s[0] as f64;
                        x[1] += f * s[1] as f64;
                        x[2] += f * s[2] as f64;
                    }
                }
                *d = x;
            }
        }
        let fitted = if fit_weight.iter().any(|&w| w != 0.0) {
            self.block(base, len).fit
        } else {
            Vec::new()
        };
        (0..len)
            .map(|o| {
                let mut d = d[o];
                if let Some(&w) = fit_weight.get(o).filter(|&&w| w != 0.0) {
                    let f = fitted.get(3 * o..3 * o + 3).unwrap_or(&[0.0; 3]);
                    for (d, f) in d.iter_mut().zip(f) {
                        *d += w * f;
                    }
                }
                self.x0[base + o] + DVec3::from_array(d)
            })
            .collect()
    }

    /// The summed weight of the bundles that took the fit at vertex `v`.
    fn fit_weight(&self, v: usize) -> f64 {
        let (cols, vals) = self.weights.row(v);
        cols.iter()
            .zip(vals)
            .filter(|(&b, _)| self.fit.get(b as usize).copied().unwrap_or(false))
            .map(|(_, &w)| w)
            .sum()
    }

    /// `x0(v)` plus the pieces at `v`, the fit's displacement at `v` (Σ_k a_k s_k(v)) from
    /// `fit` when some bundle there took it.
    #[inline]
    fn vertex_with(&self, v: usize, fit: impl FnOnce() -> [f64; 3]) -> DVec3 {
        let (cols, vals) = self.weights.row(v);
        let mut d = [0.0f64; 3];
        let piece = |b: u32| {
            let (s, e) = (
                self.start[b as usize] as usize,
                self.start[b as usize + 1] as usize,
            );
            &self.terms[s..e]
        };
        if self.fit.is_empty() {
            // No bundle took the fit (the paper's method): no per-bundle test in this loop.
            for (&b, &w) in cols.iter().zip(vals) {
                self.add_terms(piece(b), w, v, &mut d);
            }
        } else {
            let mut fit_weight = 0.0;
            for (&b, &w) in cols.iter().zip(vals) {
                if self.fit.get(b as usize).copied().unwrap_or(false) {
                    fit_weight += w;
                } else {
                    self.add_terms(piece(b), w, v, &mut d);
                }
            }
            if fit_weight != 0.0 {
                let f = fit();
                for c in 0..3 {
                    d[c] += fit_weight * f[c];
                }
            }
        }
        self.x0[v] + DVec3::from_array(d)
    }

    /// Adds `w Σ_j α_j s_j(v)` over `terms` to `d`.
    #[inline]
    fn add_terms(&self, terms: &[(usize, f64)], w: f64, v: usize, d: &mut [f64; 3]) {
        for &(offset, a) in terms {
            let at = offset + 3 * v;
            if let Some(s) = self.displacements.get(at..at + 3) {
                let f = w * a;
                d[0] += f * s[0] as f64;
                d[1] += f * s[1] as f64;
                d[2] += f * s[2] as f64;
            }
        }
    }
}

/// A block of consecutive vertices of a [`BlendInput`], with the fit's displacement summed
/// once for all of them ([`BlendInput::block`]).
pub struct Block<'b, 'a> {
    input: &'b BlendInput<'a>,
    base: usize,
    /// 3 per vertex of the block; empty when no vertex of the block takes the fit.
    fit: Vec<f64>,
}

impl Block<'_, '_> {
    /// Vertex `base + o`, bit for bit [`BlendInput::vertex`].
    #[inline]
    pub fn vertex(&self, o: usize) -> DVec3 {
        self.input.vertex_with(self.base + o, || {
            // Empty when the fit has no shape terms (the neutral): a zero displacement.
            match self.fit.get(3 * o..3 * o + 3) {
                Some(f) => [f[0], f[1], f[2]],
                None => [0.0; 3],
            }
        })
    }
}

/// Where the residual pass must put the bundles: their surface points and targets (NaN rows
/// are missing), and the round-off that triggers a refinement round (absolute).
#[derive(Clone, Copy)]
pub struct BundleTargets<'a> {
    /// The mesh's triangles.
    pub triangles: &'a [[u32; 3]],
    /// Every bundle's surface point.
    pub bundles: &'a [SurfacePoint],
    /// Every bundle's target.
    pub targets: &'a [DVec3],
    /// Largest round-off left at a bundle without a second round.
    pub tolerance: f64,
}

/// The exact residual correction for one set of present bundles.
#[derive(Debug, Clone)]
pub struct ResidualPass {
    /// Present bundles, in the order of the system's rows.
    present: Vec<u32>,
    /// Position of each bundle in `present` (u32::MAX when missing).
    slot: Vec<u32>,
    lu: Lu,
}

impl ResidualPass {
    /// Builds `M[a][b] = Σ_c bary_ac W[v_ac][b]` (how a unit correction at bundle b moves
    /// bundle a's surface point) over the present bundles and factorises it.
    pub fn new(
        triangles: &[[u32; 3]],
        bundles: &[SurfacePoint],
        weights: WeightRows<'_>,
        present: &[u32],
    ) -> Result<Self> {
        let n = present.len();
        let mut slot = vec![u32::MAX; bundles.len()];
        for (i, &b) in present.iter().enumerate() {
            slot[b as usize] = i as u32;
        }
        let mut m = vec![0.0; n * n];
        for (row, &a) in present.iter().enumerate() {
            let sp = bundles[a as usize];
            let tri = triangles[sp.triangle as usize];
            for (&v, &bary) in tri.iter().zip(&sp.bary) {
                let (cols, vals) = weights.row(v as usize);
                for (&b, &w) in cols.iter().zip(vals) {
                    let s = slot[b as usize];
                    if s != u32::MAX {
                        m[row * n + s as usize] += bary * w;
                    }
                }
            }
        }
        let lu = Lu::factor(n, m)?;
        Ok(ResidualPass {
            present: present.to_vec(),
            slot,
            lu,
        })
    }

    /// The correction rounds the residual pass adds (by bundle id): the first, and a second
    /// only when the first left more than the tolerance (as in `apply`). They need only the
    /// present bundles' triangle corners, blended and mapped: `corners(b)` gives bundle b's.
    fn rounds(
        &self,
        input: &BlendInput<'_>,
        corners: impl Fn(u32) -> [(usize, DVec3); 3],
        at: &BundleTargets<'_>,
    ) -> Vec<Vec<DVec3>> {
        // The present bundles' corners (3 per bundle, in `present` order).
        let corners: Vec<(usize, DVec3)> = self.present.iter().flat_map(|&b| corners(b)).collect();
        // A round's corrections by bundle id (the weights' columns are present bundles only).
        let by_bundle = |c: Vec<[f64; 3]>| -> Vec<DVec3> {
            let mut out = vec![DVec3::ZERO; self.slot.len()];
            for (&b, c) in self.present.iter().zip(c) {
                out[b as usize] = DVec3::from_array(c);
            }
            out
        };
        let residuals = |rounds: &[Vec<DVec3>]| -> Vec<[f64; 3]> {
            self.present
                .iter()
                .zip(corners.chunks(3))
                .map(|(&b, c)| {
                    let sp = at.bundles[b as usize];
                    let x = [0, 1, 2].map(|j| corrected(input.weights, c[j].0, c[j].1, rounds));
                    (at.targets[b as usize] - interpolate3(x, sp.bary)).to_array()
                })
                .collect()
        };
        let mut rounds = vec![by_bundle(self.lu.solve3(&residuals(&[])))];
        let r = residuals(&rounds);
        let worst = r
            .iter()
            .map(|v| DVec3::from_array(*v).length())
            .fold(0.0, f64::max);
        if worst.is_nan() || worst > at.tolerance {
            rounds.push(by_bundle(self.lu.solve3(&r)));
        }
        rounds
    }

    /// Every bundle's position (`at.bundles`, missing ones too) on the surface
    /// [`sew`](Self::sew) makes, bit for bit, from its triangle's corners alone: no other
    /// vertex is blended (what a reading of the markers needs, at a fraction of the work).
    pub fn sew_markers(
        &self,
        input: &BlendInput<'_>,
        map: impl Fn(usize, DVec3) -> DVec3 + Sync,
        at: &BundleTargets<'_>,
    ) -> Vec<DVec3> {
        // Every bundle's corners, blended and mapped once: the rounds read the present ones'.
        let corners: Vec<[(usize, DVec3); 3]> = at
            .bundles
            .iter()
            .map(|sp| blended_corners(input, &map, at.triangles, sp))
            .collect();
        let rounds = self.rounds(input, |b| corners[b as usize], at);
        at.bundles
            .iter()
            .zip(&corners)
            .map(|(sp, c)| {
                let x = c.map(|(v, x)| corrected(input.weights, v, x, &rounds));
                interpolate3(x, sp.bary)
            })
            .collect()
    }

    /// The whole of sewing in one pass over the vertices: `out[v] = map(v, blend(v))` plus the
    /// residual corrections, bit for bit what [`blend`], `map` over every vertex and the
    /// staged residual pass (`apply`, kept as the tests' reference) give one after another.
    /// The corrections only need the bundles' triangle corners, so those are blended first
    /// ([`rounds`](Self::rounds)) and every other vertex is written once. Returns the first
    /// vertex that is not finite, if any.
    pub fn sew(
        &self,
        input: &BlendInput<'_>,
        columns: Option<&BlockColumns>,
        map: impl Fn(usize, DVec3) -> DVec3 + Sync,
        at: &BundleTargets<'_>,
        out: &mut [DVec3],
    ) -> Option<usize> {
        let rounds = self.rounds(
            input,
            |b| blended_corners(input, &map, at.triangles, &at.bundles[b as usize]),
            at,
        );
        out.par_chunks_mut(BLEND_BLOCK)
            .enumerate()
            .map(|(ci, chunk)| {
                let (base, len) = (ci * BLEND_BLOCK, chunk.len());
                match columns.filter(|c| c.covers(ci, base, len)) {
                    Some(columns) => {
                        // Blended, mapped, then corrected column by column: each vertex still
                        // adds round by round, bundles ascending, as `corrected` does.
                        let mut xs = input.summed_by_columns(ci, base, len, columns);
                        for (o, x) in xs.iter_mut().enumerate() {
                            *x = map(base + o, *x);
                        }
                        for c in &rounds {
                            for (b, rows, vals) in columns.columns(ci) {
                                let c = c[b as usize];
                                for (&r, &w) in rows.iter().zip(vals) {
                                    if let Some(x) = xs.get_mut(r as usize) {
                                        *x += c * w;
                                    }
                                }
                            }
                        }
                        chunk.copy_from_slice(&xs);
                    }
                    None => {
                        let block = input.block(base, len);
                        for (o, x) in chunk.iter_mut().enumerate() {
                            let v = base + o;
                            *x = corrected(input.weights, v, map(v, block.vertex(o)), &rounds);
                        }
                    }
                }
                chunk.iter().position(|x| !x.is_finite()).map(|o| base + o)
            })
            .reduce(|| None, |a, b| a.or(b))
    }

    /// Moves `x` so that every present bundle's surface point equals its target: the staged
    /// residual pass, the reference [`sew`](Self::sew) is tested against (tests only).
    #[cfg(test)]
    pub(crate) fn apply(
        &self,
        triangles: &[[u32; 3]],
        bundles: &[SurfacePoint],
        weights: &SparseWeights,
        targets: &[DVec3],
        tolerance: f64,
        x: &mut [DVec3],
    ) {
        // Up to two rounds: a second one (iterative refinement) only when the first left more
        // round-off than `tolerance` at some bundle.
        for round in 0..2 {
            let r: Vec<[f64; 3]> = self
                .present
                .iter()
                .map(|&b| {
                    let sp = bundles[b as usize];
                    (targets[b as usize] - sp.evaluate(triangles, x)).to_array()
                })
                .collect();
            let worst = r
                .iter()
                .map(|v| DVec3::from_array(*v).length())
                .fold(0.0, f64::max);
            if round > 0 && worst <= tolerance {
                break;
            }
            let c = self.lu.solve3(&r);
            let slot = &self.slot;
            x.par_chunks_mut(BLEND_BLOCK)
                .enumerate()
                .for_each(|(ci, chunk)| {
                    for (o, xv) in chunk.iter_mut().enumerate() {
                        let (cols, vals) = weights.row(ci * BLEND_BLOCK + o);
                        for (&b, &w) in cols.iter().zip(vals) {
                            let s = slot[b as usize];
                            if s != u32::MAX {
                                *xv += DVec3::from_array(c[s as usize]) * w;
                            }
                        }
                    }
                });
        }
    }
}

/// A bundle's triangle corners, each vertex with its position blended and mapped.
fn blended_corners(
    input: &BlendInput<'_>,
    map: &impl Fn(usize, DVec3) -> DVec3,
    triangles: &[[u32; 3]],
    sp: &SurfacePoint,
) -> [(usize, DVec3); 3] {
    triangles[sp.triangle as usize].map(|v| (v as usize, map(v as usize, input.vertex(v as usize))))
}

/// Vertex `v` at `x` (blended and mapped) plus the correction rounds, each round's bundles
/// ascending by the vertex's sewing weights: the one order every path of the sewing adds in.
#[inline]
fn corrected(weights: WeightRows<'_>, v: usize, x: DVec3, rounds: &[Vec<DVec3>]) -> DVec3 {
    let mut x = x;
    let (cols, vals) = weights.row(v);
    for c in rounds {
        for (&b, &w) in cols.iter().zip(vals) {
            x += c[b as usize] * w;
        }
    }
    x
}

#[cfg(test)]
mod tests;
