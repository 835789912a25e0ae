//! numpy <-> Rust conversions, with every shape, dtype and finiteness check at the boundary.
//! No other module converts arrays by hand.

use crate::error::{input_error, internal_error};
use glam::DVec3;
use numpy::ndarray::Dimension;
use numpy::ndarray::{ArrayD, ArrayViewD, IxDyn};
use numpy::{
    Element, IntoPyArray, PyArrayDyn, PyArrayMethods, PyReadonlyArray, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes};

/// A numpy array read in place: its values as one slice, where it is C-contiguous and each
/// axis whose size `shape` gives has that size (`None` = any); else `None`, and the caller says
/// what it expected. (`as_slice` alone takes Fortran order too, whose slice is another layout.)
pub fn in_place<'a, T: Element, D: Dimension>(
    a: &'a PyReadonlyArray<'_, T, D>,
    shape: &[Option<usize>],
) -> Option<&'a [T]> {
    let got = a.shape();
    let fits = got.len() == shape.len()
        && got
            .iter()
            .zip(shape)
            .all(|(&g, w)| w.is_none_or(|w| w == g));
    a.as_slice().ok().filter(|_| fits && a.is_c_contiguous())
}

/// Reads any float32/float64 array-like of exactly `shape` (`None` = any length on that
/// axis) into a contiguous f64 `ArrayD`. `name` appears in every error message.
pub fn float_array(
    obj: &Bound<'_, PyAny>,
    name: &str,
    shape: &[Option<usize>],
) -> PyResult<ArrayD<f64>> {
    let py = obj.py();
    let np = py.import("numpy")?;
    // np.asarray does not copy arrays that are already ndarrays; it turns lists into arrays.
    let arr = np.call_method1("asarray", (obj,))?;
    let dtype: String = arr.getattr("dtype")?.getattr("name")?.extract()?;
    if dtype != "float64" && dtype != "float32" {
        return Err(input_error(format!(
            "{name}: expected a float32 or float64 array, got dtype {dtype}"
        )));
    }
    let arr = arr.call_method1("astype", ("float64",))?;
    let arr = arr
        .cast::<PyArrayDyn<f64>>()
        .map_err(|_| input_error(format!("{name}: not a numeric array")))?;
    let got: Vec<usize> = arr.shape().to_vec();
    let ok = got.len() == shape.len()
        && got
            .iter()
            .zip(shape)
            .all(|(g, want)| want.is_none_or(|w| w == *g));
    if !ok {
        let want: Vec<String> = shape
            .iter()
            .map(|d| d.map_or("N".to_string(), |w| w.to_string()))
            .collect();
        return Err(input_error(format!(
            "{name}: expected shape ({}), got {:?}",
            want.join(", "),
            got
        )));
    }
    Ok(arr.readonly().as_array().to_owned())
}

/// Any number array-like (ints, lists, bools) as a float64 array, for the arguments that
/// accept integers as numbers (jaw poses, rig pivots, points); `name` names it in errors.
pub fn any_numbers<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<Bound<'py, PyAny>> {
    let np = obj.py().import("numpy")?;
    np.call_method1("asarray", (obj, "float64"))
        .map_err(|e| input_error(format!("{name}: expected numbers: {}", e.value(obj.py()))))
}

/// A row of three coordinates as a point: NaN (a missing marker) only when `allow_nan`,
/// infinity never; the error says the `place` (e.g. "markers: row 3") has a non-finite coordinate.
fn row_point(
    r: ArrayViewD<'_, f64>,
    allow_nan: bool,
    place: impl FnOnce() -> String,
) -> PyResult<DVec3> {
    let p = DVec3::new(r[0], r[1], r[2]);
    let has_inf = p.to_array().iter().any(|x| x.is_infinite());
    if !has_inf && (p.is_finite() || (allow_nan && p.is_nan())) {
        return Ok(p);
    }
    Err(input_error(format!(
        "{} has a non-finite coordinate [{}, {}, {}]",
        place(),
        r[0],
        r[1],
        r[2]
    )))
}

/// An `(N, 3)` float array as points; `allow_nan` lets NaN through (missing markers) but
/// never infinities. `name` appears in error messages with the offending row.
pub fn points(
    obj: &Bound<'_, PyAny>,
    name: &str,
    rows: Option<usize>,
    allow_nan: bool,
) -> PyResult<Vec<DVec3>> {
    let a = float_array(obj, name, &[rows, Some(3)])?;
    a.outer_iter()
        .enumerate()
        .map(|(i, r)| row_point(r, allow_nan, || format!("{name}: row {i}")))
        .collect()
}

/// An `(F, N, 3)` float array as F sets of points (frames of markers, meshes), checked like
/// [`points`]; errors name the set and the row with `labels`, e.g. ("frame", "bundle").
pub fn point_sets(
    obj: &Bound<'_, PyAny>,
    name: &str,
    labels: (&str, &str),
    rows: Option<usize>,
    allow_nan: bool,
) -> PyResult<Vec<Vec<DVec3>>> {
    let a = float_array(obj, name, &[None, rows, Some(3)])?;
    a.outer_iter()
        .enumerate()
        .map(|(f, set)| {
            set.outer_iter()
                .enumerate()
                .map(|(i, r)| {
                    row_point(r, allow_nan, || {
                        format!("{name}: {} {f}, {} {i}", labels.0, labels.1)
                    })
                })
                .collect()
        })
        .collect()
}

/// Points as a new `(N, 3)` float64 array.
pub fn points_to_array<'py>(
    py: Python<'py>,
    pts: &[DVec3],
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let flat: Vec<f64> = pts.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
    flat_to_array(py, flat, &[pts.len(), 3])
}

/// A flat vector as a new array of `shape` (an internal size mismatch is a `RuntimeError`).
pub fn flat_to_array<'py, T: numpy::Element>(
    py: Python<'py>,
    flat: Vec<T>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyArrayDyn<T>>> {
    ArrayD::from_shape_vec(IxDyn(shape), flat)
        .map(|a| a.into_pyarray(py))
        .map_err(internal_error)
}

/// Reads an integer array-like of shape `(N, cols)` (any signed or unsigned integer dtype)
/// into a flat row-major `Vec<u32>` of `N * cols` indices. Negative values and values above
/// `u32::MAX` are errors naming `name` and the row; `name` appears in every message.
pub fn index_array(obj: &Bound<'_, PyAny>, name: &str, cols: usize) -> PyResult<Vec<u32>> {
    let py = obj.py();
    let np = py.import("numpy")?;
    let arr = np.call_method1("asarray", (obj,))?;
    let kind: String = arr.getattr("dtype")?.getattr("kind")?.extract()?;
    let dtype: String = arr.getattr("dtype")?.getattr("name")?.extract()?;
    if kind != "i" && kind != "u" {
        return Err(input_error(format!(
            "{name}: expected an integer array, got dtype {dtype}"
        )));
    }
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    if shape.len() != 2 || shape[1] != cols {
        return Err(input_error(format!(
            "{name}: expected shape (N, {cols}), got {shape:?}"
        )));
    }
    // uint64 does not fit int64: read it as such; every other integer dtype fits int64.
    fn widened<T: numpy::Element + Copy + Into<i128>>(
        arr: &Bound<'_, PyAny>,
        dtype: &str,
        name: &str,
    ) -> PyResult<Vec<i128>> {
        let a = arr.call_method1("astype", (dtype,))?;
        let a = a
            .cast::<PyArrayDyn<T>>()
            .map_err(|_| input_error(format!("{name}: not a numeric array")))?;
        Ok(a.readonly().as_array().iter().map(|&x| x.into()).collect())
    }
    let wide = if dtype == "uint64" {
        widened::<u64>(&arr, "uint64", name)?
    } else {
        widened::<i64>(&arr, "int64", name)?
    };
    wide.iter()
        .enumerate()
        .map(|(i, &x)| {
            u32::try_from(x).map_err(|_| {
                input_error(format!(
                    "{name}: row {} has index {x}, outside [0, {}]",
                    i / cols,
                    u32::MAX
                ))
            })
        })
        .collect()
}

/// A count argument (a Python int >= 0 that fits the platform's `usize`, not a bool): the
/// message names the argument instead of a bare `OverflowError` or `TypeError`.
pub fn count(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<usize> {
    let int_type = obj.py().get_type::<pyo3::types::PyInt>();
    let is_int = obj.is_instance(&int_type)? && !obj.is_instance_of::<pyo3::types::PyBool>();
    let is_numpy_int = obj
        .getattr("dtype")
        .and_then(|d| d.getattr("kind"))
        .and_then(|k| k.extract::<String>())
        .is_ok_and(|k| k == "i" || k == "u")
        && obj.getattr("ndim").and_then(|n| n.extract::<usize>()).ok() == Some(0);
    let shown = || obj.repr().map_or_else(|_| "?".into(), |r| r.to_string());
    if !(is_int || is_numpy_int) {
        return Err(input_error(format!(
            "{name}: expected an integer >= 0, got {}",
            shown()
        )));
    }
    // Beyond i128 the extraction fails: out of range like any other too-large value.
    let value: Option<i128> = obj.call_method0("__int__")?.extract().ok();
    value.and_then(|v| usize::try_from(v).ok()).ok_or_else(|| {
        input_error(format!(
            "{name}: expected an integer from 0 to {}, got {}",
            usize::MAX,
            shown()
        ))
    })
}

/// `lgi._lgi.check_count(value, name)`: [`count`] for the Python side (one rule for every
/// count argument, e.g. `smooth_window`); returns the value as an int.
#[pyfunction]
pub fn check_count(value: &Bound<'_, PyAny>, name: &str) -> PyResult<usize> {
    count(value, name)
}

/// Runs `read` on the bytes of `data` (`bytes`, borrowed; `bytearray`, copied); anything else
/// is an `lgi.InputError` naming `what`.
pub fn with_bytes<T>(
    data: &Bound<'_, PyAny>,
    what: &str,
    read: impl FnOnce(&[u8]) -> T,
) -> PyResult<T> {
    if let Ok(b) = data.cast::<PyBytes>() {
        return Ok(read(b.as_bytes()));
    }
    if let Ok(b) = data.cast::<PyByteArray>() {
        return Ok(read(&b.to_vec()));
    }
    let kind = data
        .get_type()
        .name()
        .map_or_else(|_| "?".into(), |n| n.to_string());
    Err(input_error(format!("{what}: expected bytes, got {kind}")))
}
