//! `lgi._lgi.Dataset`: the core's dataset (neutral mesh and shapes), loaded by the core's
//! readers (OBJ, glTF, bytes) or from numpy arrays, with the GIL released. `lgi.Dataset` (a
//! Python class) holds one and adds what is Python's: the `.npz` layout and ARAP augmentation.

use crate::convert::{count, flat_to_array, float_array, index_array, points, points_to_array};
use crate::error::{input_error, lgi_exception, PyLgiError, PyLgiResult};
use lgi_core::{DVec2, LgiError, Mesh};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyString};
use std::path::PathBuf;
use std::sync::Arc;

/// Neutral mesh plus S shapes (displacements). Immutable; cheap to share.
#[pyclass(frozen, module = "lgi._lgi")]
pub struct Dataset {
    pub inner: Arc<lgi_core::Dataset>,
}

#[pymethods]
impl Dataset {
    /// Loads a neutral OBJ and shape OBJs (same vertex order as the neutral; only their
    /// `v` lines are read). `shapes` is a glob pattern (str or path; matches are sorted), a
    /// sequence of paths, or None for no shapes. Shapes are named after their file stems.
    #[staticmethod]
    #[pyo3(signature = (neutral, shapes = None))]
    fn from_obj(
        py: Python<'_>,
        neutral: PathBuf,
        shapes: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Dataset> {
        let shape_paths = match shapes {
            None => Vec::new(),
            Some(s) => shape_files(s)?,
        };
        let d: PyLgiResult<_> = py
            .detach(|| lgi_core::Dataset::from_obj_files(&neutral, &shape_paths))
            .map_err(PyLgiError);
        let d = d?;
        Ok(Dataset { inner: Arc::new(d) })
    }

    /// Loads the first mesh of a glTF/GLB file; its morph targets are the shapes.
    #[staticmethod]
    fn from_gltf(py: Python<'_>, path: PathBuf) -> PyResult<Dataset> {
        let d = py
            .detach(|| lgi_core::read_gltf(&path))
            .map_err(PyLgiError)?;
        Ok(Dataset { inner: Arc::new(d) })
    }

    /// The dataset as bytes: the model file's dataset part (neutral, shape names,
    /// displacements, source polygons) in the model format's framing, magic `LGIDATAS`.
    fn to_bytes<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        let data = self.inner.clone();
        let bytes = py.detach(move || lgi_core::dataset_to_bytes(&data));
        PyBytes::new(py, &bytes)
    }

    /// A dataset from `to_bytes`'s bytes, with every check of a dataset built from arrays;
    /// corrupt bytes raise `lgi.ModelFormatError`.
    #[staticmethod]
    fn from_bytes(py: Python<'_>, data: &Bound<'_, PyAny>) -> PyResult<Dataset> {
        let d = crate::convert::with_bytes(data, "Dataset.from_bytes", |bytes| {
            py.detach(|| lgi_core::dataset_from_bytes(bytes))
                .map_err(PyLgiError)
        })??;
        Ok(Dataset { inner: Arc::new(d) })
    }

    /// Pickles as `to_bytes` (`from_bytes` rebuilds it, checked).
    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyAny>, (Bound<'py, PyBytes>,))> {
        let bytes = slf.get().to_bytes(slf.py());
        Ok((slf.get_type().getattr("from_bytes")?, (bytes,)))
    }

    /// A dataset from arrays: `neutral` (V, 3) float, `triangles` (T, 3) int, `shapes`
    /// (S, V, 3) float displacements or None, `names` (S strings; default `shape{k}`),
    /// `uvs` (U, 2) float with `uv_triangles` (T, 3) int indexing it (both or neither).
    #[staticmethod]
    #[pyo3(signature = (neutral, triangles, shapes = None, names = None, uvs = None, uv_triangles = None))]
    fn from_arrays(
        py: Python<'_>,
        neutral: &Bound<'_, PyAny>,
        triangles: &Bound<'_, PyAny>,
        shapes: Option<&Bound<'_, PyAny>>,
        names: Option<&Bound<'_, PyAny>>,
        uvs: Option<&Bound<'_, PyAny>>,
        uv_triangles: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Dataset> {
        build(py, neutral, triangles, shapes, names, uvs, uv_triangles)
    }

    /// A new dataset with in-between shapes (`name@0.5`, …) and pairwise sums of
    /// displacements added to the shapes, at least `min_shapes` when there are enough pairs
    /// (the neutral is shared); the GIL is released.
    fn augmented(&self, py: Python<'_>, min_shapes: &Bound<'_, PyAny>) -> PyResult<Dataset> {
        let min_shapes = count(min_shapes, "min_shapes")?;
        let inner = self.inner.clone();
        let d = py
            .detach(|| lgi_core::augment(&inner, min_shapes))
            .map_err(PyLgiError)?;
        Ok(Dataset { inner: Arc::new(d) })
    }

    /// The recipes of `augmented(min_shapes)`, in its order: `(name, [(shape, weight), ...])`
    /// per shape of the augmented dataset (originals first, weight 1).
    fn augment_recipes(&self, min_shapes: &Bound<'_, PyAny>) -> PyResult<Vec<lgi_core::Recipe>> {
        let min_shapes = count(min_shapes, "min_shapes")?;
        Ok(lgi_core::recipes(self.inner.names(), min_shapes))
    }

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
        flat_to_array(
            py,
            d.displacements().to_vec(),
            &[d.num_shapes(), d.num_vertices(), 3],
        )
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

    /// A new dataset with the neutral's source faces: `counts` (P,) corners per face (each
    /// >= 3), `vertices` (sum of counts,) vertex index per corner, `uvs` the UV index per
    /// corner (required exactly when the dataset has UVs). They must fan-split (corner 0
    /// with each later edge) into exactly `triangles` and `uv_triangles`; exports then write
    /// these faces. An `lgi.InputError` names what does not match.
    #[pyo3(signature = (counts, vertices, uvs = None))]
    fn with_polygons(
        &self,
        counts: &Bound<'_, PyAny>,
        vertices: &Bound<'_, PyAny>,
        uvs: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Dataset> {
        let polygons = lgi_core::Polygons {
            counts: index_vector(counts, "counts")?,
            vertices: index_vector(vertices, "vertices")?,
            uvs: match uvs {
                None => Vec::new(),
                Some(u) => index_vector(u, "uvs")?,
            },
        };
        let d = (*self.inner)
            .clone()
            .with_polygons(polygons)
            .map_err(|e| match e {
                LgiError::Dataset(m) => PyLgiError(LgiError::Input(m)),
                other => PyLgiError(other),
            })?;
        Ok(Dataset { inner: Arc::new(d) })
    }

    /// The neutral's source faces when its file had them (OBJ): `(counts, vertices, uvs)`,
    /// int64 arrays of corners per face (P,), vertex index per corner (sum of counts,) and UV
    /// index per corner (same length, or empty without UVs); fan-split they give `triangles`
    /// and `uv_triangles`. None for datasets from arrays, glTF or `.npz`.
    #[getter]
    #[allow(clippy::type_complexity)]
    fn polygons<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<
        Option<(
            Bound<'py, PyArrayDyn<i64>>,
            Bound<'py, PyArrayDyn<i64>>,
            Bound<'py, PyArrayDyn<i64>>,
        )>,
    > {
        let Some(p) = self.inner.polygons() else {
            return Ok(None);
        };
        let arr = |v: &[u32]| {
            let flat: Vec<i64> = v.iter().map(|&i| i64::from(i)).collect();
            flat_to_array(py, flat, &[v.len()])
        };
        Ok(Some((arr(&p.counts)?, arr(&p.vertices)?, arr(&p.uvs)?)))
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

/// Expands the `shapes` argument of `from_obj`: a glob pattern (str or path-like) or a
/// sequence of paths.
fn shape_files(shapes: &Bound<'_, PyAny>) -> PyResult<Vec<PathBuf>> {
    let is_pattern = shapes.is_instance_of::<PyString>() || shapes.try_iter().is_err();
    if !is_pattern {
        let mut out = Vec::new();
        for (i, item) in shapes.try_iter()?.enumerate() {
            let item = item?;
            out.push(item.extract::<PathBuf>().map_err(|_| {
                input_error(format!(
                    "shapes[{i}]: expected a str or os.PathLike, got {}",
                    type_name(&item)
                ))
            })?);
        }
        return Ok(out);
    }
    let pattern: PathBuf = shapes.extract().map_err(|_| {
        input_error(format!(
            "shapes: expected a glob pattern, a sequence of paths or None, got {}",
            type_name(shapes)
        ))
    })?;
    let pattern = pattern.to_string_lossy().into_owned();
    let out = lgi_core::expand_glob(&pattern).map_err(|e| match e {
        LgiError::Input(m) => input_error(format!("shapes: {m}")),
        other => PyLgiError(other).into(),
    })?;
    if out.is_empty() {
        return Err(lgi_exception(
            "DatasetFileError",
            format!("no shape file matches the pattern '{pattern}'"),
        ));
    }
    Ok(out)
}

fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "?".into())
}

/// Checks and converts array arguments, then builds the core dataset with the GIL released.
/// Every check failure is an `lgi.InputError` naming the argument.
fn build(
    py: Python<'_>,
    neutral: &Bound<'_, PyAny>,
    triangles: &Bound<'_, PyAny>,
    shapes: Option<&Bound<'_, PyAny>>,
    names: Option<&Bound<'_, PyAny>>,
    uvs: Option<&Bound<'_, PyAny>>,
    uv_triangles: Option<&Bound<'_, PyAny>>,
) -> PyResult<Dataset> {
    let positions = points(neutral, "neutral", None, false)?;
    let v = positions.len();
    let tris = triangle_rows(triangles, "triangles", v, "vertex")?;

    let (displacements, s) = match shapes {
        None => (Vec::new(), 0),
        Some(obj) => {
            let a = float_array(obj, "shapes", &[None, Some(v), Some(3)])?;
            let s = a.shape()[0];
            let flat: Vec<f32> = a.iter().map(|&x| x as f32).collect();
            if let Some(i) = flat.iter().position(|x| !x.is_finite()) {
                return Err(input_error(format!(
                    "shapes: shape {}, vertex {} has a non-finite displacement (or one too \
                     large for float32)",
                    i / (3 * v.max(1)),
                    (i / 3) % v.max(1)
                )));
            }
            (flat, s)
        }
    };

    let names: Vec<String> = match names {
        None => (0..s).map(|k| format!("shape{k}")).collect(),
        Some(obj) => {
            let got: Vec<String> = if obj.is_instance_of::<PyString>() {
                None
            } else {
                obj.call_method0("tolist")
                    .ok()
                    .unwrap_or_else(|| obj.clone())
                    .extract()
                    .ok()
            }
            .ok_or_else(|| {
                input_error(format!(
                    "names: expected a sequence of {s} strings, got {}",
                    type_name(obj)
                ))
            })?;
            if got.len() != s {
                return Err(input_error(format!(
                    "names: {} names for {s} shapes",
                    got.len()
                )));
            }
            got
        }
    };

    let (uv_points, uv_tris) = match (uvs, uv_triangles) {
        (None, None) => (Vec::new(), Vec::new()),
        (Some(u), Some(ut)) => {
            let a = float_array(u, "uvs", &[None, Some(2)])?;
            let mut pts = Vec::with_capacity(a.shape()[0]);
            for (i, r) in a.outer_iter().enumerate() {
                let p = DVec2::new(r[0], r[1]);
                if !p.is_finite() {
                    return Err(input_error(format!(
                        "uvs: row {i} has a non-finite coordinate [{}, {}]",
                        p.x, p.y
                    )));
                }
                pts.push(p);
            }
            let ut = triangle_rows(ut, "uv_triangles", pts.len(), "UV")?;
            if ut.len() != tris.len() {
                return Err(input_error(format!(
                    "uv_triangles: {} rows for {} triangles",
                    ut.len(),
                    tris.len()
                )));
            }
            (pts, ut)
        }
        (Some(_), None) => return Err(input_error("uvs given without uv_triangles")),
        (None, Some(_)) => return Err(input_error("uv_triangles given without uvs")),
    };

    let mesh = Mesh {
        positions,
        triangles: tris,
        uvs: uv_points,
        uv_triangles: uv_tris,
    };
    let d = py
        .detach(|| lgi_core::Dataset::new(mesh, displacements, names))
        .map_err(|e| match e {
            // Everything came from the arguments, so a dataset inconsistency is bad input.
            LgiError::Dataset(m) => PyLgiError(LgiError::Input(m)),
            other => PyLgiError(other),
        })?;
    Ok(Dataset { inner: Arc::new(d) })
}

/// A 1-D integer array as u32 indices (`lgi.InputError` naming `name` otherwise).
fn index_vector(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<u32>> {
    let np = obj.py().import("numpy")?;
    let arr = np.call_method1("asarray", (obj,))?;
    let ndim: usize = arr.getattr("ndim")?.extract()?;
    if ndim != 1 {
        return Err(input_error(format!("{name}: expected a 1-D integer array")));
    }
    index_array(&arr.call_method1("reshape", ((-1i64, 1i64),))?, name, 1)
}

/// `(T, 3)` index rows, each index below `count` (`what` names the indexed element).
fn triangle_rows(
    obj: &Bound<'_, PyAny>,
    name: &str,
    count: usize,
    what: &str,
) -> PyResult<Vec<[u32; 3]>> {
    let flat = index_array(obj, name, 3)?;
    if let Some(i) = flat.iter().position(|&x| x as usize >= count) {
        return Err(input_error(format!(
            "{name}: row {} refers to {what} {} but there are {count}",
            i / 3,
            flat[i]
        )));
    }
    Ok(flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}
