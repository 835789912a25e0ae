"""A take's own motion as a Gaussian of low rank, and what it predicts of samples a frame lacks.

A face moves its markers together: a blink moves an eyelid's markers with the other eyelid's,
a jaw moves the chin's with the lips'. The take (F frames of B markers, a matrix of F rows and
3B columns) is read as probabilistic PCA: the mean pose, its `k` strongest directions (the
thin SVD of the centred take, missing samples at the mean), each with its variance less the
noise's, and white noise of the markers' sigma. A frame's hidden coordinates are predicted by
their conditional mean given its others: the directions' posterior weights

    a = (sigma² Λ⁻¹ + V_O V_Oᵀ)⁻¹ V_O (x_O - μ_O),   prediction μ + Vᵀ a,

with V (k, 3B) the directions (orthonormal rows), V_O their columns at the frame's present
coordinates and Λ the variances. At rank k the noise is at least what the directions beyond the
k-th carry per coordinate (probabilistic PCA's maximum-likelihood noise): motion a rank-k
reading does not hold is noise to it, and on a noise-free take a direction a frame barely sees
is then held to its share instead of read from a near-singular system. The directions of a
rank-k motion are the first k of a rank-K one, so one reading serves every rank up to K
(`TakeMotion.predictions`).

Read by `lgi.solve.gaps` (a dropout filled from what the take says about it)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lgi.solve.spectrum import thin_svd

__all__ = ["TakeMotion", "read_motion"]

F64 = NDArray[np.float64]

RIDGE = 1e-10
"""Smallest noise-to-variance ratio a direction is held with: a take whose every direction is
read (no noise left at any rank) still predicts from a well-posed system where a frame hides
most of a direction's coordinates."""


REFILLS = 1
"""Rounds in which `read_motion` reads the take again with its missing samples at what the
motion read so far predicts of them (the first reading has them at the mean, which pulls the
directions toward it)."""


@dataclass(frozen=True)
class TakeMotion:
    """The take's motion (module text): `mean` (3B,), `directions` (K, 3B) with orthonormal
    rows, strongest first, the centred take's `spectrum` (its variance along each of its
    directions, descending, K or more), the `coordinates` it has (3B less those never seen) and
    the markers' `noise` sigma. At rank r the noise is the larger of `noise` and what the
    directions beyond the r-th carry per coordinate (probabilistic PCA's maximum-likelihood
    noise, Tipping & Bishop 1999: motion a rank-r reading does not hold is noise to it), and
    each direction's variance is its spectrum less that noise."""

    mean: F64
    directions: F64
    spectrum: F64
    coordinates: int
    noise: float

    @property
    def rank(self) -> int:
        return int(self.directions.shape[0])

    def truncated(self, rank: int) -> TakeMotion:
        """The same motion with its `rank` strongest directions only."""
        return TakeMotion(
            self.mean, self.directions[:rank], self.spectrum, self.coordinates, self.noise
        )

    def noise_at(self, rank: int) -> float:
        """The noise sigma of a rank-`rank` reading (class text)."""
        beyond = float(np.sum(self.spectrum[rank:])) / max(self.coordinates - rank, 1)
        return float(np.sqrt(max(self.noise**2, beyond)))

    def predictions(self, flat: F64, hidden: NDArray[np.bool_], ranks: Sequence[int]) -> list[F64]:
        """Each row of `flat` (n, 3B) predicted from its coordinates that are not `hidden`
        (n, 3B; a NaN coordinate must be hidden), by the motion's first `r` directions for
        each r in `ranks` (each ≤ `rank`): one (n, 3B) array per rank, each coordinate the
        conditional mean of its motion (without the noise) given the row's coordinates not
        hidden: a hidden coordinate's conditional mean."""
        n = flat.shape[0]
        v = self.directions
        k = v.shape[0]
        z = np.where(hidden, 0.0, flat - self.mean)
        b = z @ v.T  # (n, K): V_O (x_O - μ_O)
        # V_O V_Oᵀ = I - V_H V_Hᵀ (V's rows orthonormal): the hidden coordinates' outer
        # products summed per row (few per row: a row's dropouts and what is asked of it).
        a = np.broadcast_to(np.eye(k), (n, k, k)).copy()
        rows, cols = np.nonzero(hidden)
        if rows.size:
            vh = v[:, cols].T  # (m, K)
            outer = vh[:, :, None] * vh[:, None, :]
            starts = np.flatnonzero(np.r_[True, rows[1:] != rows[:-1]])
            a[rows[starts]] -= np.add.reduceat(outer, starts, axis=0)
        out = []
        for r in ranks:
            sigma2 = self.noise_at(r) ** 2
            variances = self.spectrum[:r] - sigma2
            ridge = np.maximum(sigma2 / np.maximum(variances, 1e-300), RIDGE)
            system = a[:, :r, :r] + np.diag(ridge)
            w = np.linalg.solve(system, b[:, :r, None])[..., 0]
            out.append(self.mean + w @ v[:r])
        return out


def read_motion(frames: F64, noise: float, rank: int) -> TakeMotion | None:
    """The motion of `frames` (F, B, 3; NaN where missing) with its `rank` strongest directions
    at most (fewer where the take has fewer above its noise), markers of noise `noise` (sigma
    per coordinate, ≥ 0); None for a take of fewer than 2 frames or without a direction."""
    f = frames.shape[0]
    flat = frames.reshape(f, -1)
    missing = ~np.isfinite(flat)
    if f < 2 or rank < 1:
        return None
    # A coordinate never seen has mean 0 and no share in any direction (always hidden).
    seen_anywhere: NDArray[np.bool_] = np.asarray(~missing.all(axis=0))
    filled = np.where(missing, 0.0, flat)
    # The first reading has the missing samples at the mean of the frames that have them.
    mean = filled.sum(axis=0) / np.maximum((~missing).sum(axis=0), 1)
    centred = np.where(missing, 0.0, filled - mean)
    rows = np.flatnonzero(missing.any(axis=1))
    motion = _reading(centred, mean, seen_anywhere, noise, rank)
    for _ in range(REFILLS if rows.size else 0):
        if motion is None:
            break
        # Read again with the missing samples at what this reading predicts of them.
        guess = motion.predictions(flat[rows], missing[rows], [motion.rank])[0]
        filled[rows] = np.where(missing[rows], guess, flat[rows])
        filled[:, ~seen_anywhere] = 0.0
        mean = filled.sum(axis=0) / f
        motion = _reading(filled - mean, mean, seen_anywhere, noise, rank)
    return motion


def _reading(
    centred: F64, mean: F64, seen: NDArray[np.bool_], noise: float, rank: int
) -> TakeMotion | None:
    """One reading of the centred take `centred` (F, 3B) about `mean`: its `rank` strongest
    directions at most, those above the noise (None: none is); coordinates not `seen` have no
    share in any."""
    centred[:, ~seen] = 0.0
    mean[~seen] = 0.0
    _, sv, vt = thin_svd(centred, lambda s: min(rank, s.size))
    spectrum = sv**2 / (centred.shape[0] - 1)
    kept = int(np.count_nonzero(spectrum[: vt.shape[0]] > noise**2))
    if kept == 0:
        return None
    return TakeMotion(mean, vt[:kept], spectrum, int(seen.sum()), float(noise))
