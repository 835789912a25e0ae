"""A take's own motion (`lgi.solve.motion`): its directions are the centred take's singular
vectors, and what it predicts of hidden coordinates is the Gaussian conditional mean, checked
against the covariance written out in full and conditioned directly."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lgi.solve.motion import TakeMotion, read_motion


def _low_rank_take(
    frames: int, markers: int, rank: int, noise: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Frames (F, B, 3) moving in `rank` random directions plus white noise, and their mean."""
    rng = np.random.default_rng(seed)
    mean = rng.normal(size=3 * markers)
    basis = rng.normal(size=(rank, 3 * markers))
    weights = rng.normal(size=(frames, rank)) * np.linspace(3.0, 1.0, rank)
    flat = mean + weights @ basis + noise * rng.normal(size=(frames, 3 * markers))
    return flat.reshape(frames, markers, 3), mean


def test_the_motions_directions_are_the_centred_takes_leading_right_singular_vectors() -> None:
    x, _ = _low_rank_take(80, 10, 4, 0.01, seed=1)
    motion = read_motion(x, 0.01, 6)
    assert motion is not None and motion.rank == 6
    flat = x.reshape(80, -1)
    centred = flat - flat.mean(axis=0)
    _, sv, vt = np.linalg.svd(centred, full_matrices=False)
    np.testing.assert_allclose(motion.mean, flat.mean(axis=0), atol=1e-12)
    # Each direction up to its sign, the spectrum the variance along each.
    np.testing.assert_allclose(np.abs(np.sum(motion.directions * vt[:6], axis=1)), 1.0, atol=1e-9)
    np.testing.assert_allclose(motion.spectrum[:30], sv[:30] ** 2 / 79, rtol=1e-9)
    # Probabilistic PCA's noise at rank r: the mean variance of the 30 - r directions beyond
    # (Tipping & Bishop), at least the noise given.
    for r in (2, 4, 6):
        beyond = np.sum(sv[r:] ** 2 / 79) / (30 - r)
        assert motion.noise_at(r) == pytest.approx(np.sqrt(max(beyond, 0.01**2)), rel=1e-9)
    assert motion.noise_at(2) > 0.1 > 0.01 == pytest.approx(motion.noise_at(4), rel=0.2)


def test_a_motion_read_from_a_take_with_a_marker_never_seen_leaves_that_marker_out() -> None:
    x, _ = _low_rank_take(40, 6, 2, 0.0, seed=2)
    x[:, 3] = np.nan
    motion = read_motion(x, 0.0, 3)
    assert motion is not None
    assert np.all(np.isfinite(motion.mean)) and np.abs(motion.directions[:, 9:12]).max() < 1e-12


def test_too_short_a_take_or_one_that_does_not_move_has_no_motion() -> None:
    x, _ = _low_rank_take(1, 5, 1, 0.0, seed=3)
    assert read_motion(x, 0.0, 2) is None
    still = np.zeros((20, 5, 3))
    assert read_motion(still, 0.01, 2) is None  # no direction above the noise


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    rank=st.integers(1, 5),
    used=st.integers(1, 5),
    hidden_count=st.integers(1, 12),
    noise=st.sampled_from([0.0, 0.001, 0.05]),
)
def test_a_prediction_is_the_conditional_mean_of_the_gaussian_the_motion_describes(
    seed: int, rank: int, used: int, hidden_count: int, noise: float
) -> None:
    rng = np.random.default_rng(seed)
    p = 24
    q, _ = np.linalg.qr(rng.normal(size=(p, rank)))
    variances = np.sort(rng.uniform(0.5, 4.0, rank))[::-1]
    motion = TakeMotion(
        mean=rng.normal(size=p),
        directions=q.T,
        spectrum=np.r_[variances + noise**2, np.full(p - rank, noise**2)],
        coordinates=p,
        noise=noise,
    )
    r = min(used, rank)
    rows = rng.normal(size=(3, p))
    hidden = np.zeros((3, p), dtype=bool)
    for i in range(3):
        hidden[i, rng.choice(p, size=hidden_count, replace=False)] = True
    rows[hidden] = np.nan  # a hidden coordinate may be missing
    got = motion.predictions(rows, hidden, [r])[0]
    v = motion.directions[:r]
    sigma = motion.noise_at(r)  # the noise given, and the directions beyond r as noise
    lam = motion.spectrum[:r] - sigma**2
    for i in range(3):
        o, h = ~hidden[i], hidden[i]
        if sigma > 0.0:
            # x = μ + Vᵀ a + e, a ~ N(0, Λ), e ~ N(0, sigma² I): its covariance written out and
            # the hidden coordinates conditioned on the others directly.
            cov = (v.T * lam) @ v + sigma**2 * np.eye(p)
            want = motion.mean[h] + cov[np.ix_(h, o)] @ np.linalg.solve(
                cov[np.ix_(o, o)], rows[i, o] - motion.mean[o]
            )
        else:
            # Noise-free: the directions' weights that reproduce the seen coordinates.
            a = np.linalg.lstsq(v[:, o].T, rows[i, o] - motion.mean[o], rcond=None)[0]
            want = (motion.mean + a @ v)[h]
        np.testing.assert_allclose(got[i, h], want, atol=1e-6)


def test_the_first_directions_of_a_motion_predict_as_the_motion_of_that_rank() -> None:
    x, _ = _low_rank_take(60, 8, 5, 0.02, seed=4)
    motion = read_motion(x, 0.02, 5)
    assert motion is not None
    flat = x.reshape(60, -1)[:4]
    hidden = np.zeros(flat.shape, dtype=bool)
    hidden[:, :6] = True
    both = motion.predictions(flat, hidden, [2, 5])
    np.testing.assert_allclose(both[0], motion.truncated(2).predictions(flat, hidden, [2])[0])
    np.testing.assert_allclose(both[1], motion.predictions(flat, hidden, [5])[0])
