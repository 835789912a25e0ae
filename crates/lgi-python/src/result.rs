//! `lgi._lgi.SolveResult`, `Choices` and `SolveState`: what a solve returns, packed once from
//! the core's per-frame [`FrameInfo`] into numpy arrays (`lgi.SolveResult` and `lgi.Choices`
//! are these classes). The baselines build results of the same class from their own arrays.

use crate::convert::flat_to_array;
use lgi_core::{FrameInfo, NO_TET};
use numpy::PyArray3;
use pyo3::prelude::*;
use pyo3::types::PyTuple;

/// Output of `Model.solve` (F frames, B markers, V vertices, S dataset shapes).
#[pyclass(frozen, module = "lgi._lgi")]
pub struct SolveResult {
    /// (F, V, 3) reconstructed meshes.
    #[pyo3(get)]
    vertices: Py<PyAny>,
    /// (F, B) distance from each marker to the reconstructed surface (0 where missing).
    #[pyo3(get)]
    bundle_residuals: Py<PyAny>,
    /// (F, B, 3) the markers' surface positions on the result (estimates where missing).
    #[pyo3(get)]
    bundle_positions: Py<PyAny>,
    /// (F, B) markers that were NaN in the input.
    #[pyo3(get)]
    missing: Py<PyAny>,
    /// Per frame and marker: the local geometry each marker chose (`Choices`).
    #[pyo3(get)]
    choices: Py<PyAny>,
    /// (F, 3) jaw poses used (open, lateral, forward), None when solved without a jaw.
    #[pyo3(get)]
    jaw_theta: Option<Py<PyAny>>,
    /// (F,) jaw-opening bin each frame was looked up in (0 for an unbinned jaw model), None
    /// when solved without a jaw.
    #[pyo3(get)]
    jaw_bin: Option<Py<PyAny>>,
    /// (F, B) how far noise-aware solving (`marker_noise=`) moved each marker before the
    /// surface interpolated it (data units; 0 when exact).
    #[pyo3(get)]
    marker_corrections: Option<Py<PyAny>>,
    /// (F, S) each frame's global blendshape fit; None when no fit was made (`fit` off, or a
    /// dataset without shapes).
    #[pyo3(get)]
    fit_weights: Option<Py<PyAny>>,
    /// What the chunk after a temporal solve needs to continue it (`solve_iter` passes it on);
    /// None for no frames, and after unpickling (a pickled result keeps its arrays only).
    #[pyo3(get)]
    state: Option<Py<SolveState>>,
    /// (F, B) missing samples the solve filled from the take (`lgi.solve.gaps`; still
    /// `missing`); None when the frames were solved each alone.
    #[pyo3(get)]
    filled: Option<Py<PyAny>>,
    /// (F, B) samples a repair changed (`lgi.solve.repair`); None when no repair was made.
    #[pyo3(get)]
    repaired: Option<Py<PyAny>>,
    /// The marker faults repaired before the solve (`lgi.solve.diagnose.Finding`s), a tuple;
    /// None when the solve did not look for them (`repair=False`, frames solved each alone).
    #[pyo3(get)]
    repairs: Option<Py<PyAny>>,
    /// How many directions of the take's own motion filled its dropouts
    /// (`lgi.solve.gaps.fill_motion`); None where each marker's neighbours filled them, or
    /// nothing was filled (`filled` None or all False).
    #[pyo3(get)]
    fill_rank: Option<usize>,
    /// (F, B, 3) how far a steady solve moved its surface at each marker to follow it where
    /// the marker is more than 5 sigma from where the solve put it (`lgi.solve.steady`): the
    /// surface's markers are `bundle_positions + marker_pulls`; None where it did not.
    #[pyo3(get)]
    marker_pulls: Option<Py<PyAny>>,
}

#[pymethods]
impl SolveResult {
    /// A result from its arrays (what the baselines return; `Model.solve` makes its own).
    #[new]
    #[pyo3(signature = (vertices, bundle_residuals, bundle_positions, missing, choices, jaw_theta=None, jaw_bin=None, marker_corrections=None, fit_weights=None, state=None, filled=None, repaired=None, repairs=None, fill_rank=None, marker_pulls=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        vertices: Py<PyAny>,
        bundle_residuals: Py<PyAny>,
        bundle_positions: Py<PyAny>,
        missing: Py<PyAny>,
        choices: Py<PyAny>,
        jaw_theta: Option<Py<PyAny>>,
        jaw_bin: Option<Py<PyAny>>,
        marker_corrections: Option<Py<PyAny>>,
        fit_weights: Option<Py<PyAny>>,
        state: Option<Py<SolveState>>,
        filled: Option<Py<PyAny>>,
        repaired: Option<Py<PyAny>>,
        repairs: Option<Py<PyAny>>,
        fill_rank: Option<usize>,
        marker_pulls: Option<Py<PyAny>>,
    ) -> Self {
        SolveResult {
            vertices,
            bundle_residuals,
            bundle_positions,
            missing,
            choices,
            jaw_theta,
            jaw_bin,
            marker_corrections,
            fit_weights,
            state,
            filled,
            repaired,
            repairs,
            fill_rank,
            marker_pulls,
        }
    }

    /// Pickles as its arrays (the state that continues a solve stays behind).
    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        let py = slf.py();
        let r = slf.get();
        // Absent optionals (and the state, which stays behind) are Python's None.
        let opt = |x: &Option<Py<PyAny>>| x.as_ref().map_or_else(|| py.None(), |a| a.clone_ref(py));
        let args = PyTuple::new(
            py,
            [
                r.vertices.clone_ref(py),
                r.bundle_residuals.clone_ref(py),
                r.bundle_positions.clone_ref(py),
                r.missing.clone_ref(py),
                r.choices.clone_ref(py),
                opt(&r.jaw_theta),
                opt(&r.jaw_bin),
                opt(&r.marker_corrections),
                opt(&r.fit_weights),
                py.None(),
                opt(&r.filled),
                opt(&r.repaired),
                opt(&r.repairs),
                r.fill_rank.into_pyobject(py)?.into_any().unbind(),
                opt(&r.marker_pulls),
            ],
        )?;
        Ok((slf.get_type().into_any(), args))
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let shape = |a: &Py<PyAny>| {
            a.bind(py)
                .getattr("shape")
                .and_then(|s| s.repr())
                .map_or_else(|_| "?".to_string(), |s| s.to_string())
        };
        format!(
            "SolveResult(vertices {}, markers {}, jaw {})",
            shape(&self.vertices),
            shape(&self.missing),
            if self.jaw_theta.is_some() {
                "posed"
            } else {
                "none"
            }
        )
    }
}

/// Per frame and marker: the local geometry each marker chose.
#[pyclass(frozen, module = "lgi._lgi")]
pub struct Choices {
    /// (F, B, 4) dataset shape indices; -1 is the neutral (or an unused slot).
    #[pyo3(get)]
    shapes: Py<PyAny>,
    /// (F, B, 4) convex weights of `shapes` (all 0 for a missing marker).
    #[pyo3(get)]
    weights: Py<PyAny>,
    /// (F, B) tet index in the marker's index, -1 when none was used.
    #[pyo3(get)]
    tets: Py<PyAny>,
    /// (F, B) True when the marker was outside every tet and was projected.
    #[pyo3(get)]
    projected: Py<PyAny>,
    /// (F, B) True where the marker took the frame's global blendshape fit instead of a tet
    /// (its `shapes`/`weights` are then unused; the fit is `SolveResult.fit_weights`).
    #[pyo3(get)]
    fit: Option<Py<PyAny>>,
}

#[pymethods]
impl Choices {
    /// Choices from their arrays (what the baselines return).
    #[new]
    #[pyo3(signature = (shapes, weights, tets, projected, fit=None))]
    fn new(
        shapes: Py<PyAny>,
        weights: Py<PyAny>,
        tets: Py<PyAny>,
        projected: Py<PyAny>,
        fit: Option<Py<PyAny>>,
    ) -> Self {
        Choices {
            shapes,
            weights,
            tets,
            projected,
            fit,
        }
    }

    /// (F, B) True when the marker was inside a tet (interpolated exactly).
    #[getter]
    fn inside<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.projected.bind(py).call_method0("__invert__")
    }

    /// Pickles as its arrays.
    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        let py = slf.py();
        let c = slf.get();
        let args = (
            c.shapes.clone_ref(py),
            c.weights.clone_ref(py),
            c.tets.clone_ref(py),
            c.projected.clone_ref(py),
            c.fit.as_ref().map(|f| f.clone_ref(py)),
        )
            .into_pyobject(py)?;
        Ok((slf.get_type().into_any(), args))
    }
}

/// The last frame's choices and jaw bin of a temporal solve: pass it as the next chunk's
/// `previous` to continue the solve (opaque).
#[pyclass(frozen, module = "lgi._lgi")]
pub struct SolveState {
    pub inner: lgi_core::FrameState,
}

/// The result of a solve of `solved.len()` frames of `b` markers on a dataset of `ns` shapes,
/// its vertices already in `vertices`. Shape ids become Python's (the core's 0, the neutral,
/// is -1; k ≥ 1 is dataset shape k − 1).
pub fn pack(
    py: Python<'_>,
    solved: &[FrameInfo],
    vertices: Bound<'_, PyArray3<f64>>,
    b: usize,
    ns: usize,
) -> PyResult<SolveResult> {
    let nf = solved.len();
    let mut res = Vec::with_capacity(nf * b);
    let mut pos = Vec::with_capacity(nf * b * 3);
    let mut shapes = Vec::with_capacity(nf * b * 4);
    let mut weights = Vec::with_capacity(nf * b * 4);
    let mut tets = Vec::with_capacity(nf * b);
    let mut projected = Vec::with_capacity(nf * b);
    let mut missing = Vec::with_capacity(nf * b);
    let mut took_fit = Vec::with_capacity(nf * b);
    let mut corrections = Vec::with_capacity(nf * b);
    // Every frame has a fit or none has (no fit asked for, or a dataset without shapes).
    let mut fit_weights = Some(Vec::with_capacity(nf * ns));
    let bins: Vec<i64> = solved.iter().map(|fr| fr.bin as i64).collect();
    let poses: Option<Vec<f64>> = solved
        .iter()
        .map(|fr| fr.theta.map(|t| t.to_array()))
        .collect::<Option<Vec<_>>>()
        .map(|t| t.into_iter().flatten().collect());
    for fr in solved {
        res.extend_from_slice(&fr.residuals);
        match fr.corrections.len() {
            0 => corrections.extend(std::iter::repeat_n(0.0, b)),
            _ => corrections.extend_from_slice(&fr.corrections),
        }
        match (fr.fit_weights.get(1..), &mut fit_weights) {
            (Some(w), Some(all)) if w.len() == ns => all.extend_from_slice(w),
            _ => fit_weights = None,
        }
        pos.extend(fr.bundle_positions.iter().flat_map(|p| [p.x, p.y, p.z]));
        for c in &fr.choices {
            match c {
                Some(c) => {
                    shapes.extend(c.shapes.iter().map(|&s| s as i64 - 1));
                    weights.extend_from_slice(&c.weights);
                    tets.push(if c.tet == NO_TET { -1 } else { c.tet as i64 });
                    projected.push(c.projected);
                    missing.push(false);
                    took_fit.push(c.fit);
                }
                None => {
                    shapes.extend([-1i64; 4]);
                    weights.extend([0.0; 4]);
                    tets.push(-1);
                    projected.push(false);
                    missing.push(true);
                    took_fit.push(false);
                }
            }
        }
    }
    let array = |a: Bound<'_, PyAny>| a.unbind();
    let choices = Choices {
        shapes: array(flat_to_array(py, shapes, &[nf, b, 4])?.into_any()),
        weights: array(flat_to_array(py, weights, &[nf, b, 4])?.into_any()),
        tets: array(flat_to_array(py, tets, &[nf, b])?.into_any()),
        projected: array(flat_to_array(py, projected, &[nf, b])?.into_any()),
        fit: Some(array(flat_to_array(py, took_fit, &[nf, b])?.into_any())),
    };
    let jaw_theta = match poses.filter(|_| nf > 0) {
        Some(t) => Some(array(flat_to_array(py, t, &[nf, 3])?.into_any())),
        None => None,
    };
    // A bin means something only with a jaw pose.
    let jaw_bin = match jaw_theta {
        Some(_) => Some(array(flat_to_array(py, bins, &[nf])?.into_any())),
        None => None,
    };
    Ok(SolveResult {
        vertices: vertices.into_any().unbind(),
        bundle_residuals: array(flat_to_array(py, res, &[nf, b])?.into_any()),
        bundle_positions: array(flat_to_array(py, pos, &[nf, b, 3])?.into_any()),
        missing: array(flat_to_array(py, missing, &[nf, b])?.into_any()),
        choices: Py::new(py, choices)?.into_any(),
        jaw_theta,
        jaw_bin,
        marker_corrections: Some(array(flat_to_array(py, corrections, &[nf, b])?.into_any())),
        fit_weights: match fit_weights {
            Some(w) => Some(array(flat_to_array(py, w, &[nf, ns])?.into_any())),
            None => None,
        },
        state: solved
            .last()
            .map(|fr| Py::new(py, SolveState { inner: fr.state() }))
            .transpose()?,
        filled: None,
        repaired: None,
        repairs: None,
        fill_rank: None,
        marker_pulls: None,
    })
}
