//! The neutral's source polygons (quads, n-gons) as read from its file: the core works on
//! their fan triangulation, exports (USD, OBJ sequences) give the artist's faces back. Kept
//! beside the triangle mesh and checked to fan-split into exactly its triangles.

use crate::error::{LgiError, Result};
use crate::mesh::Mesh;

/// Polygon faces: `counts[f]` corners each, their vertex indices in `vertices` (face after
/// face) and, when the mesh has UVs, their UV indices in `uvs` (same layout; else empty).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Polygons {
    /// Corners per face (each >= 3).
    pub counts: Vec<u32>,
    /// Vertex index of every corner, face after face.
    pub vertices: Vec<u32>,
    /// UV index of every corner (empty when the mesh has no UVs).
    pub uvs: Vec<u32>,
}

impl Polygons {
    /// Number of faces.
    pub fn num_faces(&self) -> usize {
        self.counts.len()
    }

    /// Appends one face; fan-split by [`Polygons::fan`] in the same corner order.
    pub fn push(&mut self, vertices: &[u32], uvs: Option<&[u32]>) {
        self.counts.push(vertices.len() as u32);
        self.vertices.extend_from_slice(vertices);
        if let Some(u) = uvs {
            self.uvs.extend_from_slice(u);
        }
    }

    /// The fan triangulation (corner 0 with each later edge) of `corners` from `flat`: the
    /// one rule the OBJ reader triangulates with.
    fn fan(&self, flat: &[u32]) -> Vec<[u32; 3]> {
        let mut out = Vec::with_capacity(flat.len());
        let mut at = 0usize;
        for &n in &self.counts {
            let face = &flat[at..at + n as usize];
            for w in face[1..].windows(2) {
                out.push([face[0], w[0], w[1]]);
            }
            at += n as usize;
        }
        out
    }

    /// Checks the faces are well formed and fan-split into exactly `mesh`'s triangles (and UV
    /// triangles), so both views describe the same surface. `what` names the mesh in errors.
    pub fn check_against(&self, mesh: &Mesh, what: &str) -> Result<()> {
        let bad = |m: String| LgiError::Dataset(format!("{what}: polygons: {m}"));
        if let Some(f) = self.counts.iter().position(|&n| n < 3) {
            return Err(bad(format!("face {f} has {} corners", self.counts[f])));
        }
        let corners: u64 = self.counts.iter().map(|&n| u64::from(n)).sum();
        if corners != self.vertices.len() as u64 {
            return Err(bad(format!(
                "{} vertex indices for {corners} corners",
                self.vertices.len()
            )));
        }
        let with_uvs = mesh.has_uvs();
        let uv_len = if with_uvs { corners } else { 0 };
        if self.uvs.len() as u64 != uv_len {
            return Err(bad(format!(
                "{} UV indices for {uv_len} UV corners",
                self.uvs.len()
            )));
        }
        let tris = corners - 2 * self.counts.len() as u64;
        if tris != mesh.triangles.len() as u64 {
            return Err(bad(format!(
                "{} faces make {tris} triangles, the mesh has {}",
                self.counts.len(),
                mesh.triangles.len()
            )));
        }
        if self.fan(&self.vertices) != mesh.triangles {
            return Err(bad(
                "faces do not fan-split into the mesh's triangles".into()
            ));
        }
        if with_uvs && self.fan(&self.uvs) != mesh.uv_triangles {
            return Err(bad(
                "faces' UVs do not fan-split into the mesh's UV triangles".into(),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec2, DVec3};

    fn quad_and_triangle() -> (Mesh, Polygons) {
        let mut p = Polygons::default();
        p.push(&[0, 1, 2, 3], Some(&[0, 1, 2, 3]));
        p.push(&[1, 4, 2], Some(&[1, 4, 2]));
        let mesh = Mesh {
            positions: vec![DVec3::ZERO; 5],
            triangles: vec![[0, 1, 2], [0, 2, 3], [1, 4, 2]],
            uvs: vec![DVec2::ZERO; 5],
            uv_triangles: vec![[0, 1, 2], [0, 2, 3], [1, 4, 2]],
        };
        (mesh, p)
    }

    #[test]
    fn polygons_that_fan_split_into_the_triangles_pass() {
        let (mesh, p) = quad_and_triangle();
        p.check_against(&mesh, "m").unwrap();
        assert_eq!(p.num_faces(), 2);
    }

    #[test]
    fn polygons_of_another_triangulation_or_count_are_refused() {
        let (mut mesh, p) = quad_and_triangle();
        mesh.triangles[1] = [0, 3, 2];
        assert!(p.check_against(&mesh, "m").is_err());
        let (mesh, mut p) = quad_and_triangle();
        p.counts[1] = 2;
        let e = p.check_against(&mesh, "m").unwrap_err().to_string();
        assert!(e.contains("face 1 has 2 corners"), "{e}");
        let (mesh, mut p) = quad_and_triangle();
        p.uvs.pop();
        assert!(p.check_against(&mesh, "m").is_err());
    }
}
