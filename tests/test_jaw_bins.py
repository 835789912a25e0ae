"""Point clouds binned by jaw opening: each bin's shapes re-posed to its reference opening, each
frame looked up in the bin of its opening (with hysteresis), markers still interpolated exactly."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import lgi
from lgi.solve.jaw import JawRig

OVERLAP = 0.05


@pytest.fixture(scope="module")
def rig(sample) -> JawRig:  # type: ignore[no-untyped-def]
    return JawRig(pivot=sample.jaw_pivot, weights=sample.jaw_weights)


@pytest.fixture(scope="module")
def binned(sample, sample_dataset, rig):  # type: ignore[no-untyped-def]
    return lgi.Model.build(
        sample_dataset,
        sample.markers_rest,
        jaw=rig,
        shape_theta=sample.shape_jaw_theta,
        jaw_bins=2,
        bin_overlap=OVERLAP,
    )


def expected_bins(edges: np.ndarray, overlap: float, opens: np.ndarray) -> list[int]:
    """The hysteresis rule written out: keep the previous bin while the opening is inside its
    widened range, else the bin whose core range holds it (clamped)."""
    out: list[int] = []
    k = len(edges) - 1
    for o in opens:
        if out and edges[out[-1]] - overlap <= o <= edges[out[-1] + 1] + overlap:
            out.append(out[-1])
            continue
        b = 0
        while b + 1 < k and o >= edges[b + 1]:
            b += 1
        out.append(b)
    return out


def test_int_bins_put_edges_at_quantiles_of_the_distinct_openings(sample, binned) -> None:  # type: ignore[no-untyped-def]
    open_max = np.deg2rad(25.0)  # the sample's jawOpen; every other shape is at rest
    np.testing.assert_allclose(binned.jaw_bins, [0.0, open_max / 2, open_max], rtol=1e-12)
    members = binned.core.jaw()["bin_members"]
    k = sample.names.index("jawOpen")
    assert members[1] == [k]
    assert k not in members[0] and len(members[0]) == len(sample.names) - 1


def test_binned_solve_with_true_poses_interpolates_markers_and_uses_the_pose_bins(
    sample, binned
) -> None:  # type: ignore[no-untyped-def]
    res = binned.solve(sample.performance, jaw=sample.jaw_theta, quiet=True)
    assert res.bundle_residuals.max() <= 1e-6 * binned.diagonal
    assert res.jaw_bin is not None and res.jaw_bin.dtype == np.int64
    want = expected_bins(binned.jaw_bins, OVERLAP, sample.jaw_theta[:, 0])
    np.testing.assert_array_equal(res.jaw_bin, want)
    assert set(want) == {0, 1}
    # Frames in the open bin may only use its shapes (jawOpen) or the neutral.
    k = sample.names.index("jawOpen")
    used = res.choices.shapes[res.jaw_bin == 1][res.choices.weights[res.jaw_bin == 1] > 0]
    assert set(np.unique(used).tolist()) <= {-1, k}
    e = np.linalg.norm(res.vertices - sample.truth, axis=2)
    assert e.mean() < 0.05  # cm


def test_binned_solve_with_tracked_jaw_uses_the_bins_of_the_tracked_poses(sample, binned) -> None:  # type: ignore[no-untyped-def]
    res = binned.solve(sample.performance, jaw="track", smooth_window=3, quiet=True)
    assert res.bundle_residuals.max() <= 1e-6 * binned.diagonal
    assert res.jaw_theta is not None
    want = expected_bins(binned.jaw_bins, OVERLAP, res.jaw_theta[:, 0])
    np.testing.assert_array_equal(res.jaw_bin, want)
    # Independent frames: no hysteresis, each frame in the bin of its own opening.
    free = binned.solve(
        sample.performance[:40], jaw=sample.jaw_theta[:40], temporal=False, quiet=True
    )
    core = np.searchsorted(binned.jaw_bins[1:-1], sample.jaw_theta[:40, 0], side="right")
    np.testing.assert_array_equal(free.jaw_bin, core)


def test_jaw_open_shape_is_reconstructed_in_its_bin(sample, binned) -> None:  # type: ignore[no-untyped-def]
    k = sample.names.index("jawOpen")
    mesh = sample.neutral + sample.shapes[k].astype(np.float64)
    frames = binned.bundle_positions(mesh)[None]
    res = binned.solve(frames, jaw=sample.shape_jaw_theta[k : k + 1], quiet=True)
    assert res.jaw_bin is not None and res.jaw_bin[0] == 1
    err = np.linalg.norm(res.vertices[0] - mesh, axis=1)
    assert np.median(err) < 1e-6 and err.max() < 0.02


def test_unbinned_jaw_model_reports_bin_zero_and_no_jaw_reports_none(
    sample, sample_model, sample_dataset, rig
) -> None:  # type: ignore[no-untyped-def]
    m = lgi.Model.build(
        sample_dataset, sample.markers_rest, jaw=rig, shape_theta=sample.shape_jaw_theta
    )
    assert m.jaw_bins is None
    res = m.solve(sample.performance[:5], jaw=sample.jaw_theta[:5], quiet=True)
    np.testing.assert_array_equal(res.jaw_bin, np.zeros(5, dtype=np.int64))
    assert sample_model.solve(sample.performance[:2], quiet=True).jaw_bin is None


def test_binned_model_save_load_round_trip(tmp_path: Path, sample, binned) -> None:  # type: ignore[no-untyped-def]
    path = tmp_path / "binned.lgi"
    binned.save(path)
    loaded = lgi.Model.load(path)
    np.testing.assert_array_equal(loaded.jaw_bins, binned.jaw_bins)
    a = binned.solve(sample.performance[100:130], jaw=sample.jaw_theta[100:130], quiet=True)
    b = loaded.solve(sample.performance[100:130], jaw=sample.jaw_theta[100:130], quiet=True)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.jaw_bin, b.jaw_bin)


@pytest.mark.parametrize(
    ("jaw_bins", "overlap", "match"),
    [
        (0, 0.0, ">= 1 bins"),
        (True, 0.0, "jaw_bins must be"),
        ("2", 0.0, "jaw_bins"),
        ([[0.0, 0.5]], 0.0, "1-D sequence"),
        ([0.3, 0.1], 0.0, "strictly increasing"),
        ([0.0, np.nan], 0.0, "finite"),
        ([0.0], 0.0, "at least 2 edges"),
        ([0.0, 0.5], -0.1, "overlap"),
        ([0.0, 0.5], "wide", "bin_overlap must be a number"),
        ([0.0, 0.1, 0.2, 0.5], 0.0, "jaw bin 1"),
    ],
)
def test_bad_jaw_bins_raise_input_error(
    sample, sample_dataset, rig, jaw_bins, overlap, match
) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(lgi.InputError, match=match):
        lgi.Model.build(
            sample_dataset,
            sample.markers_rest,
            jaw=rig,
            shape_theta=sample.shape_jaw_theta,
            jaw_bins=jaw_bins,
            bin_overlap=overlap,
        )


def test_jaw_bins_need_a_jaw_and_distinct_openings(sample, sample_dataset, rig) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(lgi.InputError, match="needs a jaw rig"):
        lgi.Model.build(sample_dataset, sample.markers_rest, jaw=None, jaw_bins=2)
    with pytest.raises(lgi.InputError, match="same jaw opening"):
        lgi.Model.build(
            sample_dataset,
            sample.markers_rest,
            jaw=rig,
            shape_theta=np.zeros_like(sample.shape_jaw_theta),
            jaw_bins=2,
        )
