//! Dataset: the neutral mesh `x0` and S expression shapes stored as per-vertex displacements
//! `s_k = x_k - x0` (f32 storage, f64 math). A `Dataset` cannot exist with mismatched shapes.

use crate::error::{LgiError, Result};
use crate::mesh::Mesh;
use crate::polygons::Polygons;
use glam::DVec3;

/// Neutral mesh plus shapes as displacements. Construct with [`Dataset::new`] or
/// [`Dataset::from_shape_positions`]; both validate. Reading files is `io`'s job:
/// [`Dataset::from_obj_files`] (in `io/obj.rs`) and `read_gltf` (`io/gltf.rs`) build on these.
#[derive(Debug, Clone)]
pub struct Dataset {
    neutral: Mesh,
    /// S * V * 3 displacements, shape-major.
    displacements: Vec<f32>,
    names: Vec<String>,
    /// The neutral's source polygons when its file had them (OBJ); exports use them.
    polygons: Option<Polygons>,
}

impl Dataset {
    /// A dataset from a neutral mesh and flat displacements (`S * V * 3`, shape-major).
    pub fn new(neutral: Mesh, displacements: Vec<f32>, names: Vec<String>) -> Result<Self> {
        neutral.validate("neutral")?;
        let v = neutral.num_vertices();
        let s = names.len();
        if displacements.len() != s * v * 3 {
            return Err(LgiError::Dataset(format!(
                "{} displacement values for {s} shapes of {v} vertices (expected {})",
                displacements.len(),
                s * v * 3
            )));
        }
        if let Some(i) = displacements.iter().position(|x| !x.is_finite()) {
            let k = i / (v * 3);
            return Err(LgiError::Dataset(format!(
                "shape {k} ('{}'), vertex {}: non-finite displacement",
                names[k],
                (i / 3) % v
            )));
        }
        crate::magnitude::check_dataset(
            &neutral.positions,
            &displacements,
            &names,
            neutral.diagonal(),
        )?;
        let mut seen = std::collections::HashSet::new();
        for (k, n) in names.iter().enumerate() {
            if !seen.insert(n.as_str()) {
                return Err(LgiError::Dataset(format!(
                    "shape {k}: duplicate shape name '{n}'"
                )));
            }
        }
        Ok(Dataset {
            neutral,
            displacements,
            names,
            polygons: None,
        })
    }

    /// The same dataset with the neutral's source polygons attached (checked to fan-split
    /// into its triangles, [`Polygons::check_against`]).
    pub fn with_polygons(mut self, polygons: Polygons) -> Result<Self> {
        polygons.check_against(&self.neutral, "neutral")?;
        self.polygons = Some(polygons);
        Ok(self)
    }

    /// The neutral's source polygons (quads, n-gons), when known.
    pub fn polygons(&self) -> Option<&Polygons> {
        self.polygons.as_ref()
    }

    /// A dataset from full shape meshes (positions with the neutral's topology); each
    /// `(name, positions)` becomes the displacement `positions - x0`.
    pub fn from_shape_positions(neutral: Mesh, shapes: Vec<(String, Vec<DVec3>)>) -> Result<Self> {
        let v = neutral.num_vertices();
        let mut displacements = Vec::with_capacity(shapes.len() * v * 3);
        let mut names = Vec::with_capacity(shapes.len());
        for (k, (name, pos)) in shapes.into_iter().enumerate() {
            if pos.len() != v {
                return Err(LgiError::Dataset(format!(
                    "shape {k} ('{name}') has {} vertices, the neutral has {v}",
                    pos.len()
                )));
            }
            for (p, x0) in pos.iter().zip(&neutral.positions) {
                let d = *p - *x0;
                displacements.extend_from_slice(&[d.x as f32, d.y as f32, d.z as f32]);
            }
            names.push(name);
        }
        Dataset::new(neutral, displacements, names)
    }

    /// The neutral mesh.
    pub fn neutral(&self) -> &Mesh {
        &self.neutral
    }

    /// Number of vertices V.
    pub fn num_vertices(&self) -> usize {
        self.neutral.num_vertices()
    }

    /// Number of shapes S (the neutral is not counted).
    pub fn num_shapes(&self) -> usize {
        self.names.len()
    }

    /// Shape names, in order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// All displacements, `S * V * 3`, shape-major.
    pub fn displacements(&self) -> &[f32] {
        &self.displacements
    }

    /// Displacements of shape `k` (`V * 3`).
    pub fn shape(&self, k: usize) -> &[f32] {
        let n = self.num_vertices() * 3;
        &self.displacements[k * n..(k + 1) * n]
    }

    /// Displacement of vertex `v` in shape `k`, as f64.
    pub fn displacement(&self, k: usize, v: usize) -> DVec3 {
        let s = self.shape(k);
        DVec3::new(s[3 * v] as f64, s[3 * v + 1] as f64, s[3 * v + 2] as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec2;

    fn tri_mesh() -> Mesh {
        Mesh {
            positions: vec![DVec3::ZERO, DVec3::X, DVec3::Y],
            triangles: vec![[0, 1, 2]],
            uvs: vec![DVec2::ZERO, DVec2::X, DVec2::Y],
            uv_triangles: vec![[0, 1, 2]],
        }
    }

    #[test]
    fn shape_positions_become_displacements() {
        let m = tri_mesh();
        let shape: Vec<DVec3> = m.positions.iter().map(|p| *p + DVec3::Z).collect();
        let d = Dataset::from_shape_positions(m, vec![("up".into(), shape)]).unwrap();
        assert_eq!(d.num_shapes(), 1);
        assert_eq!(d.displacement(0, 2), DVec3::Z);
    }

    #[test]
    fn mismatched_vertex_count_is_rejected_naming_the_shape() {
        let err =
            Dataset::from_shape_positions(tri_mesh(), vec![("bad".into(), vec![DVec3::ZERO])])
                .unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("'bad'") && msg.contains("1 vertices"), "{msg}");
    }

    #[test]
    fn nan_displacement_is_rejected_naming_shape_and_vertex() {
        let mut disp = vec![0.0f32; 9];
        disp[7] = f32::NAN;
        let err = Dataset::new(tri_mesh(), disp, vec!["s".into()]).unwrap_err();
        assert!(err.to_string().contains("vertex 2"), "{err}");
    }
}
