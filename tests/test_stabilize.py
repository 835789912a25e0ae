"""Rigid stabilisation against a known head motion: exact on rigid markers, within 0.1° and
0.1 mm with 20 % of the markers moving non-rigidly and 5 % gross outliers, weights that single
out the rigid markers, and the weighted Kabsch against scipy's `Rotation.align_vectors`."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import lgi
from lgi.capture.stabilize import align, despike, kabsch, stable_weights

CM_TO_MM = 10.0


def _head_motion(rng: np.random.Generator, f: int) -> tuple[np.ndarray, np.ndarray]:
    """Rotations up to 15° about random axes and translations up to 2 cm (data in cm)."""
    axes = rng.normal(size=(f, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = rng.uniform(-np.radians(15), np.radians(15), size=f)
    return Rotation.from_rotvec(axes * angles[:, None]).as_matrix(), rng.uniform(-2, 2, (f, 3))


def _layout(rng: np.random.Generator, b: int) -> np.ndarray:
    """A face-sized marker layout (cm), off the origin like a real one."""
    return rng.normal(size=(b, 3)) * [5.0, 6.0, 2.0] + [0.0, 0.0, 8.0]


def _errors(al, rot, t):  # type: ignore[no-untyped-def]
    return _pose_errors(al.rotations, al.translations, rot, t)


def _pose_errors(r_est, t_est, rot, t):  # type: ignore[no-untyped-def]
    """Per frame: angle of R_est^T R_true (degrees) and translation error (mm)."""
    rel = np.einsum("fji,fjk->fik", r_est, rot)
    deg = np.degrees(Rotation.from_matrix(rel).magnitude())
    return deg, CM_TO_MM * np.linalg.norm(t_est - t, axis=1)


def _take(rng: np.random.Generator, f: int = 60, b: int = 120, sigma: float = 0.005):  # type: ignore[no-untyped-def]
    rest = _layout(rng, b)
    rot, t = _head_motion(rng, f)
    local = np.repeat(rest[None], f, axis=0)
    moving = rng.choice(b, size=int(0.2 * b), replace=False)
    local[:, moving] += rng.normal(0, 0.6, size=(f, moving.size, 3))  # expressions, up to cm
    x = np.einsum("fij,fbj->fbi", rot, local) + t[:, None]
    x += rng.normal(0, sigma, size=x.shape)  # 0.05 mm triangulation noise
    gross = rng.random((f, b)) < 0.05
    x[gross] += rng.normal(0, 3.0, size=(int(gross.sum()), 3))  # mistracks, centimetres off
    x[rng.random((f, b)) < 0.02] = np.nan
    return x, rest, rot, t, moving, gross


def test_noise_free_rigid_markers_give_the_head_motion_exactly() -> None:
    rng = np.random.default_rng(0)
    rest = _layout(rng, 40)
    rot, t = _head_motion(rng, 10)
    x = np.einsum("fij,bj->fbi", rot, rest) + t[:, None]
    al = align(x, rest)
    deg, mm = _errors(al, rot, t)
    assert deg.max() < 1e-9 and mm.max() < 1e-9
    np.testing.assert_allclose(al.frames, np.broadcast_to(rest, x.shape), atol=1e-10)
    assert al.inliers.all()


def test_head_motion_within_0p1_degree_and_0p1_mm_with_20pc_moving_and_5pc_outliers() -> None:
    rng = np.random.default_rng(1)
    x, rest, rot, t, moving, gross = _take(rng)
    al = align(x, rest)
    deg, mm = _errors(al, rot, t)
    assert deg.max() <= 0.1 and mm.max() <= 0.1
    # Gross outliers are flagged; most rigid, clean markers are inliers.
    present = ~np.isnan(x[..., 0])
    assert not al.inliers[gross & present].any()
    rigid = np.ones(rest.shape[0], dtype=bool)
    rigid[moving] = False
    clean = present & ~gross & rigid[None]
    assert al.inliers[clean].mean() > 0.95
    # Without robustness (one plain weighted Kabsch) the same take is off by far more.
    w = np.where(present, 1.0, 0.0)
    r_plain, t_plain = kabsch(rest, x, w)
    assert _pose_errors(r_plain, t_plain, rot, t)[1].max() > 1.0


def test_stable_weights_single_out_the_rigid_markers_and_keep_the_accuracy() -> None:
    rng = np.random.default_rng(2)
    x, rest, rot, t, moving, _ = _take(rng)
    w = stable_weights(x, rest)
    rigid = np.setdiff1d(np.arange(rest.shape[0]), moving)
    assert w.shape == (rest.shape[0],) and w.max() == pytest.approx(1.0)
    assert w[moving].max() < w[rigid].min()
    deg, mm = _errors(align(x, rest, w), rot, t)
    assert deg.max() <= 0.1 and mm.max() <= 0.1


@given(seed=st.integers(0, 2**32 - 1))
def test_weighted_kabsch_equals_scipy_align_vectors(seed: int) -> None:
    rng = np.random.default_rng(seed)
    src = rng.normal(size=(12, 3))
    tgt = src @ Rotation.random(random_state=seed).as_matrix().T + rng.normal(0, 0.3, (12, 3))
    w = rng.uniform(0.1, 2.0, 12)
    rot, t = kabsch(src, tgt[None], w[None])
    cs, ct = np.average(src, axis=0, weights=w), np.average(tgt, axis=0, weights=w)
    ref, _ = Rotation.align_vectors(tgt - ct, src - cs, weights=w)
    np.testing.assert_allclose(rot[0], ref.as_matrix(), atol=1e-9)
    np.testing.assert_allclose(t[0], ct - ref.as_matrix() @ cs, atol=1e-9)


def test_kabsch_never_returns_a_reflection() -> None:
    rng = np.random.default_rng(3)
    src = rng.normal(size=(10, 3))
    mirrored = src * [1, 1, -1]
    rot, _ = kabsch(src, mirrored[None], np.ones((1, 10)))
    assert np.linalg.det(rot[0]) == pytest.approx(1.0)


def test_align_reports_bad_input_naming_the_argument_and_frame() -> None:
    rest = np.eye(3) * 5
    with pytest.raises(lgi.InputError, match=r"frames: expected shape \(F, 3, 3\)"):
        align(np.zeros((2, 4, 3)), rest)
    frames = np.repeat(rest[None], 3, axis=0)
    frames[1, :2] = np.nan
    with pytest.raises(lgi.InputError, match="frame 1 has 1 markers"):
        align(frames, rest)
    with pytest.raises(lgi.InputError, match="weights"):
        align(np.repeat(rest[None], 2, axis=0), rest, weights=[1, -1, 1])
    with pytest.raises(lgi.InputError, match="rest"):
        align(np.zeros((1, 2, 3)), np.zeros((2, 3)))
    original = frames.copy()
    align(np.nan_to_num(frames) + rest, rest)
    np.testing.assert_array_equal(np.isnan(frames), np.isnan(original))


def test_despike_removes_one_frame_jumps_and_keeps_smooth_motion() -> None:
    rng = np.random.default_rng(6)
    f, b = 200, 30
    time = np.linspace(0, 4 * np.pi, f)[:, None, None]
    smooth = np.sin(time * rng.uniform(0.5, 1.5, (1, b, 3))) + rng.normal(0, 0.01, (f, b, 3))
    spiked = smooth.copy()
    where = rng.random((f, b)) < 0.01
    spiked[where] += rng.choice([-1, 1], size=(int(where.sum()), 3)) * 0.5
    spiked[3, 4] = np.nan
    original = spiked.copy()
    cleaned, flags = despike(spiked)
    assert flags[where].all()
    assert flags[~where].mean() < 0.01  # a few real samples may go: the solve fills them
    assert np.isnan(cleaned[flags]).all()
    np.testing.assert_array_equal(cleaned[~flags], spiked[~flags])
    np.testing.assert_array_equal(spiked, original)
    with pytest.raises(lgi.InputError, match="half_window"):
        despike(spiked, half_window=0)
