//! `lgi._lgi.closest_surface_points`: the core's exact closest-point query
//! ([`lgi_core::SurfaceIndex`], a BVH answering as brute force does) on any triangle mesh, for
//! callers that need it on part of a mesh (e.g. a marker layout put on the face only).

use crate::convert::{flat_to_array, index_array, points as read_points};
use crate::error::PyLgiError;
use crate::threads;
use lgi_core::{Mesh, SurfaceIndex};
use numpy::PyArrayDyn;
use pyo3::prelude::*;

/// Each point's triangle (P,) and barycentric coordinates (P, 3).
type Closest<'py> = (Bound<'py, PyArrayDyn<i64>>, Bound<'py, PyArrayDyn<f64>>);

/// Each of `points` (P, 3)'s closest point on the mesh `vertices` (V, 3), `triangles` (T, 3):
/// the row of `triangles` it lies on (the lowest on a tie) and its barycentric coordinates
/// (GIL released).
#[pyfunction]
pub fn closest_surface_points<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    triangles: &Bound<'py, PyAny>,
    points: &Bound<'py, PyAny>,
) -> PyResult<Closest<'py>> {
    let positions = read_points(vertices, "vertices", None, false)?;
    let idx = index_array(triangles, "triangles", 3)?;
    let query = read_points(points, "points", None, false)?;
    let mesh = Mesh {
        positions,
        triangles: idx.chunks(3).map(|t| [t[0], t[1], t[2]]).collect(),
        uvs: Vec::new(),
        uv_triangles: Vec::new(),
    };
    let found = threads::detach(py, move || {
        SurfaceIndex::new(&mesh).map(|index| index.closest_many(&query))
    })
    .map_err(PyLgiError)?;
    let tri = found.iter().map(|(s, _)| i64::from(s.triangle)).collect();
    let bary = found.iter().flat_map(|(s, _)| s.bary).collect();
    Ok((
        flat_to_array(py, tri, &[found.len()])?,
        flat_to_array(py, bary, &[found.len(), 3])?,
    ))
}
