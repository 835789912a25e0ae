//! `lgi._lgi.fill_missing_rows`: a take's frames short of a row filled by their fits in the fit
//! matrix's coordinates (`lgi_core::FillFit`), for the take prior's reading.

use crate::convert::{flat_to_array, in_place};
use crate::error::{input_error, PyLgiError};
use lgi_core::{FillFit, MissingRows};
use numpy::{PyArrayDyn, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

/// A C-contiguous float64 matrix of `shape` read in place (`None`: any length on that axis).
fn matrix<'a>(
    a: &'a PyReadonlyArray2<'_, f64>,
    what: &str,
    shape: [Option<usize>; 2],
) -> PyResult<&'a [f64]> {
    in_place(a, &shape).ok_or_else(|| {
        input_error(format!(
            "fill_missing_rows: {what} must be a C-contiguous float64 array of shape {shape:?}, \
             got {:?}",
            a.shape()
        ))
    })
}

/// `zeta` (F, q) with every frame short of a row filled by its fit (`lgi_core::FillFit`): `u`
/// and `l` (R, q), `k` = `l @ u.T` (R, R), `present` (F, R) bool; `mean` (q,): fill each frame
/// under the prior of that mean (None: `zeta`'s frames are their present rows' share). All
/// float64 C-contiguous, read in place. Serial, with the GIL released: the held-out priors call
/// it from several threads at once.
#[pyfunction]
#[pyo3(signature = (u, l, k, present, zeta, mean = None))]
pub fn fill_missing_rows<'py>(
    py: Python<'py>,
    u: PyReadonlyArray2<'py, f64>,
    l: PyReadonlyArray2<'py, f64>,
    k: PyReadonlyArray2<'py, f64>,
    present: PyReadonlyArray2<'py, bool>,
    zeta: PyReadonlyArray2<'py, f64>,
    mean: Option<PyReadonlyArray1<'py, f64>>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let (r, q) = (u.shape()[0], u.shape()[1]);
    let f = zeta.shape()[0];
    let u = matrix(&u, "u", [None, None])?;
    let l = matrix(&l, "l", [Some(r), Some(q)])?;
    let k = matrix(&k, "k", [Some(r), Some(r)])?;
    let z = matrix(&zeta, "zeta", [None, Some(q)])?;
    let flags = present
        .as_slice()
        .ok()
        .filter(|_| present.shape() == [f, r] && present.is_c_contiguous())
        .ok_or_else(|| {
            input_error(format!(
                "fill_missing_rows: present must be a C-contiguous bool array of shape ({f}, \
                 {r}), got {:?}",
                present.shape()
            ))
        })?;
    let mean = match &mean {
        None => None,
        Some(m) => Some(m.as_slice().ok().filter(|s| s.len() == q).ok_or_else(|| {
            input_error(format!(
                "fill_missing_rows: mean must be {q} float64 values"
            ))
        })?),
    };
    let mut out = z.to_vec();
    py.detach(|| {
        let missing = MissingRows::of(flags, r)?;
        FillFit {
            u,
            l,
            k,
            directions: q,
        }
        .fill(&missing, &mut out, mean)
    })
    .map_err(PyLgiError)?;
    flat_to_array(py, out, &[f, q])
}
