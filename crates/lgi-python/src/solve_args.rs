//! The arguments of `_lgi.Model.solve` as the core's options, each checked with the error
//! message the Python API has always given (the jaw mode as the user writes it: `"auto"`,
//! `"fit"`, `"track"`, an (F, 3) array or None).

use crate::convert::{any_numbers, count, float_array};
use crate::error::input_error;
use crate::error::PyLgiError;
use lgi_core::{JawParams, JawPose, Model as CoreModel, Sewn, TakePrior};
use numpy::{PyArray3, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyFloat, PyString};
use std::sync::Arc;

/// `smooth_window`: a count (an int >= 0, not a bool).
pub fn smooth_window(obj: &Bound<'_, PyAny>) -> PyResult<usize> {
    count(obj, "smooth_window")
}

/// `fit`: None (the core decides), else its truth value.
pub fn fit(obj: &Bound<'_, PyAny>) -> PyResult<Option<bool>> {
    if obj.is_none() {
        return Ok(None);
    }
    obj.is_truthy().map(Some)
}

/// `surface`: how much of each frame's surface to make, `"mesh"` (None too), `"markers"` or
/// `"none"` ([`Sewn`]).
pub fn sewn(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Sewn> {
    let Some(obj) = obj.filter(|o| !o.is_none()) else {
        return Ok(Sewn::Mesh);
    };
    let word = obj.cast::<PyString>().ok().map(|s| s.to_string());
    match word.as_deref() {
        Some("mesh") => Ok(Sewn::Mesh),
        Some("markers") => Ok(Sewn::Markers),
        Some("none") => Ok(Sewn::Nothing),
        _ => {
            let shown = obj.repr().map_or_else(|_| "?".into(), |r| r.to_string());
            Err(input_error(format!(
                "surface must be 'mesh', 'markers' or 'none', got {shown}"
            )))
        }
    }
}

/// `marker_noise`: None (exact), else whatever Python's `float` makes of it (the core checks
/// its range).
pub fn marker_noise(obj: &Bound<'_, PyAny>) -> PyResult<Option<f64>> {
    if obj.is_none() {
        return Ok(None);
    }
    let shown = || obj.repr().map_or_else(|_| "?".into(), |r| r.to_string());
    obj.py()
        .get_type::<PyFloat>()
        .call1((obj,))
        .and_then(|f| f.extract::<f64>())
        .map(Some)
        .map_err(|_| {
            input_error(format!(
                "marker_noise must be a number or None, got {}",
                shown()
            ))
        })
}

/// The jaw pose of `frames` frames on `model`: `"auto"` is the fit's pose with a jaw rig and
/// the rest pose without; `"fit"` and `"track"` need a rig; an array is one pose per frame;
/// None is the rest pose.
pub fn jaw_pose(
    jaw: Option<&Bound<'_, PyAny>>,
    model: &CoreModel,
    frames: usize,
) -> PyResult<JawPose> {
    let Some(jaw) = jaw.filter(|j| !j.is_none()) else {
        return Ok(JawPose::Rest);
    };
    let mode = match jaw.cast::<PyString>() {
        Ok(s) => Some(s.to_str()?.to_owned()),
        Err(_) => None,
    };
    if mode.as_deref() == Some("auto") {
        return Ok(match model.jaw() {
            Some(_) => JawPose::Fit,
            None => JawPose::Rest,
        });
    }
    if model.jaw().is_none() {
        return Err(input_error("jaw: this model was built without a jaw rig"));
    }
    match mode.as_deref() {
        Some("fit") => return Ok(JawPose::Fit),
        Some("track") => return Ok(JawPose::Track),
        Some(_) => {
            let shown = jaw.repr().map_or_else(|_| "?".into(), |r| r.to_string());
            return Err(input_error(format!(
                "jaw must be 'auto', 'fit', 'track', an (F, 3) array or None, got {shown}"
            )));
        }
        None => {}
    }
    let arr = any_numbers(jaw, "jaw")?;
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    if shape != [frames, 3] {
        let shown = arr.getattr("shape")?.repr()?.to_string();
        return Err(input_error(format!(
            "jaw: expected shape ({frames}, 3), got {shown}"
        )));
    }
    let poses = float_array(&arr, "jaw", &[Some(frames), Some(3)])?
        .outer_iter()
        .map(|r| JawParams::from_array([r[0], r[1], r[2]]))
        .collect();
    Ok(JawPose::Given(poses))
}

/// A caller's output array for `solve(out=...)`: float64, C-contiguous, writeable, of `shape`.
pub fn output_array<'py>(
    o: &Bound<'py, PyAny>,
    shape: [usize; 3],
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let arr = o.cast::<PyArray3<f64>>().map_err(|_| {
        let dtype = o
            .getattr("dtype")
            .map(|d| d.to_string())
            .unwrap_or_else(|_| "not a numpy array".into());
        input_error(format!(
            "out: expected a float64 numpy array of shape {shape:?}, got {dtype}"
        ))
    })?;
    if arr.shape() != shape {
        return Err(input_error(format!(
            "out: expected shape {shape:?}, got {:?}",
            arr.shape()
        )));
    }
    if !arr.is_c_contiguous() {
        return Err(input_error("out: the array must be C-contiguous"));
    }
    // Writeability is checked where the solve borrows it.
    Ok(arr.clone())
}

/// Runs `work` on `arr`'s memory (an `output_array`) as points: borrowed writeable for the
/// call, errors in our words for a read-only, non-contiguous or misaligned array.
pub fn with_points_mut<T>(
    arr: &Bound<'_, PyArray3<f64>>,
    work: impl FnOnce(&mut [glam::DVec3]) -> PyResult<T>,
) -> PyResult<T> {
    use numpy::PyArrayMethods;
    let mut rw = arr.try_readwrite().map_err(|e| {
        input_error(format!(
            "out: the array is not writeable (read-only, or borrowed elsewhere): {e}"
        ))
    })?;
    let flat = rw
        .as_slice_mut()
        .map_err(|e| input_error(format!("out: the array must be C-contiguous: {e}")))?;
    let points: &mut [glam::DVec3] = bytemuck::try_cast_slice_mut(flat).map_err(|e| {
        input_error(format!(
            "out: the array's memory must be aligned to 8 bytes (a fresh np.empty is): {e}"
        ))
    })?;
    work(points)
}

/// `take_prior`: None, or `(mean (S,), factor (S, q), noise_variance)` (`lgi.TakePrior`'s
/// arrays), checked by the core.
pub fn take_prior(obj: &Bound<'_, PyAny>) -> PyResult<Option<Arc<TakePrior>>> {
    if obj.is_none() {
        return Ok(None);
    }
    let (mean, factor, noise): (Bound<'_, PyAny>, Bound<'_, PyAny>, f64) = obj
        .extract()
        .map_err(|_| input_error("take_prior: expected None or (mean, factor, noise_variance)"))?;
    let mean = float_array(&mean, "take_prior mean", &[None])?;
    let s = mean.len();
    let factor = float_array(&factor, "take_prior factor", &[Some(s), None])?;
    let rank = factor.shape()[1];
    let prior = TakePrior::new(
        mean.iter().copied().collect(),
        factor.iter().copied().collect(),
        rank,
        noise,
    )
    .map_err(PyLgiError)?;
    Ok(Some(Arc::new(prior)))
}
