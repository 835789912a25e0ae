"""The unbounded global fit (`Model.solve(fit="unbounded")`, `--unbounded-fit`): each frame's
weights by least squares with the fit's ridge alone, at the jaw pose the boxed fit refined.
Checked against numpy's closed-form ridge of the jaw-unskinned markers (an independent
reference: the rig's own unskinning, the shapes sampled at the markers), for giving back a
face whose weights leave [0, 1], for the local fits it implies, and for clear errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import lgi
from fit_reference import fit_reference
from lgi import _lgi
from lgi.io.settings import SolveSettings


def test_unbounded_fit_weights_equal_numpys_ridge_of_the_unskinned_markers_at_the_boxed_pose(
    outside_the_box,  # type: ignore[no-untyped-def]
) -> None:
    model, frames, _ = outside_the_box
    boxed = model.solve(frames, jaw="fit", fit=True, steady=False, quiet=True)
    free = model.solve(frames, jaw="fit", fit="unbounded", steady=False, quiet=True)
    # The pose is the boxed fit's, bit for bit.
    np.testing.assert_array_equal(free.jaw_theta, boxed.jaw_theta)
    # Reference: the markers unskinned by that pose with each bundle's jaw weight, fitted by
    # the shapes' marker positions unskinned the same way by each shape's own pose, ridge
    # FIT_L2 x the mean squared column norm.
    theta = np.asarray(boxed.jaw_theta)
    a, rest, markers = fit_reference(model, frames, theta)
    ridge = _lgi.FIT_L2 * np.mean(np.sum(a**2, axis=0))
    for f in range(len(frames)):
        present = np.repeat(np.isfinite(frames[f]).all(axis=1), 3)
        rows = a[present]
        rhs = (markers[f] - rest).reshape(-1)[present]
        want = np.linalg.solve(rows.T @ rows + ridge * np.eye(a.shape[1]), rows.T @ rhs)
        np.testing.assert_allclose(free.fit_weights[f], want, rtol=0, atol=1e-9)
    # And they do leave [0, 1] where the boxed ones cannot.
    assert free.fit_weights.min() < -0.5 and free.fit_weights.max() > 1.5
    assert boxed.fit_weights.min() > -0.1 and boxed.fit_weights.max() < 1.1


def test_the_recommended_solve_with_the_unbounded_fit_gives_back_a_face_outside_the_box(
    outside_the_box,  # type: ignore[no-untyped-def]
) -> None:
    model, frames, truth = outside_the_box

    def error(**kw: object) -> float:
        res = model.solve(frames, marker_noise=0.0, steady=False, quiet=True, **kw)  # type: ignore[arg-type]
        return float(np.linalg.norm(res.vertices - truth, axis=2).mean())

    boxed, free = error(fit=True), error(fit="unbounded")
    # Measured 0.0083 against 0.00032 (the sample's face is about 23 units across).
    assert free < 0.1 * boxed, (free, boxed)
    # Unbounded local fits start from it (measured 0.0012 at sigma 0.01).
    # (The frames are independent faces, not a take: each solved alone.)
    res = model.solve(frames, marker_noise=0.01, local_fits="unbounded", steady=False, quiet=True)
    alone = model.solve(frames, marker_noise=0.01, fit="unbounded", steady=False, quiet=True)
    np.testing.assert_array_equal(res.fit_weights, alone.fit_weights)
    assert np.linalg.norm(res.vertices - truth, axis=2).mean() < 0.5 * boxed


def test_solve_iter_with_the_unbounded_fit_equals_one_solve(outside_the_box) -> None:  # type: ignore[no-untyped-def]
    model, frames, _ = outside_the_box
    one = model.solve(frames, marker_noise=0.01, fit="unbounded", quiet=True)
    parts = list(model.solve_iter(frames, chunk=4, marker_noise=0.01, fit="unbounded", quiet=True))
    np.testing.assert_array_equal(np.concatenate([p.vertices for p in parts]), one.vertices)
    np.testing.assert_array_equal(np.concatenate([p.fit_weights for p in parts]), one.fit_weights)


def test_a_fit_argument_lgi_does_not_know_is_an_input_error(outside_the_box) -> None:  # type: ignore[no-untyped-def]
    model, frames, _ = outside_the_box
    for bad in ("Unbounded", "free", 2.0):
        with pytest.raises(lgi.InputError, match="fit must be True, False, None, 'unbounded'"):
            model.solve(frames, fit=bad, quiet=True)  # type: ignore[arg-type]


def test_solve_settings_record_the_unbounded_fit_and_older_files_read_as_boxed() -> None:
    s = SolveSettings.of(
        has_jaw_rig=True, jaw="auto", marker_noise=0.05, detail_weight=None, unbounded_fit=True
    )
    back = SolveSettings.from_json(s.to_json(), "x.npz")
    assert back == s and back.unbounded_fit
    assert back.describe("cm").endswith(", unbounded fit, each frame alone (lgi " + s.version + ")")
    # Unbounded local fits imply it, and say so once.
    u = SolveSettings.of(
        has_jaw_rig=True, jaw="auto", marker_noise=0.05, detail_weight=None, local_fits="unbounded"
    )
    assert u.unbounded_fit and u.pieces() == ", unbounded local fits"
    old = '{"detail_weight": null, "jaw": "auto", "marker_noise": 0.05, "version": "0.1.0"}'
    assert not SolveSettings.from_json(old, "old.npz").unbounded_fit
    bad = old[:-1] + ', "unbounded_fit": "yes"}'
    with pytest.raises(lgi.InputError, match=r"bad\.npz: unbounded_fit must be true or false"):
        SolveSettings.from_json(bad, "bad.npz")


def test_cli_unbounded_fit_writes_what_model_solve_gives_and_records_it(
    tmp_path: Path,
    sample,
    capsys,  # type: ignore[no-untyped-def]
) -> None:
    from lgi.app import cli
    from pipeline_files import build_actor, write_c3d

    actor, model_path = build_actor(tmp_path, sample)
    frames = np.asarray(sample.performance[:12], dtype=np.float64)
    take, out = tmp_path / "take.c3d", tmp_path / "o.npz"
    write_c3d(take, frames * 10.0, list(actor.names), 60.0, "mm")
    argv = ["solve", str(model_path), str(take), "-o", str(out), "--marker-noise", "0.01"]
    assert cli.main([*argv, "--unbounded-fit"]) == 0
    err = capsys.readouterr().err
    assert "marker noise 0.01, unbounded fit" in err, err
    with np.load(out) as z:
        got = z["vertices"]
        settings = SolveSettings.from_json(str(z["solve_settings"]), "o.npz")
    assert settings.unbounded_fit and not settings.local_fits
    model = lgi.Model.load(model_path)
    x = (frames * 10.0).astype(np.float32).astype(np.float64) / 10.0
    want = model.solve(x, marker_noise=0.01, quiet=True, fit="unbounded")
    np.testing.assert_allclose(got, want.vertices, rtol=0, atol=1e-6 * model.diagonal)
    boxed = model.solve(x, marker_noise=0.01, quiet=True)
    assert np.abs(boxed.vertices - want.vertices).max() > 1e-4 * model.diagonal
    # lgi info says how it was solved.
    assert cli.main(["info", str(out)]) == 0
    assert "unbounded fit" in capsys.readouterr().out
    # auto: the take's own markers decide, the choice said and recorded (the sample's
    # performance has every weight inside the box: measured "not used").
    auto = tmp_path / "auto.npz"
    argv = ["solve", str(model_path), str(take), "-o", str(auto), "--marker-noise", "0.01"]
    assert cli.main([*argv, "--unbounded-fit", "auto"]) == 0
    err = capsys.readouterr().err
    est = lgi.estimate_unbounded_fit(x, model, marker_noise=0.01)
    said = "unbounded fit used:" if est.use else "unbounded fit not used:"
    assert said in err and "with the fit held to [0, 1]" in err, err
    with np.load(auto) as z:
        assert SolveSettings.from_json(str(z["solve_settings"]), "a.npz").unbounded_fit is est.use
    # Both auto: the local fits first (on the boxed solve); the fit only where they are not used.
    both = tmp_path / "both.npz"
    argv_both = ["solve", str(model_path), str(take), "-o", str(both), "--marker-noise", "0.01"]
    assert cli.main([*argv_both, "--unbounded-fit", "auto", "--local-fits", "auto"]) == 0
    capsys.readouterr()
    local = lgi.estimate_local_fits(x, model, marker_noise=0.01).local_fits
    free = local == "unbounded" if local else est.use
    with np.load(both) as z:
        got = SolveSettings.from_json(str(z["solve_settings"]), "b.npz")
    assert (got.local_fits, got.unbounded_fit) == (local, free)
    with pytest.raises(SystemExit) as stop:  # argparse's own errors
        cli.main([*argv, "--unbounded-fit", "Auto", "--force"])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and "lgi: error:" in err, err
    assert "argument --unbounded-fit: expected no value or 'auto', got 'Auto'" in err, err


def _brute_force_choice(model, frames, sigma, per_look):  # type: ignore[no-untyped-def]
    """`estimate_unbounded_fit`'s rule from its definition: each left-out row solved on its
    own with the boxed and the unbounded fit; the looks read every LOOKS-th picked frame; used
    when the mean per-frame saving clears LOOK_SIGNIFICANCE standard errors, stopped when it is
    negative. Returns (use, frames read, mean distances boxed and unbounded over them)."""
    from lgi.plan.local import LEFT_OUT_PER_FRAME, LOOK_SIGNIFICANCE, LOOKS

    present = np.isfinite(frames).all(axis=2)
    usable = np.flatnonzero(present.sum(axis=1) > _lgi.MIN_PRESENT_MARKERS)
    at = np.unique(np.linspace(0, usable.size - 1, LOOKS * per_look).round().astype(int))
    picked = usable[at]
    dist = []
    for ordinal, f in enumerate(picked):
        markers = np.flatnonzero(present[f])
        n = markers.size
        if LEFT_OUT_PER_FRAME < n:
            step = n / LEFT_OUT_PER_FRAME
            shift = int(ordinal * step / len(picked))
            markers = markers[
                (np.floor(np.arange(LEFT_OUT_PER_FRAME) * step).astype(int) + shift) % n
            ]
        d = np.zeros((markers.size, 2))
        for row, i in enumerate(markers):
            x = frames[f : f + 1].copy()
            x[0, i] = np.nan
            for kind, fit in enumerate((None, "unbounded")):
                res = model.solve(x, marker_noise=sigma, quiet=True, temporal=False, fit=fit)
                d[row, kind] = np.linalg.norm(np.asarray(res.bundle_positions)[0, i] - frames[f, i])
        dist.append(d)
    read: list[int] = []
    use = False
    for look in range(LOOKS):
        read += [o for o in range(len(picked)) if o % LOOKS == look]
        s = np.array([dist[o][:, 0].mean() - dist[o][:, 1].mean() for o in read])
        if len(read) < 2:
            continue
        mean, se = s.mean(), s.std(ddof=1) / np.sqrt(len(read))
        if mean > LOOK_SIGNIFICANCE * se:
            use = True
            break
        if mean < 0:
            break
    return use, len(read), np.vstack([dist[o] for o in read]).mean(axis=0)


def test_the_unbounded_fit_estimate_is_the_left_out_markers_distance_both_ways(
    outside_the_box,  # type: ignore[no-untyped-def]
    sample,
    noise_aware_sample,
) -> None:
    model, frames, _ = outside_the_box
    noisy = frames + np.random.default_rng(7).normal(0.0, 0.01, frames.shape)
    faces, sigma = noise_aware_sample
    # A take outside the box (the unbounded fit should win) and the sample's own performance,
    # every weight inside it (it should not).
    for m, take, s in ((model, noisy, 0.01), (faces, sample.performance[:24], sigma)):
        got = lgi.estimate_unbounded_fit(take, m, marker_noise=s, frames_used=2)
        use, read, means = _brute_force_choice(m, take, s, 2)
        assert got.use == use and got.frames == read
        assert got.fit == ("unbounded" if use else None)
        np.testing.assert_allclose([got.error_boxed, got.error_unbounded], means, rtol=1e-9)
    assert lgi.estimate_unbounded_fit(noisy, model, marker_noise=0.01, frames_used=2).use
    with pytest.raises(lgi.InputError, match=r"frames: expected shape \(F, "):
        lgi.estimate_unbounded_fit(noisy[:, :4], model, marker_noise=0.01)


@pytest.mark.parametrize(
    ("local_read", "fit_read", "want", "reads"),
    [
        ("unbounded", None, ("unbounded", True), ["local"]),
        (True, None, (True, False), ["local"]),
        (False, True, (False, True), ["local", "fit"]),
        (False, False, (False, False), ["local", "fit"]),
    ],
)
def test_both_auto_read_the_local_fits_first_and_the_fit_only_without_them(
    monkeypatch: pytest.MonkeyPatch,
    local_read: bool | str,
    fit_read: bool | None,
    want: tuple[bool | str, bool],
    reads: list[str],
) -> None:
    from lgi.plan import choices

    calls: list[str] = []

    def local_choice(spec, frames, model, sigma, jaw, say, fit=None, readings=None):  # type: ignore[no-untyped-def]
        calls.append("local")
        assert spec == "auto" and fit is None  # read on the boxed solve
        return local_read

    def fit_choice(spec, frames, model, sigma, jaw, say, prior=False, readings=None):  # type: ignore[no-untyped-def]
        calls.append("fit")
        assert spec == "auto" and prior is False  # no --take-prior here
        return fit_read

    monkeypatch.setattr(choices, "local_fits_choice", local_choice)
    monkeypatch.setattr(choices, "unbounded_fit_choice", fit_choice)
    got = choices.fits_choice("auto", "auto", np.zeros((1, 1, 3)), None, 0.1, "auto", print)  # type: ignore[arg-type]
    assert got == want and calls == reads


def test_unbounded_local_fits_given_bring_the_unbounded_fit_without_reading_anything(
    outside_the_box,  # type: ignore[no-untyped-def]
) -> None:
    from lgi.plan import choices

    model, frames, _ = outside_the_box
    said: list[str] = []
    got = choices.fits_choice("unbounded", False, frames, model, 0.01, "auto", said.append)
    assert got == ("unbounded", True) and said == []
    assert choices.fits_choice(True, False, frames, model, 0.01, "auto", said.append) == (
        True,
        False,
    )
