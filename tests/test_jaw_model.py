"""Jaw articulation inside the model (paper Eq. 2): shapes unskinned before indexing, frames
unskinned with their jaw pose, results reskinned, markers still interpolated exactly."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import lgi
from lgi.jaw import JawRig, estimate_rig


@pytest.fixture(scope="module")
def jaw_model(sample, sample_dataset):  # type: ignore[no-untyped-def]
    rig = JawRig(pivot=sample.jaw_pivot, weights=sample.jaw_weights)
    return lgi.Model.build(
        sample_dataset, sample.markers_rest, jaw=rig, shape_theta=sample.shape_jaw_theta
    )


def test_jaw_open_shape_is_reconstructed_exactly_through_unskin_and_reskin(sample, jaw_model):  # type: ignore[no-untyped-def]
    k = sample.names.index("jawOpen")
    mesh = sample.neutral + sample.shapes[k].astype(np.float64)
    frames = jaw_model.bundle_positions(mesh)[None]
    res = jaw_model.solve(frames, jaw=sample.shape_jaw_theta[k : k + 1], quiet=True)
    err = np.linalg.norm(res.vertices[0] - mesh, axis=1)
    # Exact where the jaw weight is 0 or 1; where it blends (the mouth corners) a marker's
    # unskinning uses its interpolated weight, and the residual pass spreads the difference.
    blended = (sample.jaw_weights > 0) & (sample.jaw_weights < 1)
    assert np.median(err) < 1e-6
    assert err[~blended].max() < 0.02 and err.max() < 0.02


def test_jaw_handling_beats_no_jaw_on_the_sample_performance_and_keeps_markers_exact(
    sample, sample_model, jaw_model
):  # type: ignore[no-untyped-def]
    plain = sample_model.solve(sample.performance, quiet=True)
    jawed = jaw_model.solve(sample.performance, jaw=sample.jaw_theta, quiet=True)
    e_plain = np.linalg.norm(plain.vertices - sample.truth, axis=2)
    e_jaw = np.linalg.norm(jawed.vertices - sample.truth, axis=2)
    assert e_jaw.mean() < e_plain.mean()
    assert np.percentile(e_jaw, 95) < np.percentile(e_plain, 95)
    assert jawed.bundle_residuals.max() <= 1e-6 * jaw_model.diagonal
    np.testing.assert_array_equal(jawed.jaw_theta, sample.jaw_theta)


def test_tracked_jaw_recovers_the_sample_jaw_within_a_few_degrees(sample, sample_dataset):  # type: ignore[no-untyped-def]
    rig, theta = estimate_rig(
        sample.neutral, sample.shapes, sample.names, triangles=sample.triangles
    )
    model = lgi.Model.build(sample_dataset, sample.markers_rest, jaw=rig, shape_theta=theta)
    res = model.solve(sample.performance, jaw="track", quiet=True)
    err_deg = np.degrees(np.abs(res.jaw_theta[:, :2] - sample.jaw_theta[:, :2]))
    assert err_deg.mean() < 0.5 and err_deg.max() < 3.0
    assert res.bundle_residuals.max() <= 1e-6 * model.diagonal


def test_jaw_model_save_load_round_trip(tmp_path: Path, sample, jaw_model):  # type: ignore[no-untyped-def]
    path = tmp_path / "jaw.lgi"
    jaw_model.save(path)
    loaded = lgi.Model.load(path)
    assert loaded.jaw_rig is not None
    np.testing.assert_array_equal(loaded.jaw_rig.weights, sample.jaw_weights)
    a = jaw_model.solve(sample.performance[:8], jaw=sample.jaw_theta[:8], quiet=True)
    b = loaded.solve(sample.performance[:8], jaw=sample.jaw_theta[:8], quiet=True)
    np.testing.assert_array_equal(a.vertices, b.vertices)


def test_jaw_arguments_are_checked(sample, sample_dataset, sample_model, jaw_model):  # type: ignore[no-untyped-def]
    with pytest.raises(lgi.InputError, match="without a jaw rig"):
        sample_model.solve(sample.performance[:2], jaw="track")
    with pytest.raises(lgi.InputError, match="shape_theta"):
        lgi.Model.build(
            sample_dataset,
            sample.markers_rest,
            jaw=JawRig(pivot=sample.jaw_pivot, weights=sample.jaw_weights),
        )
    with pytest.raises(lgi.InputError, match="jaw"):
        jaw_model.solve(sample.performance[:2], jaw=np.zeros((3, 3)))


def test_smoothing_reduces_jitter_and_keeps_markers_exact(sample, jaw_model):  # type: ignore[no-untyped-def]
    def jitter(v: np.ndarray) -> float:
        return float(np.linalg.norm(v[2:] - 2 * v[1:-1] + v[:-2], axis=2).mean())

    raw = jaw_model.solve(sample.performance, jaw=sample.jaw_theta, quiet=True)
    smooth = jaw_model.solve(sample.performance, jaw=sample.jaw_theta, smooth_window=5, quiet=True)
    assert jitter(smooth.vertices) < jitter(raw.vertices)
    assert smooth.bundle_residuals.max() <= 1e-6 * jaw_model.diagonal
    with pytest.raises(lgi.InputError, match="smooth_window"):
        jaw_model.solve(sample.performance[:3], smooth_window=-1)
