"""`lgi.denoise_take`: a take's markers denoised by its own low-rank structure (Gavish & Donoho's
optimal shrinker with the known noise), checked against the closed form, a synthetic take of
known rank, and `lgi solve --denoise` end to end."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lgi
from lgi.errors import InputError
from lgi.plan.denoise import _mp_median, _signal, bulk_noise


def low_rank_take(frames: int, markers: int, rank: int, seed: int) -> np.ndarray:
    """A take (F, B, 3) whose motion lies in `rank` directions about a rest pose (cm-sized)."""
    rng = np.random.default_rng(seed)
    motion = rng.normal(size=(frames, rank)) @ rng.normal(size=(rank, 3 * markers)) * 0.3
    return motion.reshape(frames, markers, 3) + rng.normal(size=(1, markers, 3))


def test_denoise_take_keeps_the_motions_directions_and_leaves_the_noise_it_says() -> None:
    truth = low_rank_take(300, 100, 8, 0)
    rng = np.random.default_rng(1)
    for sigma in (0.02, 0.05, 0.2):
        noisy = truth + rng.normal(0.0, sigma, truth.shape)
        den = lgi.denoise_take(noisy, sigma)
        assert den.rank == 8 and den.directions == 299
        assert den.input_noise == sigma
        rms = float(np.sqrt(np.mean((den.frames - truth) ** 2)))
        # Measured: 0.238 x sigma left (8 directions of 300 x 300 and the mean), predicted to 1 %.
        assert rms < 0.3 * sigma
        assert den.marker_noise == pytest.approx(rms, rel=0.05)


def test_denoise_take_is_the_optimal_shrinker_of_the_centred_take_in_closed_form() -> None:
    # Gavish & Donoho (2017), eq. (7) for the Frobenius loss, written out here with numpy's
    # SVD: eta(y) = sqrt((y^2 - beta - 1)^2 - 4 beta) / y above 1 + sqrt(beta), else 0, with
    # y the singular value over sqrt(n) sigma (n the larger side of the centred matrix).
    truth = low_rank_take(120, 50, 5, 2)
    sigma = 0.05
    noisy = truth + np.random.default_rng(3).normal(0.0, sigma, truth.shape)
    x = noisy.reshape(120, 150)
    mean = x.mean(axis=0)
    u, s, vt = np.linalg.svd(x - mean, full_matrices=False)
    n, m = 150, 119
    beta = m / n
    y = s / (np.sqrt(n) * sigma)
    eta = np.where(
        y > 1 + np.sqrt(beta),
        np.sqrt(np.clip((y**2 - beta - 1) ** 2 - 4 * beta, 0, None)) / y,
        0.0,
    )
    expected = (u * (eta * np.sqrt(n) * sigma)) @ vt + mean
    got = lgi.denoise_take(noisy, sigma)
    np.testing.assert_allclose(got.frames.reshape(120, 150), expected, atol=1e-12)
    assert got.rank == int((eta > 0).sum())


@settings(max_examples=30, deadline=None)
@given(x=st.floats(0.8, 50.0), beta=st.floats(0.05, 1.0))
def test_signal_is_the_inverse_of_where_a_spike_lands_in_the_noisy_spectrum(
    x: float, beta: float
) -> None:
    # A spike of strength x above beta^(1/4) lands at y = sqrt((x^2 + 1)(x^2 + beta)) / x.
    if x <= beta**0.25 * 1.01:
        return
    y = np.sqrt((x**2 + 1) * (x**2 + beta)) / x
    assert float(_signal(np.array([y]), beta)[0]) == pytest.approx(x, rel=1e-7)


def test_denoise_take_fills_dropouts_from_the_motion_and_leaves_them_missing() -> None:
    truth = low_rank_take(300, 100, 8, 0)
    rng = np.random.default_rng(1)
    sigma = 0.02
    noisy = truth + rng.normal(0.0, sigma, truth.shape)
    drop = rng.random((300, 100)) < 0.02
    noisy[drop] = np.nan
    den = lgi.denoise_take(noisy, sigma)
    assert np.isnan(den.frames[drop]).all() and np.isfinite(den.frames[~drop]).all()
    # The dropouts do not add directions of their own (hard impute run until settled; stopped
    # early it kept 13 here), and the present samples are denoised as well as without them.
    assert den.rank == 8
    rms = float(np.sqrt(np.mean((den.frames[~drop] - truth[~drop]) ** 2)))
    assert rms < 0.3 * sigma


def test_denoise_take_returns_a_noise_free_or_one_frame_take_as_it_is() -> None:
    take = low_rank_take(10, 20, 3, 4)
    same = lgi.denoise_take(take, 0.0)
    np.testing.assert_array_equal(same.frames, take)
    assert same.marker_noise == 0.0
    one = lgi.denoise_take(take[:1], 0.05)
    np.testing.assert_allclose(one.frames, take[:1], atol=1e-15)
    assert one.rank == 0 and one.marker_noise == pytest.approx(0.05)


def test_denoise_take_never_says_it_left_more_noise_than_it_was_given() -> None:
    # Three frames of pure noise: no direction is kept, and the mean carries sigma^2 / 3.
    rng = np.random.default_rng(5)
    den = lgi.denoise_take(rng.normal(0.0, 0.1, (3, 40, 3)), 0.1)
    assert den.marker_noise <= 0.1


@pytest.mark.parametrize(
    "frames, sigma, message",
    [
        (np.zeros((4, 5)), 0.1, r"shape \(F, B, 3\)"),
        (np.full((4, 5, 3), np.inf), 0.1, "frame 0, marker 0 is infinite"),
        (np.zeros((4, 5, 3)), -0.1, "finite number >= 0"),
        (np.zeros((4, 5, 3)), float("nan"), "finite number >= 0"),
        (np.zeros((4, 5, 3)), True, "finite number >= 0"),
    ],
)
def test_denoise_take_refuses_bad_input_in_its_own_words(
    frames: np.ndarray, sigma: float, message: str
) -> None:
    with pytest.raises(InputError, match=message):
        lgi.denoise_take(frames, sigma)


def test_lgi_solve_denoise_says_what_it_kept_and_measures_residuals_on_the_given_markers(
    sample, noise_aware_sample, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:  # type: ignore[no-untyped-def]
    from lgi.app.cli import main
    from lgi.io.result import read_result_npz

    model, sigma = noise_aware_sample
    model_path = tmp_path / "m.lgi"
    model.save(model_path)
    markers = np.asarray(sample.performance, dtype=np.float64).copy()
    # A marker spiking 1.5 along x for 3 frames: the denoising takes most of it out of what
    # is solved, but the report reads the given markers, so it is still named (kept as given,
    # `--no-repair`).
    spiking = 7 if np.isfinite(markers[40:43, 7]).all() else 8
    markers[40:43, spiking, 0] += 1.5
    take = tmp_path / "take.npz"
    np.savez(take, markers=markers, names=np.array(model.marker_names), fps=30.0)
    out = tmp_path / "out.npz"
    noise = f"{sigma:.6g}"
    argv = ["solve", str(model_path), str(take), "-o", str(out), "--marker-noise", noise]
    assert main([*argv, "--denoise", "--no-repair"]) == 0
    said = capsys.readouterr().err
    assert "denoised the take:" in said and f"marker noise {float(noise):.4g} ->" in said, said
    spike = f"spike: {model.marker_names[spiking]}, time codes 40-42"
    assert spike in said, said
    findings = [line for line in said.splitlines() if "spike:" in line or "swap:" in line]
    r = read_result_npz(out)
    assert r.settings is not None and r.settings.denoised_from == pytest.approx(float(noise))
    assert r.settings.marker_noise is not None and r.settings.marker_noise < float(noise)
    assert r.settings.denoised_rank is not None and r.settings.denoised_rank > 0
    assert "the take denoised from" in r.settings.describe(r.units)
    # `lgi info` reads the file's residuals with the given markers' noise, as the solve did:
    # the same findings.
    assert main(["info", str(out)]) == 0
    info = capsys.readouterr().out
    assert spike in info
    assert sum("spike:" in line or "swap:" in line for line in info.splitlines()) == len(findings)
    # The residuals written are the given markers' distances from where the solve put them:
    # the surface written less the pulls that moved it to markers beyond their noise (the
    # same solve from Python: the take denoised, faults read at the given noise).
    den = lgi.denoise_take(markers, float(noise))
    ref = model.solve(
        den.frames,
        quiet=True,
        marker_noise=den.marker_noise,
        fault_noise=float(noise),
        repair=False,
    )
    assert np.array_equal(r.vertices, np.asarray(ref.vertices).astype(np.float32))
    assert ref.marker_pulls is not None and np.linalg.norm(ref.marker_pulls, axis=2).max() > 0
    on_surface = model.bundle_positions(np.asarray(r.vertices, dtype=np.float64))
    put = on_surface - ref.marker_pulls
    expected = np.nan_to_num(np.linalg.norm(markers - put, axis=2))  # 0: missing
    np.testing.assert_allclose(r.bundle_residuals, expected, atol=1e-5)  # float32 meshes
    # Repaired (the default), the spike is solved as missing and said so, denoised or not.
    assert main([*argv, "--denoise", "--force"]) == 0
    said = capsys.readouterr().err
    name = model.marker_names[spiking]
    assert f"repaired: {name} solved as missing (a spike), time codes 40-42" in said, said
    # Without a noise there is nothing to remove: an error in our words, exit 2.
    out2 = tmp_path / "out2.npz"
    bad = ["solve", str(model_path), str(take), "-o", str(out2), "--denoise"]
    assert main(bad) == 2
    assert "lgi: error: --denoise needs the markers' noise above 0" in capsys.readouterr().err
    assert not out2.exists()


def test_mp_median_is_the_marchenko_pastur_laws_median() -> None:
    # Gavish & Donoho 2014 give 0.6528 for the square case; random matrices agree elsewhere.
    assert _mp_median(1.0) == pytest.approx(0.6528, abs=2e-4)
    rng = np.random.default_rng(1)
    for p, n in ((100, 400), (300, 400)):
        ev = np.concatenate(
            [np.linalg.eigvalsh(a @ a.T / n) for a in (rng.normal(size=(p, n)) for _ in range(20))]
        )
        assert np.median(ev) == pytest.approx(_mp_median(p / n), rel=0.01)


@pytest.mark.parametrize("rank", [0, 10, 40, 80])
def test_bulk_noise_reads_white_noise_beside_low_rank_motion_with_dropouts(rank: int) -> None:
    rng = np.random.default_rng(rank)
    clean = low_rank_take(200, 120, rank, rank) if rank else np.zeros((200, 120, 3))
    for sigma in (0.02, 0.05):
        take = clean + rng.normal(0.0, sigma, clean.shape)
        take[rng.random((200, 120)) < 0.02] = np.nan
        # The fill carries no noise (2 % of the samples): at most a few percent low.
        assert bulk_noise(take, sigma) == pytest.approx(sigma, rel=0.04)
    noise_free = clean.copy()
    noise_free[rng.random((200, 120)) < 0.02] = np.nan
    # Noise-free: what the fill leaves once settled (measured 2e-6 to 5e-5 for ranks 40, 80).
    assert bulk_noise(noise_free, 0.01) < 0.01 * 0.02
    assert bulk_noise(clean[:3], 0.01) is None  # too few frames to have a spectrum
