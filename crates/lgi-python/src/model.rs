//! `lgi._lgi.Model`: build and solve with the GIL released; the Python class `lgi.Model`
//! (python/lgi/model.py) wraps it with progress bars. A solve's arguments are converted in
//! `solve_args.rs` and its result packed in `result.rs`.

use crate::config::BuildConfig;
use crate::convert::{flat_to_array, float_array, point_sets, points, points_to_array, with_bytes};
use crate::dataset::Dataset;
use crate::error::{input_error, PyLgiError};
use crate::jaw::{frame_from_array, JawRig};
use crate::result::{self, SolveResult, SolveState};
use crate::solve_args;
use crate::threads;
use glam::{DMat3, DVec3};
use lgi_core::{
    JawBins, JawInput, JawParams, JawRig as CoreRig, Model as CoreModel, Sewn, SolveOptions,
};
use numpy::{PyArray3, PyArrayDyn};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use std::sync::Arc;

/// Two numpy arrays returned together.
type ArrayPair<'py> = (Bound<'py, PyArrayDyn<f64>>, Bound<'py, PyArrayDyn<f64>>);
type ArrayTriple<'py> = (
    Bound<'py, PyArrayDyn<f64>>,
    Bound<'py, PyArrayDyn<f64>>,
    Bound<'py, PyArrayDyn<f64>>,
);

/// A built LGI model (immutable, thread-safe).
#[pyclass(frozen, module = "lgi._lgi")]
pub struct Model {
    pub inner: Arc<CoreModel>,
}

#[pymethods]
impl Model {
    /// Builds a model (GIL released) with `config` (None: the defaults); `jaw_frame`
    /// (3, 3) is the jaw rig's rotation (columns: open, lateral, forward axes; None: identity);
    /// `jaw_bins` (edges over the jaw opening, radians) and `bin_overlap` bin the clouds of a
    /// jaw model. `marker_names` (B unique names; None: `m000`, `m001`, …) and `units` (the
    /// coordinates' length unit, e.g. `cm`; None: unknown) are kept with the model.
    #[staticmethod]
    #[pyo3(signature = (dataset, markers_rest, config=None, jaw_pivot=None, jaw_weights=None, shape_theta=None, jaw_bins=None, bin_overlap=0.0, jaw_frame=None, marker_names=None, units=None))]
    #[allow(clippy::too_many_arguments)]
    fn build(
        py: Python<'_>,
        dataset: &Dataset,
        markers_rest: &Bound<'_, PyAny>,
        config: Option<PyRef<'_, BuildConfig>>,
        jaw_pivot: Option<&Bound<'_, PyAny>>,
        jaw_weights: Option<&Bound<'_, PyAny>>,
        shape_theta: Option<&Bound<'_, PyAny>>,
        jaw_bins: Option<&Bound<'_, PyAny>>,
        bin_overlap: f64,
        jaw_frame: Option<&Bound<'_, PyAny>>,
        marker_names: Option<Vec<String>>,
        units: Option<String>,
    ) -> PyResult<Model> {
        let markers = points(markers_rest, "markers_rest", None, false)?;
        let names = marker_names.unwrap_or_else(|| lgi_core::default_marker_names(markers.len()));
        let cfg = config.map(|c| c.inner.clone()).unwrap_or_default();
        let data = dataset.inner.clone();
        if jaw_bins.is_some() && jaw_pivot.is_none() {
            return Err(input_error("jaw_bins: binning needs a jaw rig"));
        }
        if jaw_frame.is_some() && jaw_pivot.is_none() {
            return Err(input_error("jaw_frame: a frame needs a jaw rig"));
        }
        let jaw = match (jaw_pivot, jaw_weights, shape_theta) {
            (None, None, None) => None,
            (Some(p), Some(w), Some(t)) => {
                let pivot = float_array(p, "jaw_pivot", &[Some(3)])?;
                let nv = data.num_vertices();
                let weights = float_array(w, "jaw_weights", &[Some(nv)])?;
                let ns = data.num_shapes();
                let thetas = float_array(t, "shape_theta", &[Some(ns), Some(3)])?;
                let frame = match jaw_frame {
                    None => DMat3::IDENTITY,
                    Some(f) => frame_from_array(f, "jaw_frame")?,
                };
                let rig = CoreRig::with_frame(
                    DVec3::new(pivot[0], pivot[1], pivot[2]),
                    weights.iter().copied().collect(),
                    frame,
                )
                .map_err(PyLgiError)?;
                let th = thetas
                    .outer_iter()
                    .map(|r| JawParams::from_array([r[0], r[1], r[2]]))
                    .collect();
                let bins = match jaw_bins {
                    None => None,
                    Some(e) => Some(JawBins {
                        edges: float_array(e, "jaw_bins", &[None])?
                            .iter()
                            .copied()
                            .collect(),
                        overlap: bin_overlap,
                    }),
                };
                Some(JawInput {
                    rig,
                    shape_thetas: th,
                    bins,
                })
            }
            _ => {
                return Err(input_error(
                    "jaw: give jaw_pivot, jaw_weights and shape_theta together (or none)",
                ))
            }
        };
        let units = units.unwrap_or_default();
        let model = threads::detach(py, move || {
            CoreModel::build_shared(data, &markers, &cfg, jaw)
                .and_then(|m| m.with_labels(names, units))
        })
        .map_err(PyLgiError)?;
        warn_if_mostly_projected(py, &model)?;
        Ok(Model {
            inner: Arc::new(model),
        })
    }

    /// Loads a model written by `save` (GIL released).
    #[staticmethod]
    fn load(py: Python<'_>, path: std::path::PathBuf) -> PyResult<Model> {
        let model = threads::detach(py, move || lgi_core::load_model(&path)).map_err(PyLgiError)?;
        Ok(Model {
            inner: Arc::new(model),
        })
    }

    /// The bytes `save` writes (the versioned model format, checksum included).
    fn to_bytes<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        let model = self.inner.clone();
        let bytes = py.detach(move || lgi_core::model_to_bytes(&model));
        PyBytes::new(py, &bytes)
    }

    /// A model from `to_bytes`'s bytes (or a model file's), with every check of `load`
    /// (GIL released); corrupt bytes raise `lgi.ModelFormatError`.
    #[staticmethod]
    fn from_bytes(py: Python<'_>, data: &Bound<'_, PyAny>) -> PyResult<Model> {
        let model = with_bytes(data, "Model.from_bytes", |bytes| {
            threads::detach(py, || lgi_core::model_from_bytes(bytes)).map_err(PyLgiError)
        })??;
        Ok(Model {
            inner: Arc::new(model),
        })
    }

    /// Pickles as the model file's bytes (`from_bytes` rebuilds it, checked like `load`).
    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyAny>, (Bound<'py, PyBytes>,))> {
        let bytes = slf.get().to_bytes(slf.py());
        Ok((slf.get_type().getattr("from_bytes")?, (bytes,)))
    }

    /// Writes the model to `path` (GIL released).
    fn save(&self, py: Python<'_>, path: std::path::PathBuf) -> PyResult<()> {
        let model = self.inner.clone();
        py.detach(move || lgi_core::save_model(&model, &path))
            .map_err(PyLgiError)?;
        Ok(())
    }

    /// Number of bundles B.
    #[getter]
    fn num_bundles(&self) -> usize {
        self.inner.num_bundles()
    }

    /// Number of vertices V.
    #[getter]
    fn num_vertices(&self) -> usize {
        self.inner.dataset().num_vertices()
    }

    /// Bounding-box diagonal of the neutral (the unit of every relative tolerance).
    #[getter]
    fn diagonal(&self) -> f64 {
        self.inner.diagonal()
    }

    /// The dataset (shared, not copied).
    #[getter]
    fn dataset(&self) -> Dataset {
        Dataset {
            inner: self.inner.dataset_shared(),
        }
    }

    /// Solves frames (F, B, 3) into a `SolveResult`. `progress(f)` is called after each
    /// frame with the GIL held. `temporal=False` solves frames independently (in parallel).
    /// `jaw`: `"auto"` (the fit's pose with a jaw rig, none without), `"fit"`, `"track"`, an
    /// (F, 3) array of poses, or None (the rest pose). `out`: a C-contiguous, writeable
    /// float64 (F, V, 3) array that receives the vertices (and is returned as `vertices`)
    /// instead of a new one. `fit` offers every bundle the frame's global blendshape fit
    /// beside its tets (None: exactly when `marker_noise` is given); `marker_noise` (data
    /// units) solves noise-aware (None: every marker interpolated as given); `previous` (a
    /// temporal solve's `state`) continues that solve: the first frame prefers its choices
    /// and keeps its jaw bin, so chunks solved in turn equal one call. `unbounded_fit`: the
    /// frame's global fit without the [0, 1] box (at the pose the boxed fit refined);
    /// `take_prior` (`(mean, factor, noise_variance)`, with `unbounded_fit`): the take's own
    /// prior on its weights in place of its ridge (`lgi.take_prior`). `surface`: `"mesh"`
    /// (every vertex; None too), `"markers"` (the markers' positions on the sewn surfaces,
    /// the same bits, no vertex written) or `"none"` (no choice and no sewing: the targets,
    /// fits and poses, for a caller that makes the surface itself); with either of the last
    /// two, `vertices` is `out` as given, or an empty (F, 0, 3) array.
    #[pyo3(signature = (frames, progress=None, temporal=true, jaw=None, smooth_window=0, out=None, fit=None, marker_noise=None, previous=None, unbounded_fit=false, take_prior=None, surface=None))]
    #[allow(clippy::too_many_arguments)]
    fn solve<'py>(
        &self,
        py: Python<'py>,
        frames: &Bound<'py, PyAny>,
        progress: Option<Py<PyAny>>,
        temporal: bool,
        jaw: Option<&Bound<'py, PyAny>>,
        #[pyo3(from_py_with = solve_args::smooth_window)] smooth_window: usize,
        out: Option<&Bound<'py, PyAny>>,
        #[pyo3(from_py_with = solve_args::fit)] fit: Option<bool>,
        #[pyo3(from_py_with = solve_args::marker_noise)] marker_noise: Option<f64>,
        previous: Option<PyRef<'py, SolveState>>,
        unbounded_fit: bool,
        #[pyo3(from_py_with = solve_args::take_prior)] take_prior: Option<
            std::sync::Arc<lgi_core::TakePrior>,
        >,
        surface: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<SolveResult> {
        let b = self.inner.num_bundles();
        let surface = solve_args::sewn(surface)?;
        let frames = point_sets(frames, "frames", ("frame", "bundle"), Some(b), true)?;
        let options = SolveOptions {
            jaw: solve_args::jaw_pose(jaw, &self.inner, frames.len())?,
            unbounded_fit,
            take_prior,
            sewn: surface,
            ..SolveOptions::new(temporal, smooth_window, fit, marker_noise)
        };
        let previous = previous.map(|p| p.inner.clone());
        let (nf, nv) = (frames.len(), self.inner.dataset().num_vertices());
        // The vertices go straight into the numpy array the caller gets (no copy, no second
        // F × V × 3 buffer).
        let vertices = match (out, surface) {
            (Some(o), _) => solve_args::output_array(o, [nf, nv, 3])?,
            (None, Sewn::Mesh) => PyArray3::<f64>::zeros(py, [nf, nv, 3], false),
            (None, Sewn::Markers | Sewn::Nothing) => PyArray3::<f64>::zeros(py, [nf, 0, 3], false),
        };
        let solved = solve_args::with_points_mut(&vertices, |out| {
            let model = self.inner.clone();
            solve_watching(py, progress.as_ref(), |on_frame| {
                model.solve(&frames, &options, previous.as_ref(), out, on_frame)
            })
        })?;
        let ns = self.inner.dataset().num_shapes();
        result::pack(py, &solved, vertices, b, ns)
    }

    /// Each frame's global-fit residual (F, B, 3; NaN for a missing marker, in the jaw
    /// bin's space) with the jaw pose `jaw` as in `solve` (a pose from the fit is refined),
    /// and the fit's rank at the bundles per frame (F,): frames independent, GIL released.
    #[pyo3(signature = (frames, jaw=None))]
    fn fit_residuals<'py>(
        &self,
        py: Python<'py>,
        frames: &Bound<'py, PyAny>,
        jaw: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<ArrayPair<'py>> {
        let b = self.inner.num_bundles();
        let frames = point_sets(frames, "frames", ("frame", "bundle"), Some(b), true)?;
        let pose = solve_args::jaw_pose(jaw, &self.inner, frames.len())?;
        let model = self.inner.clone();
        let fitted = py
            .detach(|| model.fit_residuals(&frames, &pose))
            .map_err(PyLgiError)?;
        let nf = fitted.residuals.len();
        let flat: Vec<f64> = fitted
            .residuals
            .iter()
            .flatten()
            .flat_map(|p| [p.x, p.y, p.z])
            .collect();
        let ranks: Vec<f64> = fitted.ranks.iter().map(|&r| r as f64).collect();
        Ok((
            flat_to_array(py, flat, &[nf, b, 3])?,
            flat_to_array(py, ranks, &[nf])?,
        ))
    }

    /// What the global fit of `frames` fits, for a take's prior (`lgi.take_prior`): jaw bin
    /// 0's fit matrix (3B, S; row 3n + d coordinate d of bundle n), each frame's markers in
    /// its bin's space less the bundles' rest there (F, 3B; NaN: missing) with the jaw pose
    /// `jaw` as in `solve`, and each frame's bin (F,). GIL released.
    #[pyo3(signature = (frames, jaw=None))]
    fn fit_rows<'py>(
        &self,
        py: Python<'py>,
        frames: &Bound<'py, PyAny>,
        jaw: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<ArrayTriple<'py>> {
        let b = self.inner.num_bundles();
        let frames = point_sets(frames, "frames", ("frame", "bundle"), Some(b), true)?;
        let pose = solve_args::jaw_pose(jaw, &self.inner, frames.len())?;
        let model = self.inner.clone();
        let (fitted, matrix) = py
            .detach(|| {
                let matrix = model.fit_matrix(0).ok_or_else(|| {
                    lgi_core::LgiError::Input("fit rows need a dataset with shapes".into())
                })?;
                Ok::<_, lgi_core::LgiError>((model.fit_residuals(&frames, &pose)?, matrix))
            })
            .map_err(PyLgiError)?;
        let (a, rest) = matrix;
        let nf = fitted.targets.len();
        let s = a.len() / (3 * b).max(1);
        let offsets: Vec<f64> = fitted
            .targets
            .iter()
            .flat_map(|t| t.iter().zip(&rest).flat_map(|(p, r)| (*p - *r).to_array()))
            .collect();
        let bins: Vec<f64> = fitted.bins.iter().map(|&x| x as f64).collect();
        Ok((
            flat_to_array(py, a, &[3 * b, s])?,
            flat_to_array(py, offsets, &[nf, 3 * b])?,
            flat_to_array(py, bins, &[nf])?,
        ))
    }

    /// Bundle surface positions (F, B, 3) of meshes (F, V, 3) with the neutral's topology.
    fn bundle_positions<'py>(
        &self,
        py: Python<'py>,
        meshes: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let nv = self.inner.dataset().num_vertices();
        let sets = point_sets(meshes, "meshes", ("mesh", "vertex"), Some(nv), false)?;
        let b = self.inner.num_bundles();
        let mut out = Vec::with_capacity(sets.len() * b * 3);
        for pts in &sets {
            let bp = self.inner.bundle_positions(pts).map_err(PyLgiError)?;
            out.extend(bp.iter().flat_map(|p| [p.x, p.y, p.z]));
        }
        flat_to_array(py, out, &[sets.len(), b, 3])
    }

    /// Per-bundle statistics: dict of arrays `points`, `tets`, `index_bytes` (B,).
    fn bundle_stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let st = self.inner.bundle_stats();
        let d = PyDict::new(py);
        let n = st.len();
        d.set_item(
            "points",
            flat_to_array(py, st.iter().map(|s| s.points as i64).collect(), &[n])?,
        )?;
        d.set_item(
            "tets",
            flat_to_array(py, st.iter().map(|s| s.tets as i64).collect(), &[n])?,
        )?;
        d.set_item(
            "index_bytes",
            flat_to_array(py, st.iter().map(|s| s.index_bytes as i64).collect(), &[n])?,
        )?;
        Ok(d)
    }

    /// Sewing weights as CSR arrays: dict `indptr` (V+1,), `indices`, `data` (bundle columns).
    fn sew_weights<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let w = self.inner.sew_weights();
        let d = PyDict::new(py);
        let n = w.row_start.len();
        d.set_item(
            "indptr",
            flat_to_array(py, w.row_start.iter().map(|&x| x as i64).collect(), &[n])?,
        )?;
        d.set_item(
            "indices",
            flat_to_array(
                py,
                w.cols.iter().map(|&x| x as i64).collect(),
                &[w.cols.len()],
            )?,
        )?;
        d.set_item("data", flat_to_array(py, w.vals.clone(), &[w.vals.len()])?)?;
        Ok(d)
    }

    /// Natural neighbours of each bundle (list of lists).
    fn neighbours(&self) -> Vec<Vec<u32>> {
        self.inner.neighbours().to_vec()
    }

    /// Bundles' closest points: dict `triangles` (B,) and `barycentrics` (B, 3).
    fn bundle_surface_points<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let bs = self.inner.bundles();
        let d = PyDict::new(py);
        let t: Vec<i64> = bs.iter().map(|b| b.triangle as i64).collect();
        d.set_item("triangles", flat_to_array(py, t, &[bs.len()])?)?;
        let w: Vec<f64> = bs.iter().flat_map(|b| b.bary).collect();
        d.set_item("barycentrics", flat_to_array(py, w, &[bs.len(), 3])?)?;
        Ok(d)
    }

    /// Bundles' UV positions (B, 2) in the sewing space.
    fn bundle_uvs<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let uv = &self.inner.sewing_space().bundle_uv;
        flat_to_array(
            py,
            uv.iter().flat_map(|p| [p.x, p.y]).collect(),
            &[uv.len(), 2],
        )
    }

    /// The jaw setup besides the rig (`jaw_rig`) as a dict: `shape_theta` (S, 3),
    /// `bundle_weights` (B,) and, for a binned model, `bin_edges`, `bin_overlap` and
    /// `bin_members`; None for a model without a jaw rig.
    fn jaw<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(setup) = self.inner.jaw() else {
            return Ok(None);
        };
        let j = &setup.input;
        let d = PyDict::new(py);
        let t: Vec<f64> = j.shape_thetas.iter().flat_map(|t| t.to_array()).collect();
        d.set_item(
            "shape_theta",
            flat_to_array(py, t, &[j.shape_thetas.len(), 3])?,
        )?;
        let bw = setup.bundle_weights.clone();
        d.set_item(
            "bundle_weights",
            flat_to_array(py, bw, &[setup.bundle_weights.len()])?,
        )?;
        if let Some(bins) = &j.bins {
            let n = bins.edges.len();
            d.set_item("bin_edges", flat_to_array(py, bins.edges.clone(), &[n])?)?;
            d.set_item("bin_overlap", bins.overlap)?;
            let members: Vec<Vec<u32>> = self
                .inner
                .lookups()
                .iter()
                .map(|l| l.members().to_vec())
                .collect();
            d.set_item("bin_members", members)?;
        }
        Ok(Some(d))
    }

    /// The jaw rig the model was built with (a copy), or None.
    #[getter]
    fn jaw_rig(&self) -> Option<JawRig> {
        self.inner.jaw().map(|j| JawRig {
            inner: j.input.rig.clone(),
        })
    }

    /// The build parameters (also of a loaded model).
    #[getter]
    fn config(&self) -> BuildConfig {
        BuildConfig {
            inner: self.inner.config().clone(),
        }
    }

    /// Each marker's name (B); `m000`, `m001`, … when built without names.
    #[getter]
    fn marker_names(&self) -> Vec<String> {
        self.inner.marker_names().to_vec()
    }

    /// The coordinates' length unit given at build (`cm`, `mm`, …); None when not given.
    #[getter]
    fn units(&self) -> Option<String> {
        let u = self.inner.units();
        (!u.is_empty()).then(|| u.to_string())
    }

    /// Marker rest positions (B, 3).
    #[getter]
    fn markers_rest<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        points_to_array(py, self.inner.markers_rest())
    }
}

/// Warns (`lgi.LgiWarning`) when the build left more than half of the markers whose clouds
/// could hold a tet (4+ points) without any: a config like `min_quality=2` that makes a model
/// which only projects should not pass without a word. (Refusing it in the core would also
/// refuse legitimately flat datasets.)
fn warn_if_mostly_projected(py: Python<'_>, model: &CoreModel) -> PyResult<()> {
    let stats = model.bundle_stats();
    let could = stats.iter().filter(|s| s.points >= 4).count();
    let without = stats
        .iter()
        .filter(|s| s.points >= 4 && s.tets == 0)
        .count();
    if could == 0 || without * 2 <= could {
        return Ok(());
    }
    let c = model.config();
    let msg = format!(
        "{without} of the {could} markers whose clouds could hold tets have none: they will \
         only be projected, never interpolated by the dataset's local geometry; BuildConfig is \
         probably too strict (min_quality {}, max_edge {}, max_tets {}, tet_neighbours {})",
        c.min_quality, c.max_edge, c.max_tets, c.tet_neighbours
    );
    crate::error::lgi_warning(py, msg)
}

/// The payload that unwinds a solve stopped by Ctrl-C or a failing progress callback.
struct SolveStopped;

/// Runs `solve` with the GIL released ([`threads::detach_watching`]), handing it the hook it
/// calls after each frame: the hook takes the GIL, stops on Ctrl-C (or an interrupt the
/// watching thread caught) and calls `progress(f)`; a raised exception stops the solve and is
/// raised here.
fn solve_watching<T: Send>(
    py: Python<'_>,
    progress: Option<&Py<PyAny>>,
    solve: impl FnOnce(&mut dyn FnMut(usize)) -> lgi_core::Result<T> + Send,
) -> PyResult<T> {
    let mut stopped: Option<PyErr> = None;
    let interrupt = std::sync::Mutex::new(None);
    let solved = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        threads::detach_watching(py, &interrupt, || {
            solve(&mut |f| {
                // Ctrl-C and a failing callback stop the solve after this frame.
                let called = Python::attach(|py| {
                    let caught = interrupt.lock().map(|mut i| i.take());
                    if let Ok(Some(e)) = caught {
                        return Err(e);
                    }
                    py.check_signals()?;
                    match progress {
                        Some(cb) => cb.call1(py, (f,)).map(drop),
                        None => Ok(()),
                    }
                });
                if let Err(e) = called {
                    stopped = Some(e);
                    // The core's progress hook cannot fail: unwind out of the solve with a
                    // private payload (resume_unwind runs no panic hook, so nothing is
                    // printed) and raise the Python error below.
                    std::panic::resume_unwind(Box::new(SolveStopped));
                }
            })
        })
    }));
    // A Ctrl-C the watcher caught after the work's last progress call was never taken by
    // it: raise it now rather than drop it (its signal is consumed).
    let caught = interrupt.into_inner().unwrap_or_else(|e| e.into_inner());
    match (solved, stopped.or(caught)) {
        (_, Some(e)) => Err(e),
        (Ok(r), None) => Ok(r.map_err(PyLgiError)?),
        (Err(panic), None) => std::panic::resume_unwind(panic),
    }
}
