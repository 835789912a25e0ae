"""The whole-face-scans protocol (`lgi.lab.scans`, `lgi evaluate --protocol scans`): scans picked
farthest-first with the neutral counted as scanned, each scan the capture truth rig's mesh and
its jaw pose the curve-weighted poses of the jaw shapes, and the protocol on the shared
recordings."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from conftest import ict_dir
from lgi.errors import InputError
from lgi.lab import ict
from lgi.lab.capture import HingeJaw, capture_truth
from lgi.lab.scans import pick_scans, scan_session, scan_theta


def test_scans_are_picked_farthest_first_with_the_neutral_counted_as_scanned() -> None:
    w = np.array([[0.0], [1.0], [2.0], [10.0]])
    # 10 is farthest from the neutral; then 2 (2 from the neutral, 8 from 10) beats 1.
    assert pick_scans(w, 2) == [3, 2]
    assert pick_scans(w, 4)[:3] == [3, 2, 1]
    with pytest.raises(InputError, match=r"need 1\.\.4"):
        pick_scans(w, 5)


def test_greedy_scans_cover_the_curves_within_twice_the_best_cover() -> None:
    # Farthest-first is a 2-approximation of the k-centre cover (Gonzalez 1985): brute force.
    from itertools import combinations

    rng = np.random.default_rng(4)
    w = rng.random((9, 3))
    pts = np.vstack([np.zeros((1, 3)), w])  # the neutral is always a centre

    def radius(chosen: list[int]) -> float:
        centres = np.vstack([pts[:1], w[chosen]])
        return float(np.linalg.norm(w[:, None] - centres[None], axis=2).min(axis=1).max())

    for k in (1, 2, 3):
        best = min(radius(list(c)) for c in combinations(range(9), k))
        assert radius(pick_scans(w, k)) <= 2 * best + 1e-12


def test_a_scans_jaw_pose_is_its_curve_weights_times_the_shapes_poses() -> None:
    theta = np.array([[0.2, 0.0, 0.0], [0.0, 0.05, 0.0], [0.0, 0.0, 0.0]])
    w = np.array([[0.5, 0.0, 1.0], [1.0, -1.0, 0.3]])
    np.testing.assert_allclose(scan_theta(w, theta), [[0.1, 0, 0], [0.2, -0.05, 0]])


def test_each_scan_is_the_capture_truth_of_its_picked_frame(ict_dataset) -> None:  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(0)
    w = rng.uniform(0, 0.5, size=(30, ict_dataset.num_shapes))
    hinge = HingeJaw.fit(ict_dataset, ict.lower_teeth())
    theta = rng.normal(scale=0.1, size=(ict_dataset.num_shapes, 3))
    session = scan_session(ict_dataset, w, 5, hinge, theta)
    assert session.dataset.names == [f"scan{i:03d}" for i in range(5)]
    truth = capture_truth(ict_dataset, w[session.frames], hinge)
    got = np.asarray(ict_dataset.neutral)[None] + np.asarray(session.dataset.shapes)
    np.testing.assert_allclose(got, truth, atol=1e-5)  # shapes are float32
    np.testing.assert_allclose(session.theta, w[session.frames] @ theta, atol=1e-15)
    assert session.frames == pick_scans(w, 5)


def test_cli_scans_protocol_scores_every_method_on_both_recordings(tmp_path: Path) -> None:
    from lgi.app.cli import main

    folder = ict_dir().parent / "livelinkface"
    if len(list(folder.glob("*.csv"))) < 2:
        pytest.skip(f"the scans protocol needs two Live Link recordings in {folder}")
    out = tmp_path / "scans"
    argv = ["evaluate", "--data", "ict", "--protocol", "scans", "--scans", "40", "--sigma", "0.02"]
    argv += ["--frames", "60"]
    assert main([*argv, "--ict-dir", str(ict_dir()), "--out", str(out), "-q"]) == 0
    with open(out / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    means = {r["method"]: float(r["mean"]) for r in rows}
    for rec in ("alex_rom_4", "jmtechart_myslate_3"):
        got = {k.split(": ", 1)[1]: v for k, v in means.items() if k.startswith(rec)}
        assert set(got) >= {"blendshape fit", "fit + jaw", "fit + jaw + residual", "LGI"}
        assert set(got) >= {"fit + jaw (unbounded)", "fit + jaw (unbounded) + residual"}
        # A scan's weight is no activation: without the box the local fits are closer.
        assert got["LGI + local fits (unbounded)"] < got["LGI + local fits"]
        # And the recommended call with the unbounded global fit is closer than with the box.
        assert got["LGI (unbounded fit)"] < got["LGI"]
        assert all(np.isfinite(v) and 0 < v < 1.0 for v in got.values())
        # Scans are whole faces: LGI's local geometry beats the plain blend of scans.
        assert got["LGI"] < got["blendshape fit"]
    lgi_rows = [r for r in rows if r["method"].endswith(": LGI")]
    assert all(0.0 <= float(r["bundles_fit"]) <= 1.0 for r in lgi_rows)
    assert all(r["scans"] == "40" for r in rows)


@pytest.fixture(scope="module")
def sample_truth():  # type: ignore[no-untyped-def]
    from lgi.lab.capture import NonlinearTruth
    from lgi.lab.sample import make_sample, sample_dataset

    ds = sample_dataset(make_sample(0))
    return ds, NonlinearTruth(ds)


def test_nonlinear_truth_of_one_shape_at_full_weight_is_that_shape(sample_truth) -> None:  # type: ignore[no-untyped-def]
    ds, truth = sample_truth
    shapes = np.asarray(ds.shapes, dtype=np.float64)
    neutral = np.asarray(ds.neutral)
    w = np.eye(ds.num_shapes)[[0, ds.num_shapes // 2, ds.num_shapes - 1]]
    got = truth.meshes(w)
    diag = float(np.linalg.norm(np.ptp(neutral, axis=0)))
    for row, k in zip(got, np.argmax(w, axis=1), strict=True):
        # The shape's own gradients solved back: its mesh, to the solve's precision.
        assert np.abs(row - (neutral + shapes[k])).max() < 1e-6 * diag
    np.testing.assert_array_equal(truth.meshes(np.zeros((1, ds.num_shapes)))[0], neutral)


def test_nonlinear_truth_is_off_the_linear_rig_by_less_than_the_motion(
    sample_truth,
) -> None:  # type: ignore[no-untyped-def]
    from lgi.lab.capture import departure

    ds, truth = sample_truth
    rng = np.random.default_rng(1)
    w = rng.uniform(0, 1, size=(3, ds.num_shapes))
    got, lin = truth.meshes(w), truth.linear(w)
    moved = departure(lin, np.asarray(ds.neutral)[None].repeat(3, 0))
    apart = departure(got, lin)
    # A real departure, well below the motion itself (the rule blends, it does not invent).
    assert 1e-3 * moved < apart < 0.5 * moved
    with pytest.raises(InputError, match="weights: expected finite"):
        truth.meshes(np.full((1, ds.num_shapes), np.nan))


def test_nonlinear_scans_are_the_nonlinear_truth_of_their_frames(sample_truth) -> None:  # type: ignore[no-untyped-def]
    ds, truth = sample_truth
    w = np.random.default_rng(2).uniform(0, 0.8, size=(12, ds.num_shapes))
    session = scan_session(ds, w, 4, None, None, nonlinear=truth)
    want = truth.meshes(w[session.frames]) - np.asarray(ds.neutral)[None]
    np.testing.assert_allclose(np.asarray(session.dataset.shapes), want, atol=1e-5)
    assert session.theta is None
