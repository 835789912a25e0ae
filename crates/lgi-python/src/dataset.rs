//! `lgi.Dataset`: the neutral mesh and its shapes, loaded by the core's readers.

use crate::convert::{flat_to_array, points_to_array};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use std::sync::Arc;

/// Neutral mesh plus S shapes (displacements). Immutable; cheap to share.
#[pyclass(frozen, module = "lgi._lgi")]
pub struct Dataset {
    pub inner: Arc<lgi_core::Dataset>,
}

#[pymethods]
impl Dataset {
    /// Number of vertices V.
    #[getter]
    fn num_vertices(&self) -> usize {
        self.inner.num_vertices()
    }

    /// Number of shapes S (the neutral is not counted).
    #[getter]
    fn num_shapes(&self) -> usize {
        self.inner.num_shapes()
    }

    /// Shape names.
    #[getter]
    fn names(&self) -> Vec<String> {
        self.inner.names().to_vec()
    }

    /// Neutral positions, (V, 3) float64.
    #[getter]
    fn neutral<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        points_to_array(py, &self.inner.neutral().positions)
    }

    /// Shape displacements, (S, V, 3) float32.
    #[getter]
    fn shapes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let d = &self.inner;
        flat_to_array(py, d.displacements().to_vec(), &[d.num_shapes(), d.num_vertices(), 3])
    }

    /// Triangles, (T, 3) int64.
    #[getter]
    fn triangles<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<i64>>> {
        let t = &self.inner.neutral().triangles;
        let flat: Vec<i64> = t.iter().flat_map(|f| f.map(i64::from)).collect();
        flat_to_array(py, flat, &[t.len(), 3])
    }

    /// UV coordinates, (U, 2) float64.
    #[getter]
    fn uvs<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let u = &self.inner.neutral().uvs;
        let flat: Vec<f64> = u.iter().flat_map(|p| [p.x, p.y]).collect();
        flat_to_array(py, flat, &[u.len(), 2])
    }

    /// Per-triangle UV indices, (T, 3) int64 (empty when the mesh has no UVs).
    #[getter]
    fn uv_triangles<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<i64>>> {
        let t = &self.inner.neutral().uv_triangles;
        let flat: Vec<i64> = t.iter().flat_map(|f| f.map(i64::from)).collect();
        flat_to_array(py, flat, &[t.len(), 3])
    }

    fn __repr__(&self) -> String {
        format!(
            "Dataset(num_vertices={}, num_shapes={}, num_triangles={})",
            self.inner.num_vertices(),
            self.inner.num_shapes(),
            self.inner.neutral().triangles.len()
        )
    }
}
