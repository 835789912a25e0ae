//! Python binding of lgi-core: numpy in, numpy out. Conversions live in `convert.rs`, the
//! error mapping in `error.rs`; every heavy call releases the GIL
//! (`threads::detach`: on the pool `set_num_threads` chose).

mod baselines;
mod config;
mod convert;
mod dataset;
mod error;
mod jaw;
mod local_fit;
mod missing_rows;
mod model;
mod result;
mod solve_args;
mod surface;
mod threads;

use pyo3::prelude::*;

/// The compiled extension `lgi._lgi`. Users import `lgi`, which re-exports these names.
#[pymodule]
fn _lgi(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    // The global fit's ridge and box penalty (relative to the mean squared column norm): the
    // blendshape baseline's defaults on the Python side.
    m.add("FIT_L2", lgi_core::FIT_L2)?;
    m.add("LOCAL_LENGTH", lgi_core::LOCAL_LENGTH)?;
    m.add("MIN_PRESENT_MARKERS", lgi_core::MIN_PRESENT_MARKERS)?;
    m.add("FIT_PENALTY", lgi_core::FIT_PENALTY)?;
    m.add_class::<dataset::Dataset>()?;
    m.add_class::<config::BuildConfig>()?;
    m.add_class::<jaw::JawRig>()?;
    m.add_class::<model::Model>()?;
    m.add_class::<result::SolveResult>()?;
    m.add_class::<result::Choices>()?;
    m.add_class::<result::SolveState>()?;
    m.add_class::<baselines::RbfInterpolator>()?;
    m.add_class::<baselines::BlendshapeSolver>()?;
    m.add_class::<local_fit::LocalFits>()?;
    m.add_class::<local_fit::LocalSurface>()?;
    m.add_function(wrap_pyfunction!(baselines::check_marker_frames, m)?)?;
    m.add_function(wrap_pyfunction!(convert::check_count, m)?)?;
    m.add_function(wrap_pyfunction!(local_fit::shape_basis, m)?)?;
    m.add_function(wrap_pyfunction!(local_fit::blend_local, m)?)?;
    m.add_function(wrap_pyfunction!(missing_rows::fill_missing_rows, m)?)?;
    m.add_function(wrap_pyfunction!(surface::closest_surface_points, m)?)?;
    m.add_function(wrap_pyfunction!(threads::set_num_threads, m)?)?;
    m.add_function(wrap_pyfunction!(threads::get_num_threads, m)?)?;
    m.add("MAX_THREADS", threads::MAX_THREADS)?;
    m.add("MAGNITUDE_LIMIT", lgi_core::MAGNITUDE_LIMIT)?;
    Ok(())
}
