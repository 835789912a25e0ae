//! `lgi.BuildConfig`: the core's build parameters as a frozen Python class. Each field is
//! listed once, in the `build_config!` table below (name, type, docstring); its default is the
//! core's `BuildConfig::default()`, so no default is written on the Python side.

use crate::error::input_error;
use lgi_core::BuildConfig as CoreConfig;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

/// A field's conversion from Python, with the message users saw before the class existed.
trait Field: Sized {
    fn from_py(name: &str, v: &Bound<'_, PyAny>) -> PyResult<Self>;
}

impl Field for f64 {
    fn from_py(name: &str, v: &Bound<'_, PyAny>) -> PyResult<Self> {
        v.extract::<f64>()
            .map_err(|_| input_error(format!("BuildConfig.{name}: expected a number, got {v}")))
    }
}

impl Field for usize {
    fn from_py(name: &str, v: &Bound<'_, PyAny>) -> PyResult<Self> {
        v.extract::<usize>().map_err(|_| {
            input_error(format!(
                "BuildConfig.{name}: expected a non-negative integer, got {v}"
            ))
        })
    }
}

macro_rules! build_config {
    ($($(#[doc = $doc:expr])* $name:ident: $ty:ty,)*) => {
        /// Build parameters. Distances are relative to the neutral's bounding-box diagonal.
        /// Defaults are the core's; `replace(**changes)` gives a changed copy. Values are
        /// checked when a model is built.
        #[pyclass(frozen, module = "lgi._lgi")]
        pub struct BuildConfig {
            pub inner: CoreConfig,
        }

        impl BuildConfig {
            /// Sets the field `name` of `c` from a Python value.
            fn set(c: &mut CoreConfig, name: &str, v: &Bound<'_, PyAny>) -> PyResult<()> {
                match name {
                    $(stringify!($name) => c.$name = <$ty as Field>::from_py(name, v)?,)*
                    other => {
                        return Err(input_error(format!("BuildConfig has no field '{other}'")))
                    }
                }
                Ok(())
            }

            /// The fields as (name, Python value) pairs, in declaration order.
            fn items<'py>(&self, py: Python<'py>) -> PyResult<Vec<(&'static str, Bound<'py, PyAny>)>> {
                Ok(vec![$((
                    stringify!($name),
                    self.inner.$name.into_pyobject(py)?.into_any(),
                ),)*])
            }
        }

        #[pymethods]
        impl BuildConfig {
            #[new]
            #[pyo3(signature = ($($name = None),*))]
            #[allow(clippy::too_many_arguments)] // one keyword argument per field
            fn new($($name: Option<&Bound<'_, PyAny>>),*) -> PyResult<Self> {
                let mut inner = CoreConfig::default();
                $(if let Some(v) = $name {
                    Self::set(&mut inner, stringify!($name), v)?;
                })*
                Ok(BuildConfig { inner })
            }

            $(
                $(#[doc = $doc])*
                #[getter]
                fn $name(&self) -> $ty {
                    self.inner.$name
                }
            )*

            /// A copy with the given fields changed (like `dataclasses.replace`).
            #[pyo3(signature = (**changes))]
            fn replace(&self, changes: Option<&Bound<'_, PyDict>>) -> PyResult<BuildConfig> {
                let mut inner = self.inner.clone();
                if let Some(changes) = changes {
                    for (k, v) in changes.iter() {
                        let name: String = k.extract()?;
                        Self::set(&mut inner, &name, &v)?;
                    }
                }
                Ok(BuildConfig { inner })
            }

            /// The fields as a dict (like `dataclasses.asdict`).
            fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
                let d = PyDict::new(py);
                for (k, v) in self.items(py)? {
                    d.set_item(k, v)?;
                }
                Ok(d)
            }

            fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
                let fields: Vec<String> = self
                    .items(py)?
                    .into_iter()
                    .map(|(k, v)| Ok(format!("{k}={}", v.repr()?)))
                    .collect::<PyResult<_>>()?;
                Ok(format!("BuildConfig({})", fields.join(", ")))
            }

            fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
                other
                    .cast::<BuildConfig>()
                    .is_ok_and(|o| o.get().inner == self.inner)
            }

            fn __hash__(&self, py: Python<'_>) -> PyResult<isize> {
                let values: Vec<Bound<'_, PyAny>> = self.items(py)?.into_iter().map(|(_, v)| v).collect();
                PyTuple::new(py, values)?.hash()
            }

            /// Pickling and `copy`: the fields as keyword arguments of the constructor.
            fn __getnewargs_ex__<'py>(
                &self,
                py: Python<'py>,
            ) -> PyResult<(Bound<'py, PyTuple>, Bound<'py, PyDict>)> {
                Ok((PyTuple::empty(py), self.to_dict(py)?))
            }
        }
    };
}

build_config! {
    /// Markers farther than this from the neutral surface raise `MarkerError`.
    surface_tolerance: f64,
    /// Shapes moving a bundle less than this count as the neutral for that bundle.
    prune_motion: f64,
    /// Cloud points closer than this are merged (their shapes become aliases).
    duplicate_distance: f64,
    /// Nearest neighbours of each cloud point used to form tets.
    tet_neighbours: usize,
    /// Tets kept per bundle, best quality first.
    max_tets: usize,
    /// Tets below this quality (1 = regular tet) are dropped.
    min_quality: f64,
    /// Tets with a longer edge are dropped (relative).
    max_edge: f64,
    /// Barycentric tolerance of 'inside a tet'.
    containment_eps: f64,
    /// Nearest tets scored when a marker is outside every tet.
    projection_candidates: usize,
    /// Penalty per shape not shared with the previous frame's choice (relative to diagonal²).
    temporal_weight: f64,
    /// No weight between a bundle and a vertex whose surface path is this many times longer
    /// than the straight line (it goes around a hole: the mouth, an eye). inf disables.
    detour_ratio: f64,
}
