//! `lgi._lgi.JawRig` (`lgi.jaw.JawRig`): the core's two-bone jaw skinning (paper Eq. 2) for
//! Python, vectorised over points and frames, with the rig's dataset-side tooling (shapes
//! unskinned, bundles' weights, a dict for `.npz`), so the formulas exist once, in `lgi_core::jaw`.

use crate::convert::{any_numbers, flat_to_array, float_array, point_sets, points};
use crate::error::{input_error, internal_error, PyLgiError};
use crate::threads;
use glam::{DMat3, DVec3};
use lgi_core::LgiError;
use lgi_core::{JawParams, JawRig as CoreRig};
use numpy::{PyArrayDyn, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyType};
use rayon::prelude::*;

type Array<'py> = Bound<'py, PyArrayDyn<f64>>;

/// Pivot, per-vertex jaw weights and the jaw's axes (`frame` columns: open axis, lateral axis,
/// forward direction; identity means x, y, z as in `lgi.lab.sample`). Immutable.
#[pyclass(frozen, module = "lgi._lgi")]
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

/// One pose per set: `theta` (3,) for every set or (F, 3), one per set; errors name the
/// argument (`name`).
pub(crate) fn poses(
    theta: &Bound<'_, PyAny>,
    name: &str,
    sets: usize,
    per_set: bool,
) -> PyResult<Vec<JawParams>> {
    let shape = if per_set {
        vec![Some(sets), Some(3)]
    } else {
        vec![Some(3)]
    };
    let t = float_array(&any_numbers(theta, name)?, name, &shape)?;
    let flat: Vec<f64> = t.iter().copied().collect();
    let poses: Vec<JawParams> = flat
        .chunks_exact(3)
        .map(|c| JawParams::from_array([c[0], c[1], c[2]]))
        .collect();
    for p in &poses {
        p.validate().map_err(|e| match e {
            LgiError::Input(m) => input_error(format!("{name}: {m}")),
            other => PyLgiError(other).into(),
        })?;
    }
    Ok(if per_set { poses } else { vec![poses[0]; sets] })
}

/// `np.asarray(obj, float64)` of shape (N, 3): its values (row-major) and its shape as
/// Python shows it, for messages.
fn point_rows(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(Vec<f64>, String)> {
    let arr = any_numbers(obj, name)?;
    let shape = arr.getattr("shape")?;
    let dims: Vec<usize> = shape.extract()?;
    let shown = shape.repr()?.to_string();
    if dims.len() != 2 || dims[1] != 3 {
        return Err(input_error(format!(
            "{name} must have shape (N, 3), got {shown}"
        )));
    }
    Ok((values(&arr)?, shown))
}

/// An array's values in row-major order.
fn values<T: numpy::Element + Copy>(arr: &Bound<'_, PyAny>) -> PyResult<Vec<T>> {
    let a = arr
        .cast::<PyArrayDyn<T>>()
        .map_err(|e| internal_error(format!("array of unexpected dtype: {e}")))?;
    Ok(a.readonly().as_array().iter().copied().collect())
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
        let poses = poses(theta, "theta", sets.len(), batched && theta_ndim == 2)?;
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
        // Frames in parallel (each its own buffer: the same bits as one after another).
        let out = threads::detach(py, || -> Result<Vec<f64>, LgiError> {
            let per_frame: Vec<Vec<f64>> = sets
                .par_iter()
                .zip(&poses)
                .map(|(set, &pose)| {
                    let mut buf = vec![DVec3::ZERO; n];
                    match (&w, inverse) {
                        (None, false) => rig.skin(set, pose, &mut buf)?,
                        (None, true) => rig.unskin(set, pose, &mut buf)?,
                        (Some(w), false) => rig.skin_weighted(set, w, pose, &mut buf)?,
                        (Some(w), true) => rig.unskin_weighted(set, w, pose, &mut buf)?,
                    }
                    Ok(buf.iter().flat_map(|p| [p.x, p.y, p.z]).collect())
                })
                .collect::<Result<_, LgiError>>()?;
            Ok(per_frame.concat())
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
        let pose = poses(theta, "theta", 1, false)?[0];
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
            Some(t) => poses(t, "theta0", 1, false)?[0],
        };
        let rig = &self.inner;
        let pose = py
            .detach(|| rig.fit_pose(&p, &t, w.as_deref(), start, huber, iterations))
            .map_err(PyLgiError)?;
        flat_to_array(py, pose.to_array().to_vec(), &[3])
    }

    /// `s* = T_v(theta)^-1 (x0 + s) - x0` for one shape: `neutral` and `displacements`
    /// (V, 3), each vertex unskinned with its own weight (f64 throughout).
    fn unskin_displacements<'py>(
        &self,
        py: Python<'py>,
        neutral: &Bound<'py, PyAny>,
        displacements: &Bound<'py, PyAny>,
        theta: &Bound<'py, PyAny>,
    ) -> PyResult<Array<'py>> {
        let (x0, x0_shape) = point_rows(neutral, "neutral")?;
        let (s, s_shape) = point_rows(displacements, "displacements")?;
        if x0.len() != s.len() {
            return Err(input_error(format!(
                "displacements {s_shape} do not match neutral {x0_shape}"
            )));
        }
        let moved: Vec<f64> = x0.iter().zip(&s).map(|(a, b)| a + b).collect();
        let moved = flat_to_array(py, moved, &[x0.len() / 3, 3])?;
        let out = self.apply(py, moved.as_any(), theta, None, true)?;
        {
            let mut rw = out.readwrite();
            let flat = rw
                .as_slice_mut()
                .map_err(|e| internal_error(format!("unskinned points: {e}")))?;
            for (o, a) in flat.iter_mut().zip(&x0) {
                *o -= a;
            }
        }
        Ok(out)
    }

    /// Jaw weight (B,) of each bundle on the rig's mesh: the barycentric blend of its
    /// triangle's vertex weights, clipped to [0, 1] (`triangles` (T, 3), `bundle_triangles`
    /// (B,), `barycentrics` (B, 3)); the weight a model gives each marker.
    fn bundle_weights<'py>(
        &self,
        py: Python<'py>,
        triangles: &Bound<'py, PyAny>,
        bundle_triangles: &Bound<'py, PyAny>,
        barycentrics: &Bound<'py, PyAny>,
    ) -> PyResult<Array<'py>> {
        let np = py.import("numpy")?;
        let tri = np.call_method1("asarray", (triangles, "int64"))?;
        let bt = np.call_method1("asarray", (bundle_triangles, "int64"))?;
        let bc = np.call_method1("asarray", (barycentrics, "float64"))?;
        let shape = |a: &Bound<'py, PyAny>| -> PyResult<(Vec<usize>, String)> {
            let s = a.getattr("shape")?;
            Ok((s.extract()?, s.repr()?.to_string()))
        };
        let (tri_shape, tri_shown) = shape(&tri)?;
        if tri_shape.len() != 2 || tri_shape[1] != 3 {
            return Err(input_error(format!(
                "triangles must have shape (T, 3), got {tri_shown}"
            )));
        }
        let (bt_shape, bt_shown) = shape(&bt)?;
        if bt_shape.len() != 1 {
            return Err(input_error(format!(
                "bundle_triangles must have shape (B,), got {bt_shown}"
            )));
        }
        let b = bt_shape[0];
        let (bc_shape, bc_shown) = shape(&bc)?;
        if bc_shape != [b, 3] {
            return Err(input_error(format!(
                "barycentrics must have shape ({b}, 3), got {bc_shown}"
            )));
        }
        let tri: Vec<i64> = values(&tri)?;
        let bt: Vec<i64> = values(&bt)?;
        let bc: Vec<f64> = values(&bc)?;
        let t = tri_shape[0] as i64;
        if bt.iter().any(|&i| i < 0 || i >= t) {
            return Err(input_error("bundle triangle index out of range"));
        }
        let nv = self.inner.num_vertices() as i64;
        let corners: Vec<[u32; 3]> = bt
            .iter()
            .map(|&i| {
                let c = &tri[3 * i as usize..3 * i as usize + 3];
                match c.iter().all(|&v| (0..nv).contains(&v)) {
                    true => Ok([c[0] as u32, c[1] as u32, c[2] as u32]),
                    false => Err(input_error(
                        "triangle vertex index out of range of the rig's weights",
                    )),
                }
            })
            .collect::<PyResult<_>>()?;
        let weights = corners
            .iter()
            .zip(bc.chunks_exact(3))
            .map(|(&c, w)| self.inner.interpolate_weight(c, [w[0], w[1], w[2]]))
            .collect::<Result<Vec<f64>, LgiError>>()
            .map_err(PyLgiError)?;
        flat_to_array(py, weights, &[b])
    }

    /// Arrays for `np.savez`: `jaw_pivot`, `jaw_weights` and `jaw_frame` (`from_dict` reads
    /// them back).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("jaw_pivot", self.pivot(py)?)?;
        d.set_item("jaw_weights", self.weights(py)?)?;
        d.set_item("jaw_frame", self.frame(py)?)?;
        Ok(d)
    }

    /// The rig of `to_dict`'s arrays (any mapping, e.g. a loaded `.npz`); `jaw_frame` is
    /// optional (identity).
    #[classmethod]
    fn from_dict(_cls: &Bound<'_, PyType>, d: &Bound<'_, PyAny>) -> PyResult<Self> {
        let mut missing = Vec::new();
        for key in ["jaw_pivot", "jaw_weights"] {
            if !d.contains(key)? {
                missing.push(key);
            }
        }
        if !missing.is_empty() {
            return Err(input_error(format!(
                "jaw rig is missing {}",
                missing.join(", ")
            )));
        }
        let frame = match d.contains("jaw_frame")? {
            true => Some(d.get_item("jaw_frame")?),
            false => None,
        };
        JawRig::new(
            &d.get_item("jaw_pivot")?,
            &d.get_item("jaw_weights")?,
            frame.as_ref(),
        )
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
