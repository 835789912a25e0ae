"""Local fits (`lgi.plan.local`, `Model.solve(local_fits=True)`): each bundle's piece is the
box-penalised blendshape fit of the markers in its Gaussian window. Checked against an
independent minimiser of that objective (scipy), for exact interpolation of every present
target, for giving back a dataset shape from its own markers, for chunks and `out` buffers,
and for clear errors; `test_scans.py` measures it against the peers on ICT."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize

import lgi
from lgi import _lgi
from lgi.errors import InputError
from lgi.io.settings import SolveSettings
from lgi.lab import ict
from lgi.solve.local import local_pieces


@pytest.fixture(scope="module")
def solved(sample, sample_dataset, noise_aware_sample):  # type: ignore[no-untyped-def]
    model, sigma = noise_aware_sample
    return sample_dataset, model, sample.performance[:24], sigma


def _window(
    rest: np.ndarray, b: int, lengths: float = _lgi.LOCAL_LENGTH
) -> tuple[np.ndarray, np.ndarray]:
    """Bundle b's markers and weights, from the definition: the Gaussian of the rest distance
    with `lengths` (`LOCAL_LENGTH`) median nearest-marker distances as its length, markers
    within 3 lengths."""
    d = np.linalg.norm(rest[:, None] - rest[None], axis=2)
    np.fill_diagonal(d, np.inf)
    nearest = np.sort(d.min(axis=1))
    length = lengths * nearest[len(nearest) // 2]
    dist = np.linalg.norm(rest - rest[b], axis=1)
    keep = np.flatnonzero(dist <= 3.0 * length * (1 + 1e-12))
    return keep, np.exp(-0.5 * (dist[keep] / length) ** 2)


@pytest.mark.parametrize("lengths", [0.6, _lgi.LOCAL_LENGTH, 2.5])
def test_windows_hold_the_markers_within_three_of_their_lengths_by_brute_force(
    lengths: float,
) -> None:
    rng = np.random.default_rng(9)
    rest = rng.uniform(-5, 5, size=(40, 3))
    a = rng.standard_normal((120, 4))
    fits = _lgi.LocalFits(a, rest, _lgi.FIT_L2, _lgi.FIT_PENALTY, lengths)
    want = [_window(rest, k, lengths)[0].size for k in range(40)]
    np.testing.assert_array_equal(fits.window_sizes, want)


@pytest.mark.parametrize("lengths", [0.0, -1.0, float("nan"), float("inf")])
def test_a_window_length_that_is_not_a_positive_number_is_refused_in_our_words(
    lengths: float,
) -> None:
    rest = np.random.default_rng(2).uniform(-5, 5, size=(10, 3))
    with pytest.raises(InputError, match="positive number of marker spacings"):
        _lgi.LocalFits(np.ones((30, 2)), rest, _lgi.FIT_L2, 0.0, lengths)


def test_each_local_fit_is_the_minimum_of_its_windowed_objective_found_by_scipy() -> None:
    rng = np.random.default_rng(4)
    b, s = 30, 6
    rest = rng.uniform(-5, 5, size=(b, 3))
    a = rng.standard_normal((3 * b, s))
    truth = rng.uniform(-0.2, 1.2, size=s)  # some weights outside the box
    target = (a @ truth + 0.05 * rng.standard_normal(3 * b)).reshape(1, b, 3)
    fits = _lgi.LocalFits(a, rest, _lgi.FIT_L2, _lgi.FIT_PENALTY)
    got, kept = fits.solve(target, np.zeros((1, s)))
    assert kept == 0 and got.shape == (1, b, s)
    for k in range(b):
        keep, g = _window(rest, k)
        rows = (3 * keep[:, None] + np.arange(3)).ravel()
        ga = a[rows] * np.sqrt(np.repeat(g, 3))[:, None]
        gt = target.reshape(-1)[rows] * np.sqrt(np.repeat(g, 3))
        scale = (ga**2).sum() / s
        l2, pen = _lgi.FIT_L2 * scale, _lgi.FIT_PENALTY * scale

        def objective(
            w: np.ndarray,
            ga: np.ndarray = ga,
            gt: np.ndarray = gt,
            l2: float = l2,
            pen: float = pen,
        ) -> tuple[float, np.ndarray]:
            r = ga @ w - gt
            out = np.minimum(w, 0.0) + np.maximum(w - 1.0, 0.0)
            f = r @ r + l2 * w @ w + pen * out @ out
            return float(f), 2 * ga.T @ r + 2 * l2 * w + 2 * pen * out

        ref = minimize(
            objective,
            np.full(s, 0.5),
            jac=True,
            method="L-BFGS-B",
            options={"ftol": 1e-15, "gtol": 1e-12, "maxiter": 10_000},
        ).x
        np.testing.assert_allclose(got[0, k], ref, rtol=0, atol=1e-6)


def test_unbounded_local_fits_are_each_windows_ridge_solution_in_closed_form() -> None:
    rng = np.random.default_rng(5)
    b, s = 30, 6
    rest = rng.uniform(-5, 5, size=(b, 3))
    a = rng.standard_normal((3 * b, s))
    truth = rng.uniform(-1.5, 2.5, size=s)  # far outside the box
    target = (a @ truth + 0.05 * rng.standard_normal(3 * b)).reshape(1, b, 3)
    got, kept = _lgi.LocalFits(a, rest, _lgi.FIT_L2, 0.0).solve(target, np.zeros((1, s)))
    assert kept == 0
    for k in range(b):
        keep, g = _window(rest, k)
        rows = (3 * keep[:, None] + np.arange(3)).ravel()
        ga = a[rows] * np.sqrt(np.repeat(g, 3))[:, None]
        gt = target.reshape(-1)[rows] * np.sqrt(np.repeat(g, 3))
        l2 = _lgi.FIT_L2 * (ga**2).sum() / s
        want = np.linalg.solve(ga.T @ ga + l2 * np.eye(s), ga.T @ gt)
        np.testing.assert_allclose(got[0, k], want, rtol=0, atol=1e-8)


def test_unbounded_local_fits_give_back_differences_of_shapes_the_bounded_ones_cannot(
    solved,
) -> None:  # type: ignore[no-untyped-def]
    data, model, _, _ = solved
    neutral = np.asarray(data.neutral)
    shapes = np.asarray(data.shapes, dtype=np.float64)
    theta = np.asarray(model.core.jaw()["shape_theta"])
    still = np.flatnonzero(np.abs(theta).max(axis=1) == 0.0)  # shapes that do not turn the jaw
    rng = np.random.default_rng(2)
    pairs = rng.choice(still, size=(6, 2), replace=False)
    # One shape less another: weights +1 and -1, a frame outside the [0, 1] box.
    meshes = neutral[None] + shapes[pairs[:, 0]] - shapes[pairs[:, 1]]
    frames = model.bundle_positions(meshes)
    kw = {"marker_noise": 0.0, "quiet": True, "temporal": False}
    free = model.solve(frames, local_fits="unbounded", **kw)
    boxed = model.solve(frames, local_fits=True, **kw)
    err_free = np.linalg.norm(free.vertices - meshes, axis=2).mean()
    err_box = np.linalg.norm(boxed.vertices - meshes, axis=2).mean()
    assert err_free < 0.2 * err_box, (err_free, err_box)
    # Both pass through every marker.
    assert free.bundle_residuals.max() < 1e-9 * model.diagonal


def test_the_surface_passes_through_every_present_target_with_markers_missing(solved) -> None:  # type: ignore[no-untyped-def]
    _, model, frames, sigma = solved
    given = frames.copy()
    given[3, :5] = np.nan
    base = model.solve(given, marker_noise=sigma, quiet=True)
    local = model.solve(given, marker_noise=sigma, quiet=True, local_fits=True)
    missing = np.asarray(local.missing)
    assert missing[3, :5].all() and np.isfinite(local.vertices).all()
    # Every present marker's surface point is the noise-aware target of the solve.
    at = np.asarray(local.bundle_positions)[~missing]
    np.testing.assert_allclose(at, np.asarray(base.bundle_positions)[~missing], rtol=0, atol=1e-9)
    # And the surface differs from the tets' where the local fits do.
    assert np.abs(local.vertices - base.vertices).max() > 1e-4 * model.diagonal


def test_a_dataset_shape_at_its_own_markers_comes_back_close_but_not_exactly(solved) -> None:  # type: ignore[no-untyped-def]
    data, model, _, _ = solved
    neutral = np.asarray(data.neutral)
    shapes = np.asarray(data.shapes, dtype=np.float64)
    meshes = neutral[None] + shapes
    frames = model.bundle_positions(meshes)
    got = model.solve(frames, marker_noise=0.0, quiet=True, temporal=False, local_fits=True)
    err = np.linalg.norm(got.vertices - meshes, axis=2)
    motion = np.linalg.norm(shapes, axis=2).max(axis=1)
    # Nearly every shape comes back within 2 % of its motion at every vertex, and the mean is
    # far below; unlike the tets (exact, docs/results.md), a window whose markers two local
    # shapes move alike (a squint and a blink) may take some of the other: not exact.
    worst = err.max(axis=1) / motion
    assert np.mean(worst < 0.02) >= 0.9, worst
    assert err.mean() < 1e-4 * motion.max()
    tets = model.solve(frames, marker_noise=0.0, quiet=True, temporal=False)
    assert np.linalg.norm(tets.vertices - meshes, axis=2).mean() < err.mean()


def test_chunks_and_an_out_buffer_receive_the_same_local_surface(solved) -> None:  # type: ignore[no-untyped-def]
    _, model, frames, sigma = solved
    want = model.solve(frames, marker_noise=sigma, quiet=True, local_fits=True)
    out = np.empty_like(want.vertices)
    got = model.solve(frames, marker_noise=sigma, quiet=True, local_fits=True, out=out)
    assert np.shares_memory(got.vertices, out)
    np.testing.assert_array_equal(out, want.vertices)
    parts = list(
        model.solve_iter(frames, chunk=10, marker_noise=sigma, quiet=True, local_fits=True)
    )
    # A window's fit starts at its fit of the frame before, except at a chunk's first frame:
    # the same minima, to the fits' round-off.
    np.testing.assert_allclose(
        np.concatenate([p.vertices for p in parts]), want.vertices, rtol=0, atol=1e-10
    )


def test_no_frames_give_no_meshes_with_local_fits(solved) -> None:  # type: ignore[no-untyped-def]
    _, model, _, sigma = solved
    got = model.solve(np.zeros((0, model.num_bundles, 3)), marker_noise=sigma, local_fits=True)
    assert got.vertices.shape == (0, model.num_vertices, 3)


def test_local_fits_without_marker_noise_or_with_jaw_bins_are_input_errors(solved, sample) -> None:  # type: ignore[no-untyped-def]
    data, model, frames, _ = solved
    with pytest.raises(InputError, match="local_fits needs marker_noise"):
        model.solve(frames, quiet=True, local_fits=True)
    with pytest.raises(InputError, match="fit=False"):
        model.solve(frames, quiet=True, local_fits=True, marker_noise=0.01, fit=False)
    with pytest.raises(InputError, match="local_fits must be True, False, 'unbounded'"):
        model.solve(frames, quiet=True, local_fits="yes", marker_noise=0.01)  # type: ignore[arg-type]
    binned = lgi.Model.build(data, sample.markers_rest, jaw_bins=2)
    with pytest.raises(InputError, match="jaw bins"):
        binned.solve(frames, quiet=True, local_fits=True, marker_noise=0.01)
    with pytest.raises(InputError, match="jaw bins"):
        local_pieces(binned)


def test_solve_settings_record_local_fits_and_older_files_read_as_without() -> None:
    s = SolveSettings.of(
        has_jaw_rig=True, jaw="auto", marker_noise=0.02, detail_weight=None, local_fits=True
    )
    back = SolveSettings.from_json(s.to_json(), "x.npz")
    assert back == s and back.local_fits and "local fits" in back.describe("cm")
    old = '{"detail_weight": null, "jaw": "auto", "marker_noise": 0.02, "version": "0.1.0"}'
    assert SolveSettings.from_json(old, "x.npz").local_fits is False
    with pytest.raises(InputError, match="local_fits must be true, false or 'unbounded'"):
        SolveSettings.from_json(old[:-1] + ', "local_fits": 1}', "x.npz")
    free = SolveSettings.of(
        has_jaw_rig=True, jaw="auto", marker_noise=0.0, detail_weight=None, local_fits="unbounded"
    )
    back = SolveSettings.from_json(free.to_json(), "x.npz")
    assert back == free and back.local_fits == "unbounded"
    assert "unbounded local fits" in back.describe("cm")


def _c3d_take(tmp_path: Path, sample) -> tuple[Path, Path, Path, np.ndarray]:  # type: ignore[no-untyped-def]
    """The sample actor's model file, 12 frames of its performance as a C3D take in mm, the
    output path, and the frames (cm)."""
    from pipeline_files import build_actor, write_c3d

    actor, model_path = build_actor(tmp_path, sample)
    frames = np.asarray(sample.performance[:12], dtype=np.float64)
    take = tmp_path / "take.c3d"
    write_c3d(take, frames * 10.0, list(actor.names), 60.0, "mm")
    return model_path, take, tmp_path / "o.npz", frames


def test_cli_local_fits_needs_marker_noise_and_writes_what_model_solve_gives(
    tmp_path: Path,
    sample,
    capsys,  # type: ignore[no-untyped-def]
) -> None:
    from lgi.app import cli

    model_path, take, out, frames = _c3d_take(tmp_path, sample)
    rc = cli.main(["solve", str(model_path), str(take), "-o", str(out), "--local-fits", "-q"])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("lgi: error: --local-fits needs --marker-noise"), err
    assert not out.exists()
    argv = ["solve", str(model_path), str(take), "-o", str(out), "--local-fits", "-q"]
    assert cli.main([*argv, "--marker-noise", "0.01"]) == 0
    with np.load(out) as z:
        got = z["vertices"]
        settings = SolveSettings.from_json(str(z["solve_settings"]), "o.npz")
    assert settings.local_fits and settings.marker_noise == 0.01
    model = lgi.Model.load(model_path)
    x = (frames * 10.0).astype(np.float32).astype(np.float64) / 10.0
    want = model.solve(x, marker_noise=0.01, quiet=True, local_fits=True)
    np.testing.assert_allclose(got, want.vertices, rtol=0, atol=1e-6 * model.diagonal)


def test_ctrl_c_during_the_local_fits_stops_them_within_a_chunk(solved) -> None:  # type: ignore[no-untyped-def]
    import os
    import signal
    import time

    from interrupts import python_sigint_handler
    from lgi.solve.local import FITS_CHUNK, LocalPieces

    _, model, frames, sigma = solved
    res = model.solve(frames, marker_noise=sigma, quiet=True)
    pieces = LocalPieces(model)
    real = pieces.fits_for(True)
    calls: list[int] = []

    class Counting:
        """The core's fits, sending a real SIGINT after the second chunk."""

        def solve(self, targets, starts):  # type: ignore[no-untyped-def]
            got = real.solve(targets, starts)
            calls.append(len(targets))
            if len(calls) == 2:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.05)
            return got

    counting = Counting()
    pieces.fits_for = lambda bounded, lengths=None: counting  # type: ignore[method-assign,assignment]
    many = type(res)(
        vertices=np.repeat(np.asarray(res.vertices), 4, axis=0),
        bundle_residuals=np.repeat(np.asarray(res.bundle_residuals), 4, axis=0),
        bundle_positions=np.repeat(np.asarray(res.bundle_positions), 4, axis=0),
        missing=np.repeat(np.asarray(res.missing), 4, axis=0),
        choices=res.choices,
        jaw_theta=None if res.jaw_theta is None else np.repeat(res.jaw_theta, 4, axis=0),
        fit_weights=np.repeat(np.asarray(res.fit_weights), 4, axis=0),
    )
    total = -(-many.vertices.shape[0] // FITS_CHUNK)
    with python_sigint_handler(), pytest.raises(KeyboardInterrupt):
        pieces.surface(many)
    assert 2 <= len(calls) <= 3 < total


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), b=st.integers(4, 24), s=st.integers(1, 8))
def test_local_fits_follow_the_markers_when_they_are_relabelled(seed: int, b: int, s: int) -> None:
    rng = np.random.default_rng(seed)
    rest = rng.uniform(-3, 3, size=(b, 3))
    a = rng.standard_normal((3 * b, s))
    target = rng.standard_normal((2, b, 3))
    target[1, rng.integers(b)] = np.nan
    starts = rng.uniform(0, 1, size=(2, s))
    got, kept = _lgi.LocalFits(a, rest, _lgi.FIT_L2, _lgi.FIT_PENALTY).solve(target, starts)
    order = rng.permutation(b)
    rows = (3 * order[:, None] + np.arange(3)).ravel()
    fits = _lgi.LocalFits(a[rows], rest[order], _lgi.FIT_L2, _lgi.FIT_PENALTY)
    again, kept_again = fits.solve(target[:, order], starts)
    assert kept == kept_again
    np.testing.assert_allclose(again, got[:, order], rtol=0, atol=1e-9)


def test_the_shape_basis_gives_every_shape_back_from_the_independent_ones() -> None:
    rng = np.random.default_rng(8)
    own = rng.standard_normal((5, 600)).astype(np.float32)
    mixed = np.vstack([own, own[0] + own[3], 0.5 * own[2] - own[4]]).astype(np.float32)
    found = _lgi.shape_basis(mixed)
    assert found is not None
    pivots, coefficients = found
    assert sorted(pivots.tolist()) == sorted(set(pivots.tolist())) and len(pivots) == 5
    assert coefficients.shape == (7, 5)
    back = coefficients @ mixed[pivots].astype(np.float64)
    np.testing.assert_allclose(back, mixed, rtol=0, atol=1e-5 * np.abs(mixed).max())
    assert _lgi.shape_basis(own) is None
    with pytest.raises(ValueError, match="C-contiguous"):
        _lgi.shape_basis(np.asfortranarray(mixed))


def test_local_fits_over_a_shape_basis_give_the_surface_of_every_shape(  # type: ignore[no-untyped-def]
    sample, monkeypatch
) -> None:
    # The sample's shapes plus combinations of them (an augmented dataset's in-betweens and
    # sums): the blend runs over the independent shapes, weights mapped onto them.
    shapes = np.asarray(sample.shapes, dtype=np.float64)
    extra = np.stack([0.5 * shapes[0], shapes[1] + shapes[2], 0.3 * shapes[3] - shapes[4]])
    data = lgi.Dataset.from_arrays(
        sample.neutral,
        sample.triangles,
        np.concatenate([shapes, extra]),
        uvs=sample.uvs,
        uv_triangles=sample.uv_triangles,
    )
    model = lgi.Model.build(data, sample.markers_rest)
    frames = sample.performance[:12]
    sigma = lgi.estimate_marker_noise(sample.performance, model)
    res = model.solve(frames, marker_noise=sigma, quiet=True)
    basis = local_pieces(model)
    assert basis.basis_map is not None
    assert basis.shapes.shape[2] == len(shapes) and basis.basis_map.shape == (
        len(shapes) + 3,
        len(shapes),
    )
    monkeypatch.setattr("lgi.solve.local._lgi.shape_basis", lambda _: None)
    every = lgi.solve.local.LocalPieces(model)
    assert every.basis_map is None and every.shapes.shape[2] == len(shapes) + 3
    motion = np.abs(shapes).max()
    np.testing.assert_allclose(basis.surface(res), every.surface(res), rtol=0, atol=1e-5 * motion)


def test_local_fits_at_the_bundles_are_the_surface_sampled_there(solved) -> None:  # type: ignore[no-untyped-def]
    _, model, frames, sigma = solved
    given = frames.copy()
    given[2, 3] = np.nan
    res = model.solve(given, marker_noise=sigma, quiet=True)
    pieces = local_pieces(model)
    np.testing.assert_allclose(
        pieces.at_bundles(res),
        model.bundle_positions(pieces.surface(res)),
        rtol=0,
        atol=1e-12 * model.diagonal,
    )


def test_the_local_fits_estimate_is_the_left_out_markers_distance_every_way(solved) -> None:  # type: ignore[no-untyped-def]
    from lgi.plan.local import LEFT_OUT_PER_FRAME, LOOK_SIGNIFICANCE, LOOKS
    from lgi.solve.local import UNBOUNDED

    _, model, frames, sigma = solved
    per_look = 2
    got = lgi.estimate_local_fits(frames, model, marker_noise=sigma, frames_used=per_look)
    free = lgi.estimate_local_fits(
        frames, model, marker_noise=sigma, frames_used=per_look, fit=UNBOUNDED
    )
    # Brute force: each left-out row solved on its own, the local fits' whole surface: the
    # solve, bounded local fits, unbounded ones, and the solve with the unbounded global fit.
    present = np.isfinite(frames).all(axis=2)
    picked = np.unique(np.linspace(0, len(frames) - 1, LOOKS * per_look).round().astype(int))
    dist: dict[int, np.ndarray] = {}
    kinds = ((None, False), (None, True), (None, UNBOUNDED), (UNBOUNDED, False))
    for ordinal, f in enumerate(picked):
        markers = np.flatnonzero(present[f])
        n, step = markers.size, markers.size / LEFT_OUT_PER_FRAME
        shift = int(ordinal * step / len(picked))
        chosen = markers[(np.floor(np.arange(LEFT_OUT_PER_FRAME) * step).astype(int) + shift) % n]
        d = np.zeros((len(chosen), len(kinds)))
        for row, i in enumerate(chosen):
            x = frames[f : f + 1].copy()
            x[0, i] = np.nan
            for kind, (fit, local) in enumerate(kinds):
                res = model.solve(
                    x, marker_noise=sigma, quiet=True, temporal=False, local_fits=local, fit=fit
                )
                d[row, kind] = np.linalg.norm(np.asarray(res.bundle_positions)[0, i] - frames[f, i])
        dist[ordinal] = d

    def rule(base: int, first: int, second: int | None) -> tuple[bool | str, list[int]]:
        """The looks: every LOOKS-th picked frame joins at its look; local fits (`first`) are
        used when their saving over `base` is significant, `second` (unbounded) instead when
        its saving is too and larger; stop then or when the first saving is < 0."""
        read: list[int] = []
        for look in range(LOOKS):
            read += [o for o in range(len(picked)) if o % LOOKS == look]
            s = np.array([dist[o][:, base].mean() - dist[o].mean(axis=0) for o in read])
            mean, se = s.mean(axis=0), s.std(axis=0, ddof=1) / np.sqrt(len(read))
            crossed = mean > LOOK_SIGNIFICANCE * se
            if crossed[first]:
                if second is None:
                    return UNBOUNDED, read
                bigger = crossed[second] and mean[second] > mean[first]
                return (UNBOUNDED if bigger else True), read
            if mean[first] < 0:
                break
        return False, read

    choice, read = rule(0, 1, 2)
    assert got.local_fits == choice
    assert got.frames == len(read) and got.left_out == len(read) * LEFT_OUT_PER_FRAME
    all_read = np.vstack([dist[o] for o in read]).mean(axis=0)
    np.testing.assert_allclose(got.error_without, all_read[0], rtol=1e-9)
    np.testing.assert_allclose(got.error_with, all_read[1], rtol=1e-6)
    if choice:
        np.testing.assert_allclose(got.error_unbounded, all_read[2], rtol=1e-6)
    else:  # unbounded ones are read only once bounded ones have saved
        assert np.isnan(got.error_unbounded)
    # With the unbounded global fit: its solve against unbounded local fits alone.
    choice, read = rule(3, 2, None)
    assert free.local_fits == choice and free.frames == len(read)
    all_read = np.vstack([dist[o] for o in read]).mean(axis=0)
    np.testing.assert_allclose(free.error_without, all_read[3], rtol=1e-9)
    np.testing.assert_allclose(free.error_unbounded, all_read[2], rtol=1e-6)
    assert np.isnan(free.error_with)
    with pytest.raises(InputError, match="frames_used must be >= 1, got -1"):
        lgi.estimate_local_fits(frames, model, marker_noise=sigma, frames_used=-1)
    with pytest.raises(InputError, match="fit: expected None, True or 'unbounded', got 'free'"):
        lgi.estimate_local_fits(frames, model, marker_noise=sigma, fit="free")


def test_the_looks_boundary_is_crossed_by_chance_as_often_as_one_look_at_significance() -> None:
    from scipy.stats import norm

    from lgi.plan.detail import SIGNIFICANCE
    from lgi.plan.local import LOOK_SIGNIFICANCE, LOOKS

    # With no saving, the looks' cumulative means are a random walk's scaled partial sums.
    steps = np.random.default_rng(5).standard_normal((1_000_000, LOOKS))
    z = np.cumsum(steps, axis=1) / np.sqrt(np.arange(1, LOOKS + 1))
    crossed = (z > LOOK_SIGNIFICANCE).any(axis=1).mean()
    one_look = norm.sf(SIGNIFICANCE)
    assert abs(crossed - one_look) < 0.0006, (crossed, one_look)
    # A single look at the same boundary would be stricter: the looks are what it pays for.
    assert (z[:, 0] > LOOK_SIGNIFICANCE).mean() < 0.7 * one_look


def test_unbounded_local_fits_that_save_nothing_are_chosen_by_chance_no_more_than_one_look() -> (
    None
):
    from scipy.stats import norm

    from lgi.plan.detail import SIGNIFICANCE
    from lgi.plan.local import LOOK_SIGNIFICANCE, LOOKS

    # Bounded local fits that save (their walk drifts up, so they cross), unbounded ones that
    # save no more than nothing: the unbounded kind is chosen only when its own walk crosses,
    # at the bounded kind's look, so by chance no more often than one look at significance.
    rng = np.random.default_rng(6)
    steps = rng.standard_normal((400_000, 2, LOOKS))
    steps[:, 0] += 6.0
    z = np.cumsum(steps, axis=2) / np.sqrt(np.arange(1, LOOKS + 1))
    first = np.argmax(z[:, 0] > LOOK_SIGNIFICANCE, axis=1)
    at = z[np.arange(len(z)), :, first]
    chosen = (at[:, 1] > LOOK_SIGNIFICANCE) & (at[:, 1] > at[:, 0])
    assert (z[:, 0] > LOOK_SIGNIFICANCE).any(axis=1).all()
    assert chosen.mean() <= norm.sf(SIGNIFICANCE), chosen.mean()


def test_the_local_fits_estimate_says_what_it_cannot_read() -> None:
    from lgi.plan.leave_out import leave_markers_out

    x = np.zeros((3, 5, 3))
    with pytest.raises(InputError, match="local fits: no frame has more than"):
        leave_markers_out(np.full((3, 5, 3), np.nan), 4, what="local fits")
    with pytest.raises(InputError, match="frames_used must be >= 1"):
        leave_markers_out(x, 0)
    rows = leave_markers_out(np.zeros((10, 40, 3)), 3, per_frame=8)
    # 3 frames, 8 different markers each, shifted from frame to frame.
    assert rows.frames.shape == (24, 40, 3) and np.isnan(rows.frames).any(axis=2).sum() == 24
    sets = [set(rows.marker[rows.frame == f].tolist()) for f in rows.picked]
    assert all(len(s) == 8 for s in sets) and sets[0] != sets[1]


def test_cli_local_fits_auto_says_its_choice_and_records_it(
    tmp_path: Path,
    sample,
    capsys,  # type: ignore[no-untyped-def]
) -> None:
    from lgi.app import cli

    model_path, take, out, frames = _c3d_take(tmp_path, sample)
    argv = ["solve", str(model_path), str(take), "-o", str(out), "--local-fits", "auto"]
    assert cli.main([*argv, "--marker-noise", "0.01"]) == 0
    err = capsys.readouterr().err
    line = next(ln for ln in err.splitlines() if "local fits" in ln and "left out" in ln)
    said: bool | str = "unbounded" if "used, unbounded" in line else "local fits used" in line
    with np.load(out) as z:
        settings = SolveSettings.from_json(str(z["solve_settings"]), "o.npz")
    model = lgi.Model.load(model_path)
    x = (frames * 10.0).astype(np.float32).astype(np.float64) / 10.0
    est = lgi.estimate_local_fits(x, model, marker_noise=0.01)
    assert settings.local_fits == est.local_fits == said
    with pytest.raises(SystemExit) as stop:  # argparse's own errors
        cli.main(["solve", str(model_path), str(take), "-o", str(out), "--local-fits", "maybe"])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and "lgi: error:" in err, err
    assert "--local-fits: expected no value, 'unbounded' or 'auto', got 'maybe'" in err, err


def test_a_dropped_marker_does_not_throw_unbounded_local_fits_off_the_face(rom_scans) -> None:  # type: ignore[no-untyped-def]
    # The scans protocol's setting (docs/results.md, "A dropped marker"): 120 whole-face scans
    # from one Live Link recording, frames of the other on 160 random markers. Without their
    # rows refilled by the global fit, unbounded windows that lost a marker extrapolated to its
    # place: up to 7 cm of error where the unbounded global fit had 0.7 (on these 12 frames
    # 1.21 against 0.58 cm; refilled 0.59).
    from lgi.lab.capture import make_capture

    data, hinge, rom, markers, model = rom_scans
    take = make_capture(
        data,
        rom[:: rom.shape[0] // 12][:12],
        markers,
        sigma=0.0,
        dropout=0.0,
        holdout=0.0,
        seed=3,
        jaw=hinge,
    )
    frames = take.frames.copy()
    frames[np.arange(12), (72 + 13 * np.arange(12)) % 160] = np.nan  # one marker a frame
    skin = ict.skin()
    worst = {}
    for name, kw in (("global", {"fit": "unbounded"}), ("local", {"local_fits": "unbounded"})):
        res = model.solve(frames, marker_noise=0.0, quiet=True, temporal=False, **kw)
        worst[name] = np.linalg.norm(res.vertices[:, skin] - take.truth[:, skin], axis=2).max()
    assert worst["local"] < 1.5 * worst["global"], worst


def test_the_cores_local_surface_is_the_blend_posed_and_corrected_step_by_step(solved) -> None:  # type: ignore[no-untyped-def]
    """`_lgi.LocalSurface` makes each frame's blend, jaw pose, corrective and marker positions in
    one call; the same steps made one after another with the binding's separate functions
    (`blend_local`, `JawRig.skin`, `RbfInterpolator.interpolate`, `Model.bundle_positions`)
    must give the same bits, dropouts included."""
    from lgi.solve.local import _blend

    _, model, frames, sigma = solved
    given = frames.copy()
    given[2, 3] = np.nan
    given[5, [0, 7]] = np.nan
    res = model.solve(given, marker_noise=sigma, quiet=True)
    pieces = local_pieces(model)
    assert pieces.rig is not None  # the jaw's step is in the comparison
    for bounded in (True, False):
        targets, weights, theta = pieces._fits(res, bounded)
        blend = _blend(pieces.neutral, pieces.shapes, pieces._sew_rows, weights)
        posed = pieces.rig.skin(blend, theta)
        want = posed + pieces.corrective.interpolate(targets - model.bundle_positions(posed))
        got, at = pieces.surface_and_markers(res, bounded=bounded)
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(at, model.bundle_positions(want))


def test_the_local_surface_refuses_an_output_it_cannot_write_in_our_words(solved) -> None:  # type: ignore[no-untyped-def]
    _, model, frames, sigma = solved
    res = model.solve(frames[:3], marker_noise=sigma, quiet=True)
    pieces = local_pieces(model)
    targets, weights, theta = pieces._fits(res, True)
    v = pieces.neutral.shape[0]
    with pytest.raises(InputError, match=r"out: expected shape"):
        pieces._surface.surface(weights, targets, np.empty((3, v + 1, 3)), theta)
    frozen = np.empty((3, v, 3))
    frozen.flags.writeable = False
    with pytest.raises(InputError, match=r"not writeable"):
        pieces._surface.surface(weights, targets, frozen, theta)
