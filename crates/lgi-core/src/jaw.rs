//! Jaw skinning (the paper's Eq. 2): two-bone linear blend skinning with the skull fixed and the
//! jaw a rigid motion about a pivot. Dataset shapes and captured bundles are unskinned before
//! indexing so the index sees no jaw rotation, and the result is reskinned afterwards.
//!
//! The one implementation of the skinning: Python skins through it (`lgi._lgi.JawRig`, used by
//! `lgi.jaw` and the sample generator). θ = (open, lateral, forward) maps `p` to
//! `F R Fᵀ (p − pivot) + pivot + F t` with `R = R_y(lateral) · R_x(open)`, `t = (0, 0, forward)`
//! and `F` the rig's frame (columns: open axis, lateral axis, forward direction; identity in
//! the sample).

use glam::{DAffine3, DMat3, DVec3};
use rayon::prelude::*;

use crate::error::{LgiError, Result};

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
                "jaw parameters must be finite with |open|, |lateral| < pi, got {self:?}"
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
            "jaw frame must be finite, got {frame:?}"
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
                "jaw pivot must be finite, got {pivot:?}"
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
mod tests {
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
            JawRig::with_frame(DVec3::new(0.0, -1.5, 3.0), weights.clone(), DMat3::IDENTITY)
                .unwrap();
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
    fn point_round_trips(
        r: &JawRig,
        p: DVec3,
        w: f64,
        theta: JawParams,
    ) -> Result<f64, TestCaseError> {
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
}
