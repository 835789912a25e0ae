//! `lgi._lgi.LocalFits`: each bundle's blendshape fit of the markers around it
//! (`lgi_core::LocalFits`); python/lgi/local.py blends the pieces over the mesh.

use crate::convert::{flat_to_array, float_array, points as read_points};
use crate::error::PyLgiError;
use crate::threads;
use lgi_core::LocalFits as CoreLocal;
use numpy::{
    PyArrayDyn, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

/// Local fits of one marker layout (immutable; the fits run in parallel).
#[pyclass(frozen, module = "lgi._lgi")]
pub struct LocalFits {
    inner: CoreLocal,
}

#[pymethods]
impl LocalFits {
    /// `a` (3B, S): the shapes' displacements at the markers (marker b's x, y, z in rows
    /// 3b..3b+3); `rest` (B, 3); `l2` and `penalty` relative to each window's mean squared
    /// column norm; `lengths`: the windows' Gaussian length in median marker spacings
    /// (`LOCAL_LENGTH`).
    #[new]
    #[pyo3(signature = (a, rest, l2, penalty, lengths = lgi_core::LOCAL_LENGTH))]
    fn new(
        py: Python<'_>,
        a: &Bound<'_, PyAny>,
        rest: &Bound<'_, PyAny>,
        l2: f64,
        penalty: f64,
        lengths: f64,
    ) -> PyResult<Self> {
        let rest = read_points(rest, "rest", None, false)?;
        let m = float_array(a, "a", &[Some(3 * rest.len()), None])?;
        let s = m.shape()[1];
        let flat: Vec<f64> = m.iter().copied().collect();
        let inner = threads::detach(py, || {
            CoreLocal::with_length(&flat, s, &rest, l2, penalty, lengths)
        })
        .map_err(PyLgiError)?;
        Ok(LocalFits { inner })
    }

    /// Number of bundles B.
    #[getter]
    fn num_bundles(&self) -> usize {
        self.inner.num_bundles()
    }

    /// Number of shapes S.
    #[getter]
    fn num_shapes(&self) -> usize {
        self.inner.num_shapes()
    }

    /// How many markers each bundle's window holds (B,).
    #[getter]
    fn window_sizes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<i64>>> {
        let sizes: Vec<i64> = self
            .inner
            .window_sizes()
            .iter()
            .map(|&n| n as i64)
            .collect();
        let n = sizes.len();
        flat_to_array(py, sizes, &[n])
    }

    /// `targets` (F, B, 3) displacements from rest (NaN rows: missing markers) and `starts`
    /// (F, S) -> weights (F, B, S) and how many fits kept their start (no marker of the
    /// window present, or no convergence).
    fn solve<'py>(
        &self,
        py: Python<'py>,
        targets: &Bound<'py, PyAny>,
        starts: &Bound<'py, PyAny>,
    ) -> PyResult<(Bound<'py, PyArrayDyn<f64>>, usize)> {
        let (b, s) = (self.inner.num_bundles(), self.inner.num_shapes());
        let t = float_array(targets, "targets", &[None, Some(b), Some(3)])?;
        let f = t.shape()[0];
        let st = float_array(starts, "starts", &[Some(f), Some(s)])?;
        let t: Vec<f64> = t.iter().copied().collect();
        let st: Vec<f64> = st.iter().copied().collect();
        let inner = &self.inner;
        let got = threads::detach(py, || inner.solve(&t, &st)).map_err(PyLgiError)?;
        Ok((flat_to_array(py, got.weights, &[f, b, s])?, got.kept_start))
    }
}

/// A shape basis: the basis shapes' indices (q,) and every shape's coefficients (S, q).
type Basis<'py> = (Bound<'py, PyArrayDyn<i64>>, Bound<'py, PyArrayDyn<f64>>);

/// `shapes` (S, N) float32, C-contiguous: None when no shape is a combination of the others,
/// else the basis shapes' indices (q,) and every shape's coefficients over them (S, q)
/// (`lgi_core::ShapeBasis`: a shape counts as a combination to a relative rms of 1e-6).
#[pyfunction]
pub fn shape_basis<'py>(
    py: Python<'py>,
    shapes: PyReadonlyArray2<'py, f32>,
) -> PyResult<Option<Basis<'py>>> {
    let s = shapes.shape()[0];
    let not_c =
        || pyo3::exceptions::PyValueError::new_err("shape_basis: shapes must be C-contiguous");
    // `as_slice` takes Fortran order too, whose slice is not shape-major.
    if !shapes.is_c_contiguous() {
        return Err(not_c());
    }
    let flat = shapes.as_slice().map_err(|_| not_c())?;
    let Some(basis) = threads::detach(py, || lgi_core::ShapeBasis::find(flat, s)) else {
        return Ok(None);
    };
    let q = basis.shapes.len();
    let pivots: Vec<i64> = basis.shapes.iter().map(|&k| k as i64).collect();
    Ok(Some((
        flat_to_array(py, pivots, &[q])?,
        flat_to_array(py, basis.coefficients().to_vec(), &[s, q])?,
    )))
}

/// The local fits' blend over the mesh, frame by frame (`lgi_core::blend_local`): `neutral`
/// (V, 3), `shapes` (V, 3, q) float32 C-contiguous (read in place), the sewing weights as CSR
/// rows (`indptr` (V+1,), `indices`, `data`; int64, int64, float64) and `weights` (F, B, q)
/// -> (F, V, 3).
#[pyfunction]
pub fn blend_local<'py>(
    py: Python<'py>,
    neutral: &Bound<'py, PyAny>,
    shapes: PyReadonlyArray3<'py, f32>,
    indptr: PyReadonlyArray1<'py, i64>,
    indices: PyReadonlyArray1<'py, i64>,
    data: PyReadonlyArray1<'py, f64>,
    weights: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let x0 = read_points(neutral, "neutral", None, false)?;
    let v = x0.len();
    let q = shapes.shape()[2];
    if shapes.shape()[..2] != [v, 3] || !shapes.is_c_contiguous() {
        return Err(crate::error::input_error(format!(
            "blend_local: shapes must be C-contiguous ({v}, 3, q) float32, got {:?}",
            shapes.shape()
        )));
    }
    let flat = shapes
        .as_slice()
        .map_err(|_| crate::error::input_error("blend_local: shapes must be C-contiguous"))?;
    let to_usize = |a: &PyReadonlyArray1<'py, i64>, name: &str| -> PyResult<Vec<usize>> {
        a.as_array()
            .iter()
            .map(|&i| usize::try_from(i))
            .collect::<Result<_, _>>()
            .map_err(|_| crate::error::input_error(format!("blend_local: negative {name}")))
    };
    let indptr = to_usize(&indptr, "indptr")?;
    let indices = to_usize(&indices, "indices")?;
    let data: Vec<f64> = data.as_array().iter().copied().collect();
    let w = float_array(weights, "weights", &[None, None, Some(q)])?;
    let (f, b) = (w.shape()[0], w.shape()[1]);
    let w: Vec<f64> = w.iter().copied().collect();
    let sewing = lgi_core::SewingRows {
        indptr: &indptr,
        indices: &indices,
        data: &data,
    };
    let out = threads::detach(py, || -> lgi_core::Result<Vec<f64>> {
        let mut all = Vec::with_capacity(f * v * 3);
        let mut frame = vec![glam::DVec3::ZERO; v];
        for k in 0..f {
            lgi_core::blend_local(
                &x0,
                flat,
                sewing,
                &w[k * b * q..(k + 1) * b * q],
                &mut frame,
            )?;
            all.extend(frame.iter().flat_map(|p| [p.x, p.y, p.z]));
        }
        Ok(all)
    })
    .map_err(PyLgiError)?;
    flat_to_array(py, out, &[f, v, 3])
}
