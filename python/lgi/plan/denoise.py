"""A take's markers denoised by the take's own low-rank structure (empirical Bayes in marker
space).

A performance moves a face's markers in far fewer directions than they have coordinates: a
take of F frames of B markers is, but for the noise, close to a matrix of low rank (F by 3B).
Marker noise of a known level sigma per coordinate is white in that matrix. The take's centred
matrix is shrunk by the optimal singular-value shrinker for white noise of known level (Gavish
& Donoho 2017, Frobenius loss; the same shrinker the take's prior uses,
`lgi.solve.spectrum.shrinkage_factors`): directions inside the noise's bulk edge `1 + √β` carry no
motion that can be told from noise and are dropped, the others are shrunk to what the noise
leaves of them. Nothing is read from the dataset or a solve: the take alone, and sigma.

Missing samples (NaN) are filled by the low-rank estimate itself (hard impute: the take's
present samples kept, the missing ones replaced by the shrunk matrix's values until they
settle), so a dropout neither loses the directions its marker saw nor shows as motion; they
are NaN again in the result (a missing marker stays missing for the solve).

What noise is left: the shrinker's asymptotic mean squared error per kept direction is `x² -
η²` (x the direction's signal, recovered from its singular value; η what it is shrunk to), and
the mean over the frames carries `sigma² / F`; `DenoisedTake.marker_noise` is that error per
coordinate, the sigma the solve is then given. It is not white (it lies in the kept
directions), which the solve's noise model does not know; measured in docs/results.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi.errors import InputError
from lgi.solve.spectrum import shrinkage_factors, thin_svd

__all__ = ["DenoisedTake", "bulk_noise", "denoise_take"]

F64 = NDArray[np.float64]

#: Rounds of filling missing samples by the low-rank estimate at most, and the relative change
#: of the filled samples in a round below which they have settled. Hard impute converges
#: slowly where the first fill (each marker's mean) adds directions of its own, so it runs until
#: settled, not for a fixed number of rounds.
IMPUTE_ROUNDS = 1000
IMPUTE_SETTLED = 1e-6
#: Each round moves the missing samples this far past the new estimate (successive
#: over-relaxation: the same fixed point in fewer rounds).
IMPUTE_RELAXATION = 1.5

#: `bulk_noise` reads at most this many frames, spread over the take: enough to read white
#: noise's spectrum (frame spacing does not enter it) at a cost that does not grow with the take.
BULK_FRAMES = 400


@dataclass(frozen=True)
class DenoisedTake:
    """A take denoised by `denoise_take`: `frames` (F, B, 3; NaN where the input was missing),
    `marker_noise` the noise left per coordinate (what to solve them with), `input_noise` the
    sigma given, `rank` the directions of motion kept (of `directions`, the centred take's
    smaller dimension)."""

    frames: F64
    marker_noise: float
    input_noise: float
    rank: int
    directions: int


def _signal(y: F64, beta: float) -> F64:
    """A kept singular value's signal x (noise level 1, aspect `beta`): the inverse of
    y² = (x² + 1)(x² + β) / x², the position a spike of x takes in the noisy spectrum."""
    t = y**2 - 1.0 - beta
    return np.sqrt(0.5 * (t + np.sqrt(np.maximum(t**2 - 4.0 * beta, 0.0))))


def _shrink(centred: F64, sigma: float) -> tuple[F64, int, float]:
    """`centred` (F, p) with white noise `sigma` shrunk optimally: the estimate, how many
    directions were kept, and its expected squared error per entry."""
    f, p = centred.shape
    big, small = max(f - 1, p), min(f - 1, p)
    if small < 1:
        return np.zeros_like(centred), 0, 0.0
    scale = np.sqrt(big) * sigma

    def kept_count(sv: F64) -> int:
        # The shrinker keeps the singular values above the bulk edge: the leading ones.
        return int(np.count_nonzero(shrinkage_factors(sv / scale, small / big) > 0.0))

    u, sv, vt = thin_svd(centred, kept_count)
    y = sv / scale
    factors = shrinkage_factors(y, small / big)
    kept = factors > 0.0
    k = int(kept.sum())
    est = (u[:, :k] * (sv[:k] * factors[:k])) @ vt[:k]
    x = _signal(y[kept], small / big)
    eta = y[kept] * factors[kept]
    error = sigma**2 * float(np.sum(x**2 - eta**2)) / small
    return est, k, error


def _filled(flat: F64, missing: NDArray[np.bool_], sigma: float) -> tuple[F64, F64, int, float]:
    """The take `flat` (F, p) with its `missing` samples filled by hard impute at noise `sigma`
    (> 0): the filled take (present samples as given), its shrunk
    estimate, the directions kept and the shrinker's error per entry (`_shrink`)."""
    # A sample's first fill is its marker's mean over the frames it is present in (a marker
    # missing everywhere: 0, and it stays missing).
    counts = (~missing).sum(axis=0)
    means = np.where(counts > 0, np.nansum(flat, axis=0) / np.maximum(counts, 1), 0.0)
    filled = np.where(missing, means, flat)
    estimate, rank, error = filled, 0, 0.0
    for _ in range(IMPUTE_ROUNDS if missing.any() else 1):
        mean = filled.mean(axis=0)
        low, rank, error = _shrink(filled - mean, sigma)
        estimate = low + mean
        before = filled[missing]
        after = before + IMPUTE_RELAXATION * (estimate[missing] - before)
        filled[missing] = after
        change = float(np.linalg.norm(after - before))
        if change <= IMPUTE_SETTLED * max(float(np.linalg.norm(after)), 1e-300):
            break
    return filled, estimate, rank, error


def _mp_median(beta: float) -> float:
    """The median of the Marchenko-Pastur law of aspect `beta` (0 < beta <= 1) at unit noise:
    the squared singular values of a p x n (p <= n) white-noise matrix over n, by its density's
    cumulative integral on a fine grid (to about 1e-5)."""
    lo, hi = (1.0 - np.sqrt(beta)) ** 2, (1.0 + np.sqrt(beta)) ** 2
    # x = lo + (hi - lo) t²: the density's 1/sqrt(x) at beta = 1 becomes finite in t.
    t = np.linspace(0.0, 1.0, 100_001)
    x = lo + (hi - lo) * t**2
    dx_dt = 2.0 * (hi - lo) * t
    root = np.sqrt(np.maximum(hi - x, 0.0)) * np.sqrt(hi - lo) * t  # sqrt((hi - x)(x - lo))
    with np.errstate(divide="ignore", invalid="ignore"):
        per_t = np.where(x > 0.0, root * dx_dt / (2.0 * np.pi * beta * x), 0.0)
    if lo == 0.0:
        per_t[0] = 2.0 * np.sqrt(hi) * np.sqrt(hi) / (2.0 * np.pi * beta)  # the limit at t = 0
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (per_t[1:] + per_t[:-1]) * np.diff(t))])
    return float(np.interp(0.5 * cdf[-1], cdf, x))


def bulk_noise(frames: ArrayLike, fill_noise: float) -> float | None:
    """The markers' white noise sigma per coordinate read from the take's own spectrum (F, B,
    3; NaN missing): what its directions of motion leave. The centred take's squared singular
    values beyond its r strongest directions are, for white noise of sigma, those of an (m - r)
    x (n - r) noise matrix (m <= n its sides), whose median is sigma² (n - r) times the
    Marchenko-Pastur law's median (Gavish & Donoho 2014's estimate, deflated by the directions
    above the noise's bulk edge, r read again at each sigma until it stays; at most half the
    spectrum, so the median is the bulk's). Missing samples are first filled by hard impute at
    `fill_noise` (`_filled`: a fill's error only raises the reading). Frame spacing does not
    enter: motion between frames far apart is still motion in the take's few directions. A
    face's motion that is not low rank (a real performer's small motions, markers beyond the
    take's directions) counts as noise: an upper reading like the tracks'. None for fewer than
    4 frames or 2 coordinates."""
    arr = np.asarray(frames, dtype=np.float64)
    if arr.shape[0] > BULK_FRAMES:  # frames spread over the take: spacing does not matter
        arr = arr[np.linspace(0, arr.shape[0] - 1, BULK_FRAMES).round().astype(int)]
    n_frames = arr.shape[0]
    flat = arr.reshape(n_frames, -1)
    missing = np.isnan(flat)
    keep = ~missing.all(axis=0)
    flat, missing = flat[:, keep], missing[:, keep]
    m, n = min(n_frames - 1, flat.shape[1]), max(n_frames - 1, flat.shape[1])
    if n_frames < 4 or flat.shape[1] < 2:
        return None
    if missing.any() and fill_noise > 0.0:
        flat = _filled(flat, missing, fill_noise)[0]
    elif missing.any():
        flat = np.where(missing, np.nanmean(flat, axis=0), flat)
    _, sv, _ = thin_svd(flat - flat.mean(axis=0))
    ev = np.sort(sv**2)[::-1][:m]
    r, sigma2 = 0, 0.0
    for _ in range(m):
        rows, cols = m - r, n - r
        sigma2 = float(np.median(ev[r:])) / (cols * _mp_median(rows / cols))
        edge = sigma2 * cols * (1.0 + np.sqrt(rows / cols)) ** 2
        above = min(int(np.sum(ev > edge)), m // 2)
        if above == r:
            break
        r = above
    return float(np.sqrt(max(sigma2, 0.0)))


def denoise_take(frames: ArrayLike, marker_noise: float) -> DenoisedTake:
    """The take `frames` (F, B, 3; NaN: a missing marker) with its markers' white noise of
    `marker_noise` per coordinate (data units) removed as far as the take's own low-rank
    structure allows (module doc). `marker_noise` 0 returns the frames as they are. An
    InputError for a shape other than (F, B, 3), an infinite sample or a sigma that is not a
    finite number ≥ 0."""
    arr = np.asarray(frames, dtype=np.float64)
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.shape[0] < 1 or arr.shape[1] < 1:
        raise InputError(f"denoise: frames must have shape (F, B, 3), got {arr.shape}")
    if np.isinf(arr).any():
        f, b, _ = np.argwhere(np.isinf(arr))[0]
        raise InputError(f"denoise: frame {f}, marker {b} is infinite")
    sigma = float(marker_noise)
    if isinstance(marker_noise, bool) or not np.isfinite(sigma) or sigma < 0.0:
        raise InputError(
            f"denoise: marker_noise must be a finite number >= 0, got {marker_noise!r}"
        )
    n_frames, b, _ = arr.shape
    flat = arr.reshape(n_frames, 3 * b)
    missing = np.isnan(flat)
    directions = min(n_frames - 1, 3 * b)
    if sigma == 0.0 or missing.all():
        return DenoisedTake(arr.copy(), sigma, sigma, directions, directions)
    _, estimate, rank, error = _filled(flat, missing, sigma)
    # The asymptotic error can exceed sigma where nearly every direction is kept (a few
    # frames): no shrinker leaves more noise than it was given.
    left = min(float(np.sqrt(error + sigma**2 / n_frames)), sigma)
    out = np.where(missing, np.nan, estimate).reshape(arr.shape)
    return DenoisedTake(out, left, sigma, rank, directions)
