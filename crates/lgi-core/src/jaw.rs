//! Jaw skinning (the paper's Eq. 2): two-bone linear blend skinning with the skull fixed and the
//! jaw a rigid motion about a pivot. Dataset shapes and captured bundles are unskinned before
//! indexing so the index sees no jaw rotation, and the result is reskinned afterwards.
//!
//! The one implementation of the skinning: Python skins through it (`lgi._lgi.JawRig`, used by
//! `lgi.jaw` and the sample generator), and `jaw/fit.rs` fits poses to points with it.
//! θ = (open, lateral, forward) maps `p` to `F R Fᵀ (p − pivot) + pivot + F t` with
//! `R = R_y(lateral) · R_x(open)`, `t = (0, 0, forward)` and `F` the rig's frame (columns: open
//! axis, lateral axis, forward direction; identity in the sample).

use glam::{DAffine3, DMat3, DVec3};
use rayon::prelude::*;

use crate::error::{LgiError, Result};

mod fit;

/// Jaw pose θ: open angle (radians, about x; positive moves the chin down and back), lateral
/// angle (radians, about y; positive moves the chin towards +x) and forward translation along
/// +z (data units).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct JawParams {
    /// Opening angle about the x axis through the pivot, radians.
    pub open: f64,
    /// Lateral angle about the y axis through the pivot, radians.
    pub lateral: f64,
    /// Forward translation along +z, in the data's units.
    pub forward: f64,
}

impl JawParams {
    /// The rest pose (all zero): skinning with it is the identity.
    pub const ZERO: JawParams = JawParams {
        open: 0.0,
        lateral: 0.0,
        forward: 0.0,
    };

    /// θ from `[open, lateral, forward]`.
    pub fn from_array(a: [f64; 3]) -> Self {
        JawParams {
            open: a[0],
            lateral: a[1],
            forward: a[2],
        }
    }

    /// `[open, lateral, forward]`.
    pub fn to_array(self) -> [f64; 3] {
        [self.open, self.lateral, self.forward]
    }

    /// Checks that θ is finite and both angles are below 180° in magnitude. Below 180° the
    /// blended matrix `(1 − w) I + w R` is invertible for every weight in [0, 1], so unskinning
    /// is well defined.
    pub fn validate(&self) -> Result<()> {
        let ok = self.open.is_finite()
            && self.lateral.is_finite()
            && self.forward.is_finite()
            && self.open.abs() < std::f64::consts::PI
            && self.lateral.abs() < std::f64::consts::PI;
        if ok {
            Ok(())
        } else {
            Err(LgiError::Input(format!(
                "jaw parameters must be finite with |open|, |lateral| < pi rad, got open {} rad, \
                 lateral {} rad, forward {}",
                crate::text::num(self.open),
                crate::text::num(self.lateral),
                crate::text::num(self.forward)
            )))
        }
    }

    /// The jaw's rotation `R_y(lateral) · R_x(open)`.
    pub fn rotation(&self) -> DMat3 {
        DMat3::from_rotation_y(self.lateral) * DMat3::from_rotation_x(self.open)
    }

    /// The jaw's translation `(0, 0, forward)`.
    pub fn translation(&self) -> DVec3 {
        DVec3::new(0.0, 0.0, self.forward)
    }
}

/// A two-bone jaw rig: the pivot of the jaw rotation, the jaw's axes and one jaw weight per
/// vertex (0 = follows the skull, 1 = follows the jaw).
#[derive(Debug, Clone, PartialEq)]
pub struct JawRig {
    /// Centre of the jaw rotation.
    pub pivot: DVec3,
    /// Per-vertex jaw weight in [0, 1].
    pub weights: Vec<f64>,
    /// The jaw's axes as a rotation: columns are the open axis, the lateral axis and the
    /// forward direction (identity: x, y, z). θ is applied in this frame.
    pub frame: DMat3,
}

/// How far `FᵀF` may be from the identity (largest element) for a frame to count as
/// orthonormal; matches the Python rig's check.
pub const FRAME_TOLERANCE: f64 = 1e-9;

/// Checks that `frame` is a rotation: finite, orthonormal columns (`FᵀF = I` to
/// [`FRAME_TOLERANCE`]) and determinant +1 (not a reflection).
pub fn validate_frame(frame: &DMat3) -> Result<()> {
    if !frame.is_finite() {
        return Err(LgiError::Input(format!(
            "jaw frame must be finite, got columns {} {} {}",
            crate::text::point(frame.x_axis),
            crate::text::point(frame.y_axis),
            crate::text::point(frame.z_axis)
        )));
    }
    let gram = frame.transpose() * *frame - DMat3::IDENTITY;
    let off = gram
        .to_cols_array()
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs()));
    if off > FRAME_TOLERANCE {
        return Err(LgiError::Input(format!(
            "jaw frame columns must be orthonormal: max |F^T F - I| = {off:e} > \
             {FRAME_TOLERANCE:e}"
        )));
    }
    let det = frame.determinant();
    if det <= 0.0 {
        return Err(LgiError::Input(format!(
            "jaw frame must be a rotation (determinant +1), got a reflection (determinant {det})"
        )));
    }
    Ok(())
}

/// The blended skinning map of one vertex, `p ↦ p + w ((R − I)(p − pivot) + t)` with `R` and
/// `t` in world space, kept as its pieces so the inverse can be applied exactly.
#[derive(Debug, Clone, Copy)]
struct Blend {
    rot_minus_id: DMat3,
    translation: DVec3,
    pivot: DVec3,
}

impl Blend {
    /// World space: `F R Fᵀ − I` is formed as `F (R − I) Fᵀ` so that θ = 0 still gives an
    /// exactly zero map (`F Fᵀ − I` is only zero to rounding). The identity frame skips the
    /// products so those rigs keep the exact arithmetic of the frame-less rig.
    fn new(theta: JawParams, pivot: DVec3, frame: &DMat3) -> Self {
        let rot_minus_id = theta.rotation() - DMat3::IDENTITY;
        let translation = theta.translation();
        if *frame == DMat3::IDENTITY {
            return Blend {
                rot_minus_id,
                translation,
                pivot,
            };
        }
        Blend {
            rot_minus_id: *frame * rot_minus_id * frame.transpose(),
            translation: *frame * translation,
            pivot,
        }
    }

    /// Written as `p + w · moved` (not `(1 − w) p + w T p`) so that θ = 0 or w = 0 returns `p`
    /// bit for bit. Each row of `(R − I)(p − pivot)` is summed with fused multiply-adds, x term
    /// first ([`fused_row`]): one rounding per term on every machine, and the order numpy's
    /// matrix product takes, so the sample generator's truth (first written with numpy) is
    /// reproduced bit for bit now that it skins through this function.
    #[inline]
    fn skin(&self, p: DVec3, w: f64) -> DVec3 {
        let moved = fused_mul_vec(&self.rot_minus_id, p - self.pivot) + self.translation;
        p + w * moved
    }

    /// Solves `M q = y − pivot − w t` with `M = I + w (R − I)` and returns `pivot + q`.
    #[inline]
    fn unskin(&self, y: DVec3, w: f64) -> DVec3 {
        if w == 0.0 {
            return y;
        }
        let m = DMat3::IDENTITY + self.rot_minus_id * w;
        let rhs = y - self.pivot - w * self.translation;
        let inv = m.inverse();
        let mut q = inv * rhs;
        // One step of iterative refinement: the cofactor inverse is accurate to a few ulps of
        // cond(M); the correction brings the round trip to the rounding of the forward map.
        q += inv * (rhs - m * q);
        self.pivot + q
    }
}

/// `m · d` with each row summed as `fma(d.z, m₂, fma(d.y, m₁, d.x · m₀))`.
#[inline]
fn fused_mul_vec(m: &DMat3, d: DVec3) -> DVec3 {
    let row = |i: usize| {
        d.z.mul_add(m.z_axis[i], d.y.mul_add(m.y_axis[i], d.x * m.x_axis[i]))
    };
    DVec3::new(row(0), row(1), row(2))
}

impl JawRig {
    /// A rig with the identity frame (θ about x, y, along z) from its pivot and per-vertex
    /// weights; every value must be finite and every weight in [0, 1] (the error names the
    /// first offending vertex).
    pub fn new(pivot: DVec3, weights: Vec<f64>) -> Result<Self> {
        JawRig::with_frame(pivot, weights, DMat3::IDENTITY)
    }

    /// A rig whose axes are the columns of `frame` (open axis, lateral axis, forward
    /// direction), which must be a rotation ([`validate_frame`]); otherwise as [`JawRig::new`].
    pub fn with_frame(pivot: DVec3, weights: Vec<f64>, frame: DMat3) -> Result<Self> {
        if !pivot.is_finite() {
            return Err(LgiError::Input(format!(
                "jaw pivot must be finite, got {}",
                crate::text::point(pivot)
            )));
        }
        if let Some((v, w)) = weights
            .iter()
            .enumerate()
            .find(|(_, w)| !(w.is_finite() && (0.0..=1.0).contains(*w)))
        {
            return Err(LgiError::Input(format!(
                "jaw weight of vertex {v} must be finite and in [0, 1], got {w}"
            )));
        }
        validate_frame(&frame)?;
        Ok(JawRig {
            pivot,
            weights,
            frame,
        })
    }

    /// Number of vertices the rig has weights for.
    pub fn num_vertices(&self) -> usize {
        self.weights.len()
    }

    /// The rigid jaw transform for `theta` about `pivot` in the identity frame:
    /// `p ↦ R (p − pivot) + pivot + t`.
    pub fn transform(theta: JawParams, pivot: DVec3) -> DAffine3 {
        let r = theta.rotation();
        DAffine3::from_mat3_translation(r, pivot - r * pivot + theta.translation())
    }

    /// This rig's rigid jaw transform for `theta` (weight-1 vertices move by it):
    /// `p ↦ F R Fᵀ (p − pivot) + pivot + F t`.
    pub fn rigid_transform(&self, theta: JawParams) -> DAffine3 {
        let f = self.frame;
        let r = f * theta.rotation() * f.transpose();
        DAffine3::from_mat3_translation(r, self.pivot - r * self.pivot + f * theta.translation())
    }

    /// The blended map of `theta` in this rig's frame.
    fn blend(&self, theta: JawParams) -> Blend {
        Blend::new(theta, self.pivot, &self.frame)
    }

    /// Skins one point with jaw weight `w`: `p + w (T(θ) p − p)`.
    pub fn skin_point(&self, p: DVec3, w: f64, theta: JawParams) -> DVec3 {
        self.blend(theta).skin(p, w)
    }

    /// The exact inverse of [`JawRig::skin_point`] (the blended affine map inverted in f64).
    /// θ should satisfy [`JawParams::validate`]; otherwise the result may not be finite.
    pub fn unskin_point(&self, p: DVec3, w: f64, theta: JawParams) -> DVec3 {
        self.blend(theta).unskin(p, w)
    }

    /// Jaw weight at a point given by barycentric coordinates in a triangle of the mesh the rig
    /// belongs to (how bundles get their weight).
    pub fn interpolate_weight(&self, triangle: [u32; 3], barycentric: [f64; 3]) -> Result<f64> {
        let mut w = 0.0;
        for (&v, &b) in triangle.iter().zip(barycentric.iter()) {
            let wv = self.weights.get(v as usize).ok_or_else(|| {
                LgiError::Input(format!(
                    "triangle vertex {v} out of range (rig has {} vertices)",
                    self.weights.len()
                ))
            })?;
            w += b * wv;
        }
        Ok(w.clamp(0.0, 1.0))
    }

    /// Skins every vertex with its own weight into `out`.
    pub fn skin(&self, positions: &[DVec3], theta: JawParams, out: &mut [DVec3]) -> Result<()> {
        self.apply(positions, theta, out, Blend::skin)
    }

    /// [`JawRig::skin`] in place, one thread: for a caller that already runs frames in
    /// parallel (a frame's mesh, skinned where it lies, without a copy or nested tasks). The
    /// same arithmetic, bit for bit, where a vertex moves; a vertex of weight 0 is left as it
    /// is (`p + 0 · moved` equals `p`; only a coordinate of −0.0 would read +0.0 there).
    pub fn skin_in_place(&self, points: &mut [DVec3], theta: JawParams) -> Result<()> {
        theta.validate()?;
        if points.len() != self.weights.len() {
            return Err(LgiError::Input(format!(
                "jaw skinning needs one weight per point: {} points, {} weights",
                points.len(),
                self.weights.len()
            )));
        }
        let blend = self.blend(theta);
        for (p, &w) in points.iter_mut().zip(&self.weights) {
            if w != 0.0 {
                *p = blend.skin(*p, w);
            }
        }
        Ok(())
    }

    /// Unskins every vertex with its own weight into `out` (inverse of [`JawRig::skin`]).
    pub fn unskin(&self, positions: &[DVec3], theta: JawParams, out: &mut [DVec3]) -> Result<()> {
        self.apply(positions, theta, out, Blend::unskin)
    }

    /// Skins arbitrary points (e.g. bundles) each with its own weight from `weights`.
    pub fn skin_weighted(
        &self,
        positions: &[DVec3],
        weights: &[f64],
        theta: JawParams,
        out: &mut [DVec3],
    ) -> Result<()> {
        apply_weighted(self, positions, weights, theta, out, Blend::skin)
    }

    /// Unskins arbitrary points (e.g. bundles) each with its own weight from `weights`.
    pub fn unskin_weighted(
        &self,
        positions: &[DVec3],
        weights: &[f64],
        theta: JawParams,
        out: &mut [DVec3],
    ) -> Result<()> {
        apply_weighted(self, positions, weights, theta, out, Blend::unskin)
    }

    /// Unskins one dataset shape: `s*_k = T_v(θ_k)⁻¹ (x0 + s_k) − x0`, with `disp` the V·3
    /// displacements of the shape. Computed in f64, returned as f32 like the dataset stores it.
    pub fn unskin_displacements(
        &self,
        neutral: &[DVec3],
        disp: &[f32],
        theta: JawParams,
    ) -> Result<Vec<f32>> {
        theta.validate()?;
        let v = self.weights.len();
        if neutral.len() != v {
            return Err(LgiError::Input(format!(
                "neutral has {} vertices, jaw rig has {v} weights",
                neutral.len()
            )));
        }
        if disp.len() != 3 * v {
            return Err(LgiError::Input(format!(
                "displacements have {} values, expected {} (3 per vertex)",
                disp.len(),
                3 * v
            )));
        }
        let blend = self.blend(theta);
        let mut out = vec![0.0f32; 3 * v];
        out.par_chunks_mut(3)
            .zip(disp.par_chunks(3))
            .zip(neutral.par_iter().zip(self.weights.par_iter()))
            .for_each(|((o, s), (&x0, &w))| {
                let s = DVec3::new(f64::from(s[0]), f64::from(s[1]), f64::from(s[2]));
                let d = blend.unskin(x0 + s, w) - x0;
                o[0] = d.x as f32;
                o[1] = d.y as f32;
                o[2] = d.z as f32;
            });
        Ok(out)
    }

    /// Unskins all S shapes of a dataset (`displacements` shape-major, S·V·3) with their θ_k.
    pub fn unskin_shapes(
        &self,
        neutral: &[DVec3],
        displacements: &[f32],
        thetas: &[JawParams],
    ) -> Result<Vec<f32>> {
        let stride = 3 * self.weights.len();
        if displacements.len() != thetas.len() * stride {
            return Err(LgiError::Input(format!(
                "displacements have {} values, expected {} shapes x {stride}",
                displacements.len(),
                thetas.len()
            )));
        }
        let mut out = Vec::with_capacity(displacements.len());
        for (k, theta) in thetas.iter().enumerate() {
            let shape = &displacements[k * stride..(k + 1) * stride];
            out.extend(self.unskin_displacements(neutral, shape, *theta)?);
        }
        Ok(out)
    }

    /// Re-poses dataset shapes to a reference pose (a jaw bin's): returns the neutral skinned
    /// to `reference`, `T(θ_ref) x0`, and for each of `members` (dataset shape indices) its
    /// displacement from it, `T(θ_ref) T(θ_k)⁻¹ (x0 + s_k) − T(θ_ref) x0` (per-vertex maps,
    /// f64 math, f32 storage like the dataset), shape-major.
    pub fn repose_shapes(
        &self,
        neutral: &[DVec3],
        displacements: &[f32],
        thetas: &[JawParams],
        members: &[u32],
        reference: JawParams,
    ) -> Result<(Vec<DVec3>, Vec<f32>)> {
        reference.validate()?;
        let v = self.weights.len();
        let stride = 3 * v;
        if neutral.len() != v || displacements.len() != thetas.len() * stride {
            return Err(LgiError::Input(format!(
                "re-posing needs {v} neutral vertices and {} x {stride} displacement values, \
                 got {} and {}",
                thetas.len(),
                neutral.len(),
                displacements.len()
            )));
        }
        let to_ref = self.blend(reference);
        let mut base = vec![DVec3::ZERO; v];
        base.par_iter_mut()
            .zip(neutral.par_iter().zip(self.weights.par_iter()))
            .for_each(|(o, (&x0, &w))| *o = to_ref.skin(x0, w));
        let mut out = vec![0.0f32; members.len() * stride];
        for (j, &k) in members.iter().enumerate() {
            let k = k as usize;
            let theta = *thetas.get(k).ok_or_else(|| {
                LgiError::Input(format!("member shape {k} out of range ({})", thetas.len()))
            })?;
            theta.validate()?;
            let from = self.blend(theta);
            let shape = &displacements[k * stride..(k + 1) * stride];
            out[j * stride..(j + 1) * stride]
                .par_chunks_mut(3)
                .zip(shape.par_chunks(3))
                .zip(neutral.par_iter().zip(self.weights.par_iter()))
                .zip(base.par_iter())
                .for_each(|(((o, s), (&x0, &w)), &b0)| {
                    let s = DVec3::new(f64::from(s[0]), f64::from(s[1]), f64::from(s[2]));
                    let d = to_ref.skin(from.unskin(x0 + s, w), w) - b0;
                    o[0] = d.x as f32;
                    o[1] = d.y as f32;
                    o[2] = d.z as f32;
                });
        }
        Ok((base, out))
    }

    fn apply(
        &self,
        positions: &[DVec3],
        theta: JawParams,
        out: &mut [DVec3],
        f: fn(&Blend, DVec3, f64) -> DVec3,
    ) -> Result<()> {
        apply_weighted(self, positions, &self.weights, theta, out, f)
    }
}

/// A frame's jaw map of every vertex, for sewing one vertex at a time: unskin from `from` (a
/// bin's reference pose), then skin to `to` (the frame's pose) — vertex by vertex the same
/// arithmetic as [`JawRig::unskin`] then [`JawRig::skin`].
#[derive(Debug, Clone)]
pub struct VertexMap<'a> {
    weights: &'a [f64],
    from: Option<Blend>,
    to: Option<Blend>,
}

impl JawRig {
    /// The map from pose `from` to pose `to` (`None`: rest, no transform) for a mesh of
    /// `num_vertices` vertices.
    pub fn vertex_map(
        &self,
        from: Option<JawParams>,
        to: Option<JawParams>,
        num_vertices: usize,
    ) -> Result<VertexMap<'_>> {
        if num_vertices != self.weights.len() {
            return Err(LgiError::Input(format!(
                "jaw skinning needs one weight per vertex: {num_vertices} vertices, {} weights",
                self.weights.len()
            )));
        }
        let blend = |t: Option<JawParams>| -> Result<Option<Blend>> {
            t.map(|t| t.validate().map(|_| self.blend(t))).transpose()
        };
        Ok(VertexMap {
            weights: &self.weights,
            from: blend(from)?,
            to: blend(to)?,
        })
    }
}

impl VertexMap<'_> {
    /// Vertex `v` at `p` mapped from the first pose to the second.
    #[inline]
    pub fn apply(&self, v: usize, p: DVec3) -> DVec3 {
        let w = self.weights.get(v).copied().unwrap_or(0.0);
        let mut q = p;
        if let Some(b) = &self.from {
            q = b.unskin(q, w);
        }
        if let Some(b) = &self.to {
            q = b.skin(q, w);
        }
        q
    }
}

/// Point clouds binned by jaw opening (the paper's suggestion for large openings): bin b's core
/// range over θ.open is `[edges[b], edges[b + 1]]`; its members are the dataset shapes whose
/// opening lies in the core range widened by `overlap` on both sides, unskinned to the bin's
/// reference pose (the core range's midpoint). Binning changes which shapes a frame may use.
#[derive(Debug, Clone, PartialEq)]
pub struct JawBins {
    /// Bin edges over the opening angle (radians), finite and strictly increasing; K + 1 of
    /// them for K bins.
    pub edges: Vec<f64>,
    /// How far (radians, ≥ 0) each bin's member range reaches beyond its core range.
    pub overlap: f64,
}

impl JawBins {
    /// Checks the edges (at least 2, finite, strictly increasing, references below 180°) and
    /// the overlap (finite, ≥ 0).
    pub fn validate(&self) -> Result<()> {
        let e = &self.edges;
        if e.len() < 2 {
            return Err(LgiError::Input(format!(
                "jaw bins need at least 2 edges (one bin), got {}",
                e.len()
            )));
        }
        if let Some(i) = e.iter().position(|x| !x.is_finite()) {
            return Err(LgiError::Input(format!(
                "jaw bin edge {i} must be finite, got {}",
                e[i]
            )));
        }
        if let Some(i) = (1..e.len()).find(|&i| e[i] <= e[i - 1]) {
            return Err(LgiError::Input(format!(
                "jaw bin edges must be strictly increasing: edge {i} ({}) <= edge {} ({})",
                e[i],
                i - 1,
                e[i - 1]
            )));
        }
        if !(self.overlap.is_finite() && self.overlap >= 0.0) {
            return Err(LgiError::Input(format!(
                "jaw bin overlap must be finite and >= 0, got {}",
                self.overlap
            )));
        }
        for b in 0..self.num_bins() {
            self.reference(b).validate()?;
        }
        Ok(())
    }

    /// Number of bins K.
    pub fn num_bins(&self) -> usize {
        self.edges.len().saturating_sub(1)
    }

    /// Bin b's core range `[edges[b], edges[b + 1]]`.
    pub fn core_range(&self, b: usize) -> (f64, f64) {
        (self.edges[b], self.edges[b + 1])
    }

    /// Bin b's member range: the core range widened by the overlap.
    pub fn member_range(&self, b: usize) -> (f64, f64) {
        let (lo, hi) = self.core_range(b);
        (lo - self.overlap, hi + self.overlap)
    }

    /// Bin b's reference pose: the core range's midpoint opening, no lateral or forward motion.
    pub fn reference(&self, b: usize) -> JawParams {
        let (lo, hi) = self.core_range(b);
        JawParams {
            open: 0.5 * (lo + hi),
            ..JawParams::ZERO
        }
    }

    /// Dataset shape indices (0-based, ascending) whose opening lies in bin b's member range.
    pub fn members(&self, b: usize, shape_thetas: &[JawParams]) -> Vec<u32> {
        let (lo, hi) = self.member_range(b);
        (0..shape_thetas.len() as u32)
            .filter(|&k| (lo..=hi).contains(&shape_thetas[k as usize].open))
            .collect()
    }

    /// The bin a frame with opening `open` uses: the previous frame's bin while `open` stays
    /// in its member range (hysteresis, so a frame near an edge does not flip between bins),
    /// otherwise the bin whose core range holds `open` (clamped to the first and last bins).
    pub fn select(&self, open: f64, previous: Option<usize>) -> usize {
        let k = self.num_bins();
        if let Some(p) = previous.filter(|&p| p < k) {
            let (lo, hi) = self.member_range(p);
            if (lo..=hi).contains(&open) {
                return p;
            }
        }
        self.edges
            .partition_point(|&e| e <= open)
            .saturating_sub(1)
            .min(k.saturating_sub(1))
    }
}

fn apply_weighted(
    rig: &JawRig,
    positions: &[DVec3],
    weights: &[f64],
    theta: JawParams,
    out: &mut [DVec3],
    f: fn(&Blend, DVec3, f64) -> DVec3,
) -> Result<()> {
    theta.validate()?;
    if positions.len() != weights.len() || out.len() != weights.len() {
        return Err(LgiError::Input(format!(
            "jaw skinning needs one weight per point: {} points, {} weights, {} outputs",
            positions.len(),
            weights.len(),
            out.len()
        )));
    }
    let blend = rig.blend(theta);
    out.par_iter_mut()
        .zip(positions.par_iter().zip(weights.par_iter()))
        .for_each(|(o, (&p, &w))| *o = f(&blend, p, w));
    Ok(())
}

#[cfg(test)]
mod tests;
