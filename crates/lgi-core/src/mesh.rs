//! Triangle mesh with per-corner UVs: the neutral face and its topology. Quads and n-gons are
//! split into triangles by the readers; UV seams are kept (a vertex may have several UVs).
//! A [`SurfacePoint`] (triangle + barycentric) names a point on it, and on every shape with
//! its topology: bundles, sewing and hole-detour distances all address the surface that way.

use crate::error::{LgiError, Result};
use crate::geom::interpolate3;
use glam::{DVec2, DVec3};

/// A triangle mesh. `uv_triangles[t]` indexes `uvs` for the corners of `triangles[t]`
/// (empty when the mesh has no UVs).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions (V).
    pub positions: Vec<DVec3>,
    /// Triangles as vertex indices (T).
    pub triangles: Vec<[u32; 3]>,
    /// UV coordinates (U); shared by corners through `uv_triangles`.
    pub uvs: Vec<DVec2>,
    /// Per-triangle UV indices (T, or empty when the mesh has no UVs).
    pub uv_triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// Checks the invariants: finite positions and UVs, indices in range, one UV triangle per
    /// triangle (or none), no triangle repeating a vertex. `what` names the mesh in messages.
    pub fn validate(&self, what: &str) -> Result<()> {
        if self.positions.is_empty() {
            return Err(LgiError::Dataset(format!("{what}: mesh has no vertices")));
        }
        if let Some(v) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(LgiError::Dataset(format!(
                "{what}: vertex {v} has a non-finite coordinate {}",
                crate::text::point(self.positions[v])
            )));
        }
        if self.triangles.is_empty() {
            return Err(LgiError::Dataset(format!("{what}: mesh has no faces")));
        }
        let nv = self.positions.len() as u32;
        for (t, tri) in self.triangles.iter().enumerate() {
            if let Some(&i) = tri.iter().find(|&&i| i >= nv) {
                return Err(LgiError::Dataset(format!(
                    "{what}: triangle {t} refers to vertex {i} but the mesh has {nv} vertices"
                )));
            }
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                return Err(LgiError::Dataset(format!(
                    "{what}: triangle {t} repeats a vertex {tri:?}"
                )));
            }
        }
        if !self.uv_triangles.is_empty() {
            if self.uv_triangles.len() != self.triangles.len() {
                return Err(LgiError::Dataset(format!(
                    "{what}: {} UV triangles for {} triangles",
                    self.uv_triangles.len(),
                    self.triangles.len()
                )));
            }
            let nu = self.uvs.len() as u32;
            for (t, tri) in self.uv_triangles.iter().enumerate() {
                if let Some(&i) = tri.iter().find(|&&i| i >= nu) {
                    return Err(LgiError::Dataset(format!(
                        "{what}: triangle {t} refers to UV {i} but the mesh has {nu} UVs"
                    )));
                }
            }
            if let Some(u) = self.uvs.iter().position(|p| !p.is_finite()) {
                return Err(LgiError::Dataset(format!(
                    "{what}: UV {u} is not finite {}",
                    crate::text::uv(self.uvs[u])
                )));
            }
        }
        Ok(())
    }

    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.positions.len()
    }

    /// Whether the mesh carries UVs.
    pub fn has_uvs(&self) -> bool {
        !self.uv_triangles.is_empty()
    }

    /// Axis-aligned bounding box (min, max) of the vertices.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        self.positions.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        )
    }

    /// Length of the bounding-box diagonal: the face size every tolerance is relative to.
    pub fn diagonal(&self) -> f64 {
        let (lo, hi) = self.bounds();
        (hi - lo).length()
    }

    /// Corner positions of triangle `t`.
    pub fn triangle(&self, t: usize) -> [DVec3; 3] {
        let [a, b, c] = self.triangles[t];
        [
            self.positions[a as usize],
            self.positions[b as usize],
            self.positions[c as usize],
        ]
    }
}

/// A point on the surface: triangle index + barycentric (u,v,w) of its corners.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfacePoint {
    /// Index of the triangle in the mesh's `triangles`.
    pub triangle: u32,
    /// Barycentric coordinates of the triangle's corners (sum 1, all `>= 0`).
    pub bary: [f64; 3],
}

impl SurfacePoint {
    /// The point on `mesh` (barycentric interpolation of the triangle's corners).
    /// Out-of-range indices give a NaN vector rather than a panic.
    pub fn position(&self, mesh: &Mesh) -> DVec3 {
        self.evaluate(&mesh.triangles, &mesh.positions)
    }

    /// The point on any mesh with the same topology (`triangles`) and vertex `positions`, e.g. a
    /// dataset shape. Out-of-range triangle or vertex indices give a NaN vector rather than a
    /// panic, since a `SurfacePoint` can be built by hand against another mesh.
    pub fn evaluate(&self, triangles: &[[u32; 3]], positions: &[DVec3]) -> DVec3 {
        let Some(tri) = triangles.get(self.triangle as usize) else {
            return DVec3::NAN;
        };
        let mut corners = [DVec3::ZERO; 3];
        for (c, &i) in corners.iter_mut().zip(tri) {
            match positions.get(i as usize) {
                Some(p) => *c = *p,
                None => return DVec3::NAN,
            }
        }
        interpolate3(corners, self.bary)
    }
}
