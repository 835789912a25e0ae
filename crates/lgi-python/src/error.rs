//! The one place where core errors become Python exceptions. Each `LgiError` variant maps to
//! a class defined in `lgi/errors.py` (so classes can also derive from `ValueError` or
//! `FileNotFoundError`); all derive from `lgi.LgiError`.

use lgi_core::LgiError;
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;

/// Newtype so `?` converts core errors into the right Python exception.
pub struct PyLgiError(pub LgiError);

impl From<LgiError> for PyLgiError {
    fn from(e: LgiError) -> Self {
        PyLgiError(e)
    }
}

/// Builds an instance of `lgi.errors.<class_name>(msg)`; falls back to `RuntimeError` only
/// if the Python package is missing (the extension imported on its own).
pub fn lgi_exception(class_name: &str, msg: String) -> PyErr {
    Python::attach(|py| {
        let made = py
            .import("lgi.errors")
            .and_then(|m| m.getattr(class_name))
            .and_then(|cls| cls.call1((msg.clone(),)));
        match made {
            Ok(inst) => PyErr::from_value(inst),
            Err(_) => PyRuntimeError::new_err(format!("{class_name}: {msg}")),
        }
    })
}

/// Issues `msg` as an `lgi.errors.LgiWarning` attributed to the caller's caller (the
/// Python line that called the binding through `lgi`'s wrapper).
pub fn lgi_warning(py: Python<'_>, msg: String) -> PyResult<()> {
    let category = py.import("lgi.errors")?.getattr("LgiWarning")?;
    let msg = std::ffi::CString::new(msg).map_err(|e| input_error(e.to_string()))?;
    PyErr::warn(py, &category, &msg, 2)
}

impl From<PyLgiError> for PyErr {
    fn from(e: PyLgiError) -> PyErr {
        let class = match &e.0 {
            LgiError::Io { .. } => "DatasetFileError",
            LgiError::Write { .. } => "FileWriteError",
            LgiError::Parse { .. } | LgiError::Dataset(_) => "DatasetError",
            LgiError::Input(_) => "InputError",
            LgiError::MarkerOffSurface { .. } => "MarkerError",
            LgiError::ModelFormat { .. } => "ModelFormatError",
        };
        lgi_exception(class, e.0.to_string())
    }
}

/// Result type of binding functions that call the core.
pub type PyLgiResult<T> = Result<T, PyLgiError>;

/// A `RuntimeError` for a broken invariant of the binding itself (a bug, not bad input).
pub fn internal_error(msg: impl std::fmt::Display) -> PyErr {
    pyo3::exceptions::PyRuntimeError::new_err(format!("internal: {msg}"))
}

/// An `lgi.InputError` raised by the binding itself (shape and dtype checks).
pub fn input_error(msg: impl Into<String>) -> PyErr {
    lgi_exception("InputError", msg.into())
}
