//! `lgi._lgi.LocalFits`: each bundle's blendshape fit of the markers around it
//! (`lgi_core::LocalFits`); python/lgi/local.py blends the pieces over the mesh.

use crate::convert::{flat_to_array, float_array, in_place, points as read_points};
use crate::error::PyLgiError;
use crate::threads;
use glam::DVec3;
use lgi_core::LocalFits as CoreLocal;
use numpy::{
    PyArrayDyn, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use rayon::prelude::*;

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

/// `shapes` (V, 3, q) float32 read in place, vertex-major as `lgi_core::blend_local` reads it;
/// an error naming `what` for another shape or a non-contiguous array.
fn vertex_shapes<'a>(
    shapes: &'a PyReadonlyArray3<'_, f32>,
    v: usize,
    what: &str,
) -> PyResult<&'a [f32]> {
    in_place(shapes, &[Some(v), Some(3), None]).ok_or_else(|| {
        crate::error::input_error(format!(
            "{what}: shapes must be C-contiguous ({v}, 3, q) float32, got {:?}",
            shapes.shape()
        ))
    })
}

/// An int64 index array as `usize`s; `what` names it in the error for a negative one.
fn indices_of(a: &PyReadonlyArray1<'_, i64>, what: &str) -> PyResult<Vec<usize>> {
    a.as_array()
        .iter()
        .map(|&i| usize::try_from(i))
        .collect::<Result<_, _>>()
        .map_err(|_| crate::error::input_error(format!("{what}: a negative index")))
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

/// The local fits' blend over the mesh of several frames (`lgi_core::blend_local_frames`):
/// `neutral` (V, 3), `shapes` (V, 3, q) float32 C-contiguous (read in place), the sewing
/// weights as CSR rows (`indptr` (V+1,), `indices`, `data`; int64, int64, float64) and
/// `weights` (F, B, q) -> (F, V, 3).
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
    let flat = vertex_shapes(&shapes, v, "blend_local")?;
    let indptr = indices_of(&indptr, "blend_local: indptr")?;
    let indices = indices_of(&indices, "blend_local: indices")?;
    let data: Vec<f64> = data.as_array().iter().copied().collect();
    let w = float_array(weights, "weights", &[None, None, Some(q)])?;
    let f = w.shape()[0];
    let w: Vec<f64> = w.iter().copied().collect();
    let sewing = lgi_core::SewingRows {
        indptr: &indptr,
        indices: &indices,
        data: &data,
    };
    let out = threads::detach(py, || -> lgi_core::Result<Vec<f64>> {
        if f == 0 {
            return Ok(Vec::new());
        }
        let mut all = vec![glam::DVec3::ZERO; f * v];
        lgi_core::blend_local_frames(&x0, flat, sewing, &w, &mut all)?;
        Ok(all.iter().flat_map(|p| [p.x, p.y, p.z]).collect())
    })
    .map_err(PyLgiError)?;
    flat_to_array(py, out, &[f, v, 3])
}

/// The local fits' surface of a chunk of frames in one call (python/lgi/solve/local.py): each
/// frame's blend of its bundles' weights over the mesh (`lgi_core::blend_local`), skinned by its
/// jaw pose, plus the biharmonic corrective of what the blend misses at the targets, written
/// into the caller's array, and the markers' positions measured on it. Frames run in parallel,
/// each with its own buffers, so no frame-sized array goes back to Python between the steps
/// and the result is the same, bit for bit, as those steps one after another.
#[pyclass(frozen, module = "lgi._lgi")]
pub struct LocalSurface {
    neutral: Vec<DVec3>,
    /// V × 3 × q float32, vertex-major (as `blend_local` reads it).
    shapes: Vec<f32>,
    q: usize,
    indptr: Vec<usize>,
    indices: Vec<usize>,
    data: Vec<f64>,
    rig: Option<Py<crate::jaw::JawRig>>,
    corrective: Py<crate::baselines::RbfInterpolator>,
    model: Py<crate::model::Model>,
}

#[pymethods]
impl LocalSurface {
    /// `neutral` (V, 3); `shapes` (V, 3, q) float32 C-contiguous; the sewing weights as CSR
    /// rows (`indptr` (V+1,), `indices`, `data`); `rig`: the jaw rig that poses the blend
    /// (None: none); `corrective`: the RBF interpolator over the mesh; `model`: whose bundles
    /// are measured.
    #[new]
    #[allow(clippy::too_many_arguments)]
    fn new<'py>(
        neutral: &Bound<'py, PyAny>,
        shapes: PyReadonlyArray3<'py, f32>,
        indptr: PyReadonlyArray1<'py, i64>,
        indices: PyReadonlyArray1<'py, i64>,
        data: PyReadonlyArray1<'py, f64>,
        rig: Option<Py<crate::jaw::JawRig>>,
        corrective: Py<crate::baselines::RbfInterpolator>,
        model: Py<crate::model::Model>,
    ) -> PyResult<Self> {
        let neutral = read_points(neutral, "neutral", None, false)?;
        let v = neutral.len();
        let q = shapes.shape()[2];
        let flat = vertex_shapes(&shapes, v, "LocalSurface")?;
        if q == 0 {
            return Err(crate::error::input_error(format!(
                "LocalSurface: shapes must be C-contiguous ({v}, 3, q) float32, got {:?}",
                shapes.shape()
            )));
        }
        let surface = LocalSurface {
            shapes: flat.to_vec(),
            q,
            indptr: indices_of(&indptr, "LocalSurface: indptr")?,
            indices: indices_of(&indices, "LocalSurface: indices")?,
            data: data.as_array().iter().copied().collect(),
            rig,
            corrective,
            model,
            neutral,
        };
        let nv = surface.model.get().inner.dataset().num_vertices();
        let rbf = &surface.corrective.get().inner;
        if nv != v || rbf.num_points() != v {
            return Err(crate::error::input_error(format!(
                "LocalSurface: the model's mesh has {nv} vertices and the corrective {}, the \
                 neutral {v}",
                rbf.num_points()
            )));
        }
        Ok(surface)
    }

    /// `weights` (F, B, q), `targets` (F, B, 3) (NaN rows: missing markers), `out` (F, V, 3)
    /// float64 C-contiguous (receives the surface), `theta` (F, 3) jaw poses (None: unposed)
    /// -> the markers' positions on the surface (F, B, 3). `corrective=False`: the posed blend
    /// only, without the corrective that puts it through the targets (a caller that adds the
    /// corrective itself, `lgi.solve.steady`), and the positions on it.
    #[pyo3(signature = (weights, targets, out, theta=None, corrective=true))]
    fn surface<'py>(
        &self,
        py: Python<'py>,
        weights: &Bound<'py, PyAny>,
        targets: &Bound<'py, PyAny>,
        out: &Bound<'py, PyAny>,
        theta: Option<&Bound<'py, PyAny>>,
        corrective: bool,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let model = &self.model.get().inner;
        let (v, b, q) = (self.neutral.len(), model.num_bundles(), self.q);
        let w = float_array(weights, "weights", &[None, Some(b), Some(q)])?;
        let f = w.shape()[0];
        let w: Vec<f64> = w.iter().copied().collect();
        let t = float_array(targets, "targets", &[Some(f), Some(b), Some(3)])?;
        let t: Vec<DVec3> = t
            .as_slice()
            .map(|s| s.to_vec())
            .unwrap_or_else(|| t.iter().copied().collect())
            .chunks_exact(3)
            .map(|c| DVec3::new(c[0], c[1], c[2]))
            .collect();
        let poses = match (theta, &self.rig) {
            (Some(th), Some(_)) => Some(crate::jaw::poses(th, "theta", f, true)?),
            _ => None,
        };
        let arr = crate::solve_args::output_array(out, [f, v, 3])?;
        let rig = self.rig.as_ref().map(|r| &r.get().inner);
        let rbf = &self.corrective.get().inner;
        let sewing = lgi_core::SewingRows {
            indptr: &self.indptr,
            indices: &self.indices,
            data: &self.data,
        };
        // In stages over the chunk's frames, each frame's arithmetic as its own: the blend of
        // every frame a block of vertices at a time (its shapes read once for all the
        // frames), then per frame its jaw pose and what the blend misses at the markers, then
        // the corrective of every frame (its matrix read once for all), then the markers.
        let surface = |out: &mut [DVec3]| -> lgi_core::Result<Vec<Vec<DVec3>>> {
            if f == 0 {
                return Ok(Vec::new());
            }
            lgi_core::blend_local_frames(&self.neutral, &self.shapes, sewing, &w, out)?;
            let misses = out
                .par_chunks_mut(v)
                .enumerate()
                .map(|(k, o)| {
                    if let (Some(rig), Some(poses)) = (rig, &poses) {
                        rig.skin_in_place(o, poses[k])?;
                    }
                    let on = model.bundle_positions(o)?;
                    Ok(t[k * b..(k + 1) * b]
                        .iter()
                        .zip(&on)
                        .map(|(target, at)| *target - *at)
                        .collect::<Vec<DVec3>>())
                })
                .collect::<lgi_core::Result<Vec<Vec<DVec3>>>>()?;
            if corrective {
                rbf.add_interpolated_frames(&misses.concat(), out)?;
            }
            out.par_chunks(v)
                .map(|o| model.bundle_positions(o))
                .collect()
        };
        let positions = crate::solve_args::with_points_mut(&arr, |out| {
            threads::detach(py, || surface(out)).map_err(|e| PyLgiError(e).into())
        })?;
        let flat: Vec<f64> = positions
            .iter()
            .flatten()
            .flat_map(|p| [p.x, p.y, p.z])
            .collect();
        flat_to_array(py, flat, &[f, b, 3])
    }
}
