//! `lgi._lgi.JawRig`: the core's two-bone jaw skinning (paper Eq. 2) for Python, vectorised
//! over points and frames. `lgi.jaw.JawRig` and the sample generator skin through it, so the
//! skinning formula exists once, in `lgi_core::jaw`.

use crate::convert::{any_numbers, flat_to_array, float_array, point_sets, points};
use crate::error::{input_error, PyLgiError};
use glam::{DMat3, DVec3};
use lgi_core::LgiError;
use lgi_core::{JawParams, JawRig as CoreRig};
use numpy::PyArrayDyn;
use pyo3::prelude::*;

type Array<'py> = Bound<'py, PyArrayDyn<f64>>;

/// Pivot, per-vertex jaw weights and the jaw's axes (`frame` columns: open axis, lateral axis,
/// forward direction). Immutable; `lgi.jaw.JawRig` subclasses it with the rig tooling.
#[pyclass(frozen, subclass, module = "lgi._lgi")]
pub struct JawRig {
    pub inner: CoreRig,
}

/// A (3, 3) array whose columns are the axes, as a matrix.
pub fn frame_from_array(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<DMat3> {
    let f = float_array(obj, name, &[Some(3), Some(3)])?;
    let col = |j: usize| DVec3::new(f[[0, j]], f[[1, j]], f[[2, j]]);
    Ok(DMat3::from_cols(col(0), col(1), col(2)))
}

/// A matrix as a row-major (3, 3) array (its columns are the array's columns).
fn matrix_to_array<'py>(py: Python<'py>, m: DMat3) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    flat_to_array(py, m.transpose().to_cols_array().to_vec(), &[3, 3])
}

/// One pose per set: `theta` (3,) for every set or (F, 3), one per set; errors say "theta".
fn poses(theta: &Bound<'_, PyAny>, sets: usize, per_set: bool) -> PyResult<Vec<JawParams>> {
    let shape = if per_set {
        vec![Some(sets), Some(3)]
    } else {
        vec![Some(3)]
    };
    let t = float_array(&any_numbers(theta, "theta")?, "theta", &shape)?;
    let flat: Vec<f64> = t.iter().copied().collect();
    let poses: Vec<JawParams> = flat
        .chunks_exact(3)
        .map(|c| JawParams::from_array([c[0], c[1], c[2]]))
        .collect();
    for p in &poses {
        p.validate().map_err(|e| match e {
            LgiError::Input(m) => input_error(format!("theta: {m}")),
            other => PyLgiError(other).into(),
        })?;
    }
    Ok(if per_set { poses } else { vec![poses[0]; sets] })
}

impl JawRig {
    /// Skins (`inverse`: unskins) (N, 3) or (F, N, 3) points to `theta` ((3,), or (F, 3)
    /// with (F, N, 3) points) with `weights` (N,) or the rig's own (N = V).
    fn apply<'py>(
        &self,
        py: Python<'py>,
        pts: &Bound<'py, PyAny>,
        theta: &Bound<'py, PyAny>,
        weights: Option<&Bound<'py, PyAny>>,
        inverse: bool,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let ndim: usize = pts.getattr("ndim").and_then(|n| n.extract()).unwrap_or(0);
        let batched = ndim == 3;
        let sets = if batched {
            point_sets(pts, "points", ("frame", "point"), None, true)?
        } else {
            vec![points(pts, "points", None, true)?]
        };
        let n = sets.first().map_or(0, Vec::len);
        let theta_ndim: usize = theta.getattr("ndim").and_then(|n| n.extract()).unwrap_or(1);
        let poses = poses(theta, sets.len(), batched && theta_ndim == 2)?;
        let w = match weights {
            None => None,
            Some(w) => Some(
                float_array(w, "weights", &[Some(n)])?
                    .iter()
                    .copied()
                    .collect::<Vec<f64>>(),
            ),
        };
        if w.is_none() && n != self.inner.num_vertices() {
            return Err(input_error(format!(
                "points: {n} points but the rig has weights for {} vertices (give weights)",
                self.inner.num_vertices()
            )));
        }
        let rig = &self.inner;
        let out = py.detach(|| -> Result<Vec<f64>, LgiError> {
            let mut flat = Vec::with_capacity(sets.len() * n * 3);
            let mut buf = vec![DVec3::ZERO; n];
            for (set, &pose) in sets.iter().zip(&poses) {
                match (&w, inverse) {
                    (None, false) => rig.skin(set, pose, &mut buf)?,
                    (None, true) => rig.unskin(set, pose, &mut buf)?,
                    (Some(w), false) => rig.skin_weighted(set, w, pose, &mut buf)?,
                    (Some(w), true) => rig.unskin_weighted(set, w, pose, &mut buf)?,
                }
                flat.extend(buf.iter().flat_map(|p| [p.x, p.y, p.z]));
            }
            Ok(flat)
        });
        let out = out.map_err(PyLgiError)?;
        if batched {
            flat_to_array(py, out, &[sets.len(), n, 3])
        } else {
            flat_to_array(py, out, &[n, 3])
        }
    }
}

#[pymethods]
impl JawRig {
    /// A rig from `pivot` (3,), per-vertex `weights` (V,) in [0, 1] and `frame` (3, 3), a
    /// rotation whose columns are the open, lateral and forward axes (None: identity).
    #[new]
    #[pyo3(signature = (pivot, weights, frame=None))]
    fn new(
        pivot: &Bound<'_, PyAny>,
        weights: &Bound<'_, PyAny>,
        frame: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let p = float_array(&any_numbers(pivot, "pivot")?, "pivot", &[Some(3)])?;
        let w = float_array(&any_numbers(weights, "weights")?, "weights", &[None])?;
        let frame = match frame {
            None => DMat3::IDENTITY,
            Some(f) => frame_from_array(&any_numbers(f, "frame")?, "frame")?,
        };
        let inner = CoreRig::with_frame(
            DVec3::new(p[0], p[1], p[2]),
            w.iter().copied().collect(),
            frame,
        )
        .map_err(PyLgiError)?;
        Ok(JawRig { inner })
    }

    /// (3,) centre of the jaw rotation.
    #[getter]
    fn pivot<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        flat_to_array(py, self.inner.pivot.to_array().to_vec(), &[3])
    }

    /// (V,) jaw weight of each vertex in [0, 1].
    #[getter]
    fn weights<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let w = self.inner.weights.clone();
        let n = w.len();
        flat_to_array(py, w, &[n])
    }

    /// (3, 3) rotation whose columns are the open, lateral and forward axes.
    #[getter]
    fn frame<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        matrix_to_array(py, self.inner.frame)
    }

    /// Number of vertices V the rig has weights for.
    #[getter]
    fn num_vertices(&self) -> usize {
        self.inner.num_vertices()
    }

    /// World rotation R (3, 3) and translation t (3,) of the rigid jaw at pose `theta` (3,):
    /// a weight-1 point p moves to R (p - pivot) + pivot + t.
    fn transform<'py>(
        &self,
        py: Python<'py>,
        theta: &Bound<'py, PyAny>,
    ) -> PyResult<(Array<'py>, Array<'py>)> {
        let pose = poses(theta, 1, false)?[0];
        let a = self.inner.rigid_transform(pose);
        let r = a.matrix3;
        // The affine's translation is pivot - R pivot + t: take the pivot terms back out.
        let t = self.inner.frame * pose.translation();
        Ok((
            matrix_to_array(py, r)?,
            flat_to_array(py, t.to_array().to_vec(), &[3])?,
        ))
    }

    /// Skins (N, 3) points to jaw pose `theta` (3,), or (F, N, 3) points to `theta` (3,) or
    /// one pose per frame (F, 3), each point with its jaw weight: `weights` (N,), or the rig's
    /// (N = V). A point moves by w (T(theta) p - p); theta = 0 or w = 0 leave it bit for bit.
    #[pyo3(signature = (points, theta, weights=None))]
    fn skin<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        theta: &Bound<'py, PyAny>,
        weights: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        self.apply(py, points, theta, weights, false)
    }

    /// The exact inverse of `skin` (same arguments).
    #[pyo3(signature = (points, theta, weights=None))]
    fn unskin<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        theta: &Bound<'py, PyAny>,
        weights: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        self.apply(py, points, theta, weights, true)
    }

    /// The pose (3,) whose skinning carries `points` (N, 3) onto `targets` (N, 3), by
    /// Gauss–Newton from `theta0` (3,; None: rest): `weights` (N,) are the points' jaw weights
    /// (None: 1, a rigid fit); `huber` (in robust standard deviations of the residuals, e.g.
    /// 1.345) reweighs outliers (None: plain least squares); at most `iterations` steps.
    #[pyo3(signature = (points, targets, weights=None, theta0=None, huber=None, iterations=50))]
    #[allow(clippy::too_many_arguments)]
    fn fit_pose<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        targets: &Bound<'py, PyAny>,
        weights: Option<&Bound<'py, PyAny>>,
        theta0: Option<&Bound<'py, PyAny>>,
        huber: Option<f64>,
        iterations: usize,
    ) -> PyResult<Array<'py>> {
        let p = crate::convert::points(points, "points", None, false)?;
        let t = crate::convert::points(targets, "targets", Some(p.len()), false)?;
        let w: Option<Vec<f64>> = match weights {
            None => None,
            Some(w) => Some(
                float_array(w, "weights", &[Some(p.len())])?
                    .iter()
                    .copied()
                    .collect(),
            ),
        };
        let start = match theta0 {
            None => JawParams::ZERO,
            Some(t) => poses(t, 1, false)?[0],
        };
        let rig = &self.inner;
        let pose = py
            .detach(|| rig.fit_pose(&p, &t, w.as_deref(), start, huber, iterations))
            .map_err(PyLgiError)?;
        flat_to_array(py, pose.to_array().to_vec(), &[3])
    }

    fn __repr__(&self) -> String {
        let p = self.inner.pivot;
        format!(
            "JawRig(pivot=[{}, {}, {}], num_vertices={})",
            p.x,
            p.y,
            p.z,
            self.inner.num_vertices()
        )
    }
}
