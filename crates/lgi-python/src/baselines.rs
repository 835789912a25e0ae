//! `lgi._lgi.RbfInterpolator` and `lgi._lgi.BlendshapeSolver`: the numerical kernels of the
//! baselines (python/lgi/baselines.py wraps them with the `lgi.Model` solve API), and the
//! marker-frame check they share with `Model.solve`.

use crate::convert::{flat_to_array, float_array, points as read_points};
use crate::dataset::Dataset;
use crate::error::{input_error, PyLgiError};
use crate::threads;
use glam::DVec3;
use lgi_core::{BlendshapeSolver as CoreBlend, RbfInterpolator as CoreRbf};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use rayon::prelude::*;

/// Fitted weights (F, S) and iteration counts (F,).
type WeightsAndIterations<'py> = (Bound<'py, PyArrayDyn<f64>>, Bound<'py, PyArrayDyn<i64>>);

/// Biharmonic RBF interpolation of marker values over mesh vertices (exact at the markers).
#[pyclass(frozen, module = "lgi._lgi")]
pub struct RbfInterpolator {
    pub(crate) inner: CoreRbf,
}

/// Active-set solver of the box-penalised blendshape least squares.
#[pyclass(frozen, module = "lgi._lgi")]
pub struct BlendshapeSolver {
    inner: CoreBlend,
}

#[pymethods]
impl RbfInterpolator {
    /// Constraints: marker i's value is Σ_j sample_weights[i, j] f(points[sample_vertices[i, j]]).
    #[new]
    fn new(
        py: Python<'_>,
        points: &Bound<'_, PyAny>,
        sample_vertices: &Bound<'_, PyAny>,
        sample_weights: &Bound<'_, PyAny>,
    ) -> PyResult<Self> {
        let pts = read_points(points, "points", None, false)?;
        let idx = crate::convert::index_array(sample_vertices, "sample_vertices", 3)?;
        let b = idx.len() / 3;
        let w = float_array(sample_weights, "sample_weights", &[Some(b), Some(3)])?;
        let samples: Vec<([u32; 3], [f64; 3])> = (0..b)
            .map(|i| {
                (
                    [idx[3 * i], idx[3 * i + 1], idx[3 * i + 2]],
                    [w[[i, 0]], w[[i, 1]], w[[i, 2]]],
                )
            })
            .collect();
        let inner = threads::detach(py, move || CoreRbf::new(pts, samples)).map_err(PyLgiError)?;
        Ok(RbfInterpolator { inner })
    }

    /// Markers on the dataset's neutral (closest point within `tolerance`, data units).
    #[staticmethod]
    fn from_dataset(
        py: Python<'_>,
        dataset: &Dataset,
        markers_rest: &Bound<'_, PyAny>,
        tolerance: f64,
    ) -> PyResult<Self> {
        let markers = read_points(markers_rest, "markers_rest", None, false)?;
        let data = dataset.inner.clone();
        let inner = threads::detach(py, move || {
            CoreRbf::from_dataset(&data, &markers, tolerance)
        })
        .map_err(PyLgiError)?;
        Ok(RbfInterpolator { inner })
    }

    /// Number of markers B.
    #[getter]
    fn num_markers(&self) -> usize {
        self.inner.num_markers()
    }

    /// Number of points V.
    #[getter]
    fn num_points(&self) -> usize {
        self.inner.num_points()
    }

    /// (V, B) interpolation matrix (all markers present).
    #[getter]
    fn matrix<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let (v, b) = (self.inner.num_points(), self.inner.num_markers());
        flat_to_array(py, self.inner.matrix().to_vec(), &[v, b])
    }

    /// (B, 3) vertex indices of each marker's constraint.
    #[getter]
    fn sample_vertices<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<i64>>> {
        let s = self.inner.samples();
        let flat = s.iter().flat_map(|(v, _)| v.map(|x| x as i64)).collect();
        flat_to_array(py, flat, &[s.len(), 3])
    }

    /// (B, 3) barycentric weights of each marker's constraint.
    #[getter]
    fn sample_weights<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let s = self.inner.samples();
        let flat = s.iter().flat_map(|(_, w)| *w).collect();
        flat_to_array(py, flat, &[s.len(), 3])
    }

    /// (B, 3) RBF centres (the markers' surface points).
    #[getter]
    fn centres<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        crate::convert::points_to_array(py, self.inner.centres())
    }

    /// Interpolates values (F, B, 3) (NaN rows: missing markers) to (F, V, 3) (GIL released).
    fn interpolate<'py>(
        &self,
        py: Python<'py>,
        values: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let b = self.inner.num_markers();
        let a = float_array(values, "values", &[None, Some(b), Some(3)])?;
        let frames: Vec<Vec<DVec3>> = a
            .outer_iter()
            .map(|f| {
                f.outer_iter()
                    .map(|r| DVec3::new(r[0], r[1], r[2]))
                    .collect()
            })
            .collect();
        let nf = frames.len();
        let inner = &self.inner;
        // Frames in parallel: a frame with its own missing markers factors its own system
        // (the left-out rows of a reading: one each), which is one thread's work.
        let out = threads::detach(py, || {
            frames
                .par_iter()
                .map(|f| inner.interpolate(f))
                .collect::<lgi_core::Result<Vec<_>>>()
        })
        .map_err(PyLgiError)?;
        let flat: Vec<f64> = out.iter().flatten().flat_map(|p| [p.x, p.y, p.z]).collect();
        flat_to_array(py, flat, &[nf, inner.num_points(), 3])
    }
}

#[pymethods]
impl BlendshapeSolver {
    /// `a` (R, S); `l2` and `penalty` absolute and non-negative.
    #[new]
    fn new(a: &Bound<'_, PyAny>, l2: f64, penalty: f64) -> PyResult<Self> {
        let m = float_array(a, "a", &[None, None])?;
        let (r, s) = (m.shape()[0], m.shape()[1]);
        let flat: Vec<f64> = m.iter().copied().collect();
        let inner = CoreBlend::new(flat, r, s, l2, penalty).map_err(PyLgiError)?;
        Ok(BlendshapeSolver { inner })
    }

    /// Number of shapes S.
    #[getter]
    fn num_shapes(&self) -> usize {
        self.inner.num_shapes()
    }

    /// Number of rows R.
    #[getter]
    fn num_rows(&self) -> usize {
        self.inner.num_rows()
    }

    /// Objective at weights `w` (S,) for `target` (R,) (NaN entries dropped).
    fn objective(&self, w: &Bound<'_, PyAny>, target: &Bound<'_, PyAny>) -> PyResult<f64> {
        let s = self.inner.num_shapes();
        let w = float_array(w, "w", &[Some(s)])?;
        let t = float_array(target, "target", &[Some(self.inner.num_rows())])?;
        let w: Vec<f64> = w.iter().copied().collect();
        let t: Vec<f64> = t.iter().copied().collect();
        Ok(self.inner.objective(&w, &t))
    }

    /// Solves targets (F, R) (NaN entries: dropped rows) in parallel; returns weights (F, S)
    /// and iteration counts (F,).
    fn solve<'py>(
        &self,
        py: Python<'py>,
        targets: &Bound<'py, PyAny>,
    ) -> PyResult<WeightsAndIterations<'py>> {
        let r = self.inner.num_rows();
        let a = float_array(targets, "targets", &[None, Some(r)])?;
        let rows: Vec<Vec<f64>> = a
            .outer_iter()
            .map(|x| x.iter().copied().collect())
            .collect();
        let nf = rows.len();
        let inner = &self.inner;
        let sols = threads::detach(py, || inner.solve_many(&rows)).map_err(PyLgiError)?;
        let s = inner.num_shapes();
        let w: Vec<f64> = sols
            .iter()
            .flat_map(|x| x.weights.iter().copied())
            .collect();
        let it: Vec<i64> = sols.iter().map(|x| x.iterations as i64).collect();
        if w.len() != nf * s {
            return Err(input_error("internal: weight count mismatch".to_string()));
        }
        Ok((
            flat_to_array(py, w, &[nf, s])?,
            flat_to_array(py, it, &[nf])?,
        ))
    }
}

/// Checks marker frames (F, B, 3) against the magnitude policy of every method
/// ([`lgi_core::Extent`]): the error names frame and marker.
#[pyfunction]
pub fn check_marker_frames(
    frames: &Bound<'_, PyAny>,
    markers_rest: &Bound<'_, PyAny>,
    diagonal: f64,
) -> PyResult<()> {
    let rest = read_points(markers_rest, "markers_rest", None, false)?;
    let frames = crate::convert::point_sets(
        frames,
        "frames",
        ("frame", "marker"),
        Some(rest.len()),
        true,
    )?;
    lgi_core::Extent::new(&rest, diagonal)
        .check_frames(&frames, lgi_core::Naming::default())
        .map_err(|e| PyLgiError(e).into())
}
