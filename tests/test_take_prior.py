"""The take's own prior on the unbounded global fit (`lgi.estimate_take_prior`,
`Model.solve(take_prior=...)`, `--take-prior`): the shrinker against Gavish & Donoho's closed
form, the core's per-frame fit against numpy's MAP weights of the Gaussian prior over each
frame's present rows, the rows it is read from against the rig's own unskinning, what it buys
on a take that moves in two directions, the left-out reading against brute force, and clear
errors."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lgi
from fit_reference import fit_reference
from lgi.io.settings import SolveSettings
from lgi.plan.take_prior import shrinkage_factors, with_ridge
from lgi.solve.take_prior import TakePrior

SIGMA = 0.02


def two_direction_take(model: Any, seed: int = 11) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 90-frame take on `model` whose weights move along two fixed directions of the shapes
    that do not turn the jaw (weights outside [0, 1] too), markers with noise of SIGMA per
    coordinate and 2 % dropouts; the noise-free markers and the truth meshes."""
    data = model.dataset
    still = np.abs(np.asarray(model.core.jaw()["shape_theta"])).max(axis=1) == 0.0
    rng = np.random.default_rng(seed)
    directions = rng.uniform(-1.0, 1.5, (2, data.num_shapes)) * still
    t = np.linspace(0.0, 6.0, 90)
    w = np.outer(np.sin(t), directions[0]) + np.outer(0.5 + 0.5 * np.cos(1.7 * t), directions[1])
    x0, shapes = np.asarray(data.neutral), np.asarray(data.shapes, dtype=np.float64)
    truth = x0[None] + np.einsum("fk,kvd->fvd", w, shapes)
    clean = model.bundle_positions(truth)
    frames = clean + rng.normal(0.0, SIGMA, clean.shape)
    frames[rng.random(frames.shape[:2]) < 0.02] = np.nan
    return frames, clean, truth


@pytest.fixture(scope="module")
def two_directions() -> tuple[Any, np.ndarray, np.ndarray, np.ndarray]:
    """The sample's model and `two_direction_take` on it."""
    from lgi.lab.sample import make_sample, sample_dataset

    s = make_sample(0)
    model = lgi.Model.build(sample_dataset(s), s.markers_rest)
    return (model, *two_direction_take(model))


def test_shrinkage_factors_are_gavish_and_donohos_closed_form() -> None:
    # Square matrices (beta = 1): eta(y) = sqrt(y^2 - 4) beyond the bulk edge 2.
    y = np.array([0.5, 1.9, 2.0, 2.5, 4.0, 100.0])
    want = np.where(y > 2.0, np.sqrt(np.maximum(y**2 - 4.0, 0.0)) / y, 0.0)
    np.testing.assert_allclose(shrinkage_factors(y, 1.0), want, rtol=1e-12, atol=0)
    # beta = 1/4 at y = 2: sqrt((4 - 1.25)^2 - 1) / 4, worked by hand.
    np.testing.assert_allclose(shrinkage_factors(np.array([2.0]), 0.25), [0.640434], atol=1e-6)
    assert shrinkage_factors(np.array([1.5]), 0.25)[0] == 0.0  # at the edge 1 + sqrt(1/4)


@settings(max_examples=60, deadline=None)
@given(
    st.floats(0.01, 1.0),
    st.lists(st.floats(0.0, 50.0), min_size=1, max_size=20),
)
def test_shrinkage_factors_lie_in_0_1_and_grow_with_the_singular_value(
    beta: float, values: list[float]
) -> None:
    y = np.sort(np.array(values))
    f = shrinkage_factors(y, beta)
    assert np.all((f >= 0.0) & (f < 1.0))
    assert np.all(np.diff(f) >= -1e-12)
    assert np.all(f[y <= 1.0 + np.sqrt(beta)] == 0.0)


def test_with_ridge_adds_the_ridge_precision_on_the_priors_span() -> None:
    rng = np.random.default_rng(2)
    factor = rng.normal(size=(7, 3))
    p = 0.7
    out = with_ridge(factor, p)
    # On the span: (L L^T)^+ + p I restricted to it, inverted: L (I + p L^T L)^-1 L^T.
    want = factor @ np.linalg.inv(np.eye(3) + p * factor.T @ factor) @ factor.T
    np.testing.assert_allclose(out @ out.T, want, atol=1e-12)


def test_fit_rows_are_the_markers_unskinned_by_the_boxed_pose_less_the_rest(
    two_directions: Any,
) -> None:
    model, frames, _, _ = two_directions
    a, offsets, bins = model.core.fit_rows(frames, jaw="fit")
    boxed = model.solve(frames, jaw="fit", fit=True, steady=False, quiet=True)
    # Reference: the rig's own unskinning of the markers at the boxed pose (each bundle's jaw
    # weight), and of the shapes' marker positions at each shape's own pose.
    want_a, rest, markers = fit_reference(model, frames, np.asarray(boxed.jaw_theta))
    np.testing.assert_allclose(a, want_a, atol=1e-9)
    want = (markers - rest[None]).reshape(len(frames), -1)
    missing = np.repeat(np.isnan(frames).any(axis=2), 3, axis=1)
    assert np.array_equal(np.isnan(offsets), missing)
    np.testing.assert_allclose(offsets[~missing], want[~missing], atol=1e-9)
    assert np.all(bins == 0)


def test_the_take_prior_fit_is_numpys_map_weights_of_the_gaussian_prior(
    two_directions: Any,
) -> None:
    model, frames, _, _ = two_directions
    prior = lgi.estimate_take_prior(model, frames, SIGMA)
    # Each frame alone: the reference reads the frame's own markers, its dropouts missing.
    res = model.solve(
        frames, marker_noise=SIGMA, fit="unbounded", take_prior=prior, steady=False, quiet=True
    )
    a, offsets, _ = model.core.fit_rows(frames, jaw="auto")
    mu, ell = prior.mean, prior.factor
    for f in range(len(frames)):
        p = np.isfinite(offsets[f])
        ap = a[p]
        # Covariance form: mu + Sigma A^T (A Sigma A^T + sigma^2 I)^-1 (d - A mu).
        cov = ell @ ell.T
        k = ap @ cov @ ap.T + SIGMA**2 * np.eye(p.sum())
        want = mu + cov @ ap.T @ np.linalg.solve(k, offsets[f, p] - ap @ mu)
        np.testing.assert_allclose(res.fit_weights[f], want, rtol=0, atol=1e-8)


def test_the_take_prior_keeps_the_takes_few_directions_and_cuts_the_error_by_a_quarter(
    two_directions: Any,
) -> None:
    model, frames, _, truth = two_directions
    prior = lgi.estimate_take_prior(model, frames, SIGMA)
    # Two directions move; the jaw pose each frame's fit refines and the frames short of a
    # marker add one each here (measured 4; 2 without either).
    assert 2 <= prior.kept <= 4, prior.kept
    assert prior.directions > 10 and prior.frames == len(frames)

    def error(**kw: Any) -> float:
        res = model.solve(frames, marker_noise=SIGMA, fit="unbounded", quiet=True, **kw)
        return float(np.linalg.norm(res.vertices - truth, axis=2).mean())

    without, with_prior = error(), error(take_prior=prior)
    # Measured 0.0078 against 0.0121 (the face is about 23 units across).
    assert with_prior < 0.75 * without, (with_prior, without)


def test_a_take_of_one_still_face_keeps_no_direction_and_solves_to_its_mean(
    two_directions: Any,
) -> None:
    model, _, clean, _ = two_directions
    rng = np.random.default_rng(5)
    still = clean[10][None] + rng.normal(0.0, SIGMA, (60, *clean.shape[1:]))
    still[rng.random(still.shape[:2]) < 0.02] = np.nan  # the refill with no direction kept
    prior = lgi.estimate_take_prior(model, still, SIGMA)
    assert prior.kept == 0
    res = model.solve(still, marker_noise=SIGMA, fit="unbounded", take_prior=prior, quiet=True)
    np.testing.assert_allclose(res.fit_weights, np.repeat(prior.mean[None], 60, axis=0))


def test_solve_iter_with_the_take_prior_equals_one_solve(two_directions: Any) -> None:
    model, frames, _, _ = two_directions
    prior = lgi.estimate_take_prior(model, frames, SIGMA)
    kw: dict[str, Any] = {"marker_noise": SIGMA, "fit": "unbounded", "take_prior": prior}
    one = model.solve(frames, quiet=True, **kw)
    parts = list(model.solve_iter(frames, chunk=32, quiet=True, **kw))
    np.testing.assert_array_equal(np.concatenate([p.vertices for p in parts]), one.vertices)


def _rows_read(out: Any, frames_read: int) -> np.ndarray:
    """The left-out rows the looks read to reach `frames_read` frames: look k reads every
    LOOKS-th picked frame from the k-th."""
    from lgi.plan.leave_out import LOOKS

    ordinal = np.arange(out.picked.size) % LOOKS
    seen = next(
        out.picked[ordinal <= k]
        for k in range(LOOKS)
        if np.count_nonzero(ordinal <= k) == frames_read
    )
    return np.flatnonzero(np.isin(out.frame, seen))


def _left_out_error(
    model: Any, out: Any, rows: np.ndarray, priors: Any = None, **solve: Any
) -> float:
    """Each row solved on its own (`solve`'s options; `priors`: with the prior read without
    the row's left-out marker) and its left-out marker's mean distance from the surface."""
    errs = []
    for r in rows:
        if priors is not None:
            solve["take_prior"] = priors.prior(without=int(out.marker[r]))
        res = model.solve(
            out.frames[r][None], temporal=False, marker_noise=SIGMA, quiet=True, **solve
        )
        errs.append(float(np.linalg.norm(res.bundle_positions[0, out.marker[r]] - out.given[r])))
    return float(np.mean(errs))


def _left_out_with_held_rows(model: Any, frames: np.ndarray) -> tuple[Any, Any]:
    """The rows the estimates leave out at `frames_used=2` and the prior's rows read from the
    frames none of them leaves a marker out of."""
    from lgi.plan.leave_out import LOOKS, leave_markers_out
    from lgi.plan.take_prior import TakeRows

    out = leave_markers_out(np.asarray(frames), LOOKS * 2, 30)
    others = np.setdiff1d(np.arange(len(frames)), out.picked)
    return out, TakeRows(model, frames[others], SIGMA)


def test_the_left_out_reading_matches_every_row_solved_alone(two_directions: Any) -> None:
    model, frames, _, _ = two_directions
    est = lgi.estimate_take_prior_use(frames, model, marker_noise=SIGMA, frames_used=2)
    out, held = _left_out_with_held_rows(model, frames)
    rows = _rows_read(out, est.frames)
    assert est.left_out == len(rows) > 0
    free = {"fit": "unbounded"}
    assert est.error_without == pytest.approx(_left_out_error(model, out, rows, **free), rel=1e-9)
    with_prior = _left_out_error(model, out, rows, held, **free)
    assert est.error_with == pytest.approx(with_prior, rel=1e-9)
    # On this take the prior pays, and the whole take's prior comes with the answer.
    assert est.use and est.error_with < est.error_without
    assert isinstance(est.prior, TakePrior) and est.prior.frames == len(frames)


def test_the_unbounded_fits_reading_with_the_take_prior_solves_it_as_it_would_be(
    two_directions: Any,
) -> None:
    model, frames, _, _ = two_directions
    est = lgi.estimate_unbounded_fit(
        frames, model, marker_noise=SIGMA, frames_used=2, take_prior=True
    )
    out, held = _left_out_with_held_rows(model, frames)
    rows = _rows_read(out, est.frames)
    assert est.error_boxed == pytest.approx(_left_out_error(model, out, rows), rel=1e-9)
    free = _left_out_error(model, out, rows, held, fit="unbounded")
    assert est.error_unbounded == pytest.approx(free, rel=1e-9)
    plain = lgi.estimate_unbounded_fit(frames, model, marker_noise=SIGMA, frames_used=2)
    assert plain.error_unbounded != est.error_unbounded


def test_a_prior_read_without_a_marker_does_not_depend_on_its_track(two_directions: Any) -> None:
    from lgi.plan.take_prior import TakeRows

    model, frames, _, _ = two_directions
    rows = TakeRows(model, frames, SIGMA)
    before = rows.prior(without=7)
    rows.offsets[:, 21:24] += 5.0  # marker 7's track, moved far away in every frame
    after = rows.prior(without=7)
    np.testing.assert_array_equal(before.mean, after.mean)
    np.testing.assert_array_equal(before.factor, after.factor)
    assert not np.array_equal(rows.prior().mean, before.mean)


def test_noise_free_or_short_takes_are_not_read(two_directions: Any) -> None:
    model, frames, _, _ = two_directions
    est = lgi.estimate_take_prior_use(frames, model, marker_noise=0.0)
    assert not est.use and est.left_out == 0 and est.prior is None
    short = lgi.estimate_take_prior_use(frames[:20], model, marker_noise=SIGMA)
    assert not short.use and short.left_out == 0 and np.isnan(short.error_with)


def test_take_prior_errors_say_what_is_wrong(two_directions: Any) -> None:
    model, frames, _, _ = two_directions
    prior = lgi.estimate_take_prior(model, frames, SIGMA)
    with pytest.raises(lgi.InputError, match="noise-free markers need no prior"):
        lgi.estimate_take_prior(model, frames, 0.0)
    with pytest.raises(lgi.InputError, match="2 frames or more"):
        lgi.estimate_take_prior(model, frames[:1], SIGMA)
    with pytest.raises(lgi.InputError, match=r"fit='unbounded'"):
        model.solve(frames, marker_noise=SIGMA, take_prior=prior, quiet=True)
    with pytest.raises(lgi.InputError, match=r"or an lgi\.TakePrior"):
        model.solve(frames, marker_noise=SIGMA, fit="unbounded", take_prior=(1, 2), quiet=True)  # type: ignore[arg-type]
    other = TakePrior(prior.mean[:-1], prior.factor[:-1], SIGMA, prior.directions, 2)
    with pytest.raises(lgi.InputError, match=r"made for .* shapes"):
        model.solve(frames, marker_noise=SIGMA, fit="unbounded", take_prior=other, quiet=True)
    bad = TakePrior(prior.mean, np.full_like(prior.factor, np.nan), SIGMA, 1, 2)
    with pytest.raises(lgi.InputError, match="must be finite"):
        model.solve(frames, marker_noise=SIGMA, fit="unbounded", take_prior=bad, quiet=True)


def test_the_settings_record_the_take_prior_and_read_old_files_without_it() -> None:
    s = SolveSettings.of(
        has_jaw_rig=True,
        jaw="auto",
        marker_noise=0.02,
        detail_weight=None,
        unbounded_fit=True,
        take_prior=True,
    )
    back = SolveSettings.from_json(s.to_json(), "here")
    assert back == s and back.take_prior
    assert back.pieces() == ", unbounded fit, take prior"
    old = s.to_json().replace(', "take_prior": true', "")
    assert not SolveSettings.from_json(old, "here").take_prior
    with pytest.raises(lgi.InputError, match="take_prior must be true or false"):
        SolveSettings.from_json(s.to_json().replace('"take_prior": true', '"take_prior": 1'), "x")


def test_cli_take_prior_writes_what_model_solve_gives_and_says_its_reading(
    tmp_path: Path,
    sample: Any,
    capsys: pytest.CaptureFixture[str],
) -> None:
    from lgi.app import cli
    from pipeline_files import build_actor, write_c3d

    actor, model_path = build_actor(tmp_path, sample)
    model = lgi.Model.load(model_path)
    frames, _, _ = two_direction_take(model)
    take, out = tmp_path / "take.c3d", tmp_path / "o.npz"
    write_c3d(take, frames * 10.0, list(actor.names), 60.0, "mm")
    x = (frames * 10.0).astype(np.float32).astype(np.float64) / 10.0
    argv = ["solve", str(model_path), str(take), "-o", str(out), "--marker-noise", str(SIGMA)]
    assert cli.main([*argv, "--unbounded-fit", "--take-prior"]) == 0
    err = capsys.readouterr().err
    prior = lgi.estimate_take_prior(model, x, SIGMA)
    assert f"take prior: {prior.kept} of {prior.directions} directions move above" in err, err
    assert f"marker noise {SIGMA:g}, unbounded fit, take prior" in err, err
    want = model.solve(x, marker_noise=SIGMA, fit="unbounded", take_prior=prior, quiet=True)
    with np.load(out) as z:
        np.testing.assert_allclose(z["vertices"], want.vertices, rtol=0, atol=1e-6 * model.diagonal)
        assert SolveSettings.from_json(str(z["solve_settings"]), "o.npz").take_prior
    # auto: read from the take's markers left out, said with its numbers.
    auto = tmp_path / "auto.npz"
    argv_auto = ["solve", str(model_path), str(take), "-o", str(auto), "--marker-noise"]
    assert cli.main([*argv_auto, str(SIGMA), "--unbounded-fit", "--take-prior", "auto"]) == 0
    err = capsys.readouterr().err
    est = lgi.estimate_take_prior_use(x, model, marker_noise=SIGMA)
    said = "take prior used (" if est.use else "take prior not used:"
    assert said in err and "markers left out one at a time" in err, err
    # Both auto: the unbounded fit is read as it would be solved, with the prior.
    both = ["solve", str(model_path), str(take), "-o", str(tmp_path / "both.npz")]
    argv_both = [*both, "--marker-noise", str(SIGMA), "--unbounded-fit", "auto"]
    assert cli.main([*argv_both, "--take-prior", "auto"]) == 0
    err = capsys.readouterr().err
    assert "unbounded fit (with the take prior) " in err, err
    # Without the unbounded fit, or without noise: exit 2 in lgi's own words.
    bad = ["solve", str(model_path), str(take), "-o", str(tmp_path / "x.npz")]
    assert cli.main([*bad, "--marker-noise", str(SIGMA), "--take-prior"]) == 2
    assert "lgi: error: --take-prior is a prior on the unbounded global fit" in (
        capsys.readouterr().err
    )
    assert cli.main([*bad, "--unbounded-fit", "--take-prior"]) == 2
    assert "lgi: error: --take-prior needs the markers' noise" in capsys.readouterr().err
    assert not (tmp_path / "x.npz").exists()


def test_take_prior_auto_says_why_it_was_not_read(two_directions: Any) -> None:
    from lgi.plan.choices import take_prior_choice

    model, frames, _, _ = two_directions
    said: list[str] = []
    for sigma, unbounded in ((SIGMA, False), (None, True), (0.0, True)):
        got = take_prior_choice("auto", frames, model, sigma, "auto", said.append, unbounded)
        assert got is None
    assert said == [
        "take prior not read: the fit is held to [0, 1]",
        "take prior not read: no --marker-noise (every marker interpolated as given)",
        "take prior not read: the markers are noise-free",
    ]
    # A take_prior that is none of these is refused where the options are built, once.
    with pytest.raises(lgi.InputError, match=r"take_prior must be True, False or .auto."):
        lgi.SolveOptions(take_prior="Auto")


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), most_missing=st.integers(1, 9))
def test_the_core_fills_equal_each_frames_fit_on_its_present_rows(
    seed: int, most_missing: int
) -> None:
    """The take prior's reading fills every frame short of a row in the core (Woodbury's
    identity on each frame's missing rows, `_filled`); each frame must equal its own fit made
    directly on its present rows: the ridge fit first, then the MAP under a prior, solved by
    numpy in the q-dimensional weights."""
    from lgi.plan.take_prior import _filled

    rng = np.random.default_rng(seed)
    rows, q, k, frames = 24, 7, 3, 12
    u, s, _ = np.linalg.svd(rng.normal(size=(rows, q)), full_matrices=False)
    s = s * rng.uniform(0.5, 2.0, q)
    offsets = rng.normal(size=(frames, rows))
    for f in range(frames):
        gone = rng.choice(rows, size=rng.integers(0, most_missing + 1), replace=False)
        offsets[f, gone] = np.nan
    sigma, ridge = 0.3, 0.2
    present = np.isfinite(offsets)
    c_all = (np.where(present, offsets, 0.0) @ u) / sigma
    ua = u / (1.0 + ridge / s**2)
    zeta = _filled(u, ua, ua @ u.T, present, c_all, None)
    d_inv = np.diag(1.0 / (1.0 + ridge / s**2))
    mean, phi = rng.normal(size=q), rng.normal(size=(q, k))
    up_fit = u @ (phi @ np.linalg.solve(phi.T @ phi + np.eye(k), phi.T))
    again = _filled(u, up_fit, up_fit @ u.T, present, zeta, mean)
    for f in range(frames):
        p = np.isfinite(offsets[f])
        up, um = u[p], u[~p]
        c = up.T @ offsets[f, p] / sigma
        # Ridge fit: (D - U_Mᵀ U_M) z = c, i.e. (I + ridge S⁻² - U_Mᵀ U_M) z = c.
        fitted = np.linalg.solve(np.linalg.inv(d_inv) - um.T @ um, c)
        want = c + um.T @ (um @ fitted)
        np.testing.assert_allclose(zeta[f], want, rtol=1e-9, atol=1e-9)
        # MAP under the prior: mean + Φ (Φᵀ U_PᵀU_P Φ + I)⁻¹ Φᵀ (c_f - U_PᵀU_P mean).
        cf = up.T @ (up @ zeta[f])
        gram = phi.T @ up.T @ up @ phi + np.eye(k)
        fit_map = mean + phi @ np.linalg.solve(gram, phi.T @ (cf - up.T @ (up @ mean)))
        np.testing.assert_allclose(again[f], cf + um.T @ (um @ fit_map), rtol=1e-9, atol=1e-9)


def test_held_out_priors_read_on_threads_equal_each_read_alone(two_directions: Any) -> None:
    """`HeldOutPriors.read` reads the priors on lgi's threads (one BLAS thread each); each must
    be the prior `TakeRows.prior(without=...)` reads alone."""
    from lgi.plan.take_prior import HeldOutPriors, TakeRows

    model, frames, _, _ = two_directions
    rows = TakeRows(model, frames, SIGMA)
    held = HeldOutPriors(rows)
    markers = np.array([0, 3, 3, 7, 11])
    before = lgi.get_num_threads()
    lgi.set_num_threads(2)
    try:
        held.read(markers)
    finally:
        lgi.set_num_threads(before)
    assert sorted(held._priors) == [0, 3, 7, 11]
    for k in (0, 3, 7, 11):
        alone = rows.prior(without=k)
        got = held.without(k)
        np.testing.assert_allclose(got.mean, alone.mean, rtol=0, atol=1e-12)
        np.testing.assert_allclose(
            got.factor @ got.factor.T, alone.factor @ alone.factor.T, atol=1e-12
        )
