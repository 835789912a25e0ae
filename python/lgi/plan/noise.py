"""The markers' noise sigma, estimated from a take (`estimate_marker_noise`, what
`--marker-noise auto` and `lgi batch` use).

Four readings. The tracks': a sample's second difference holds 6 sigma^2 of independent noise
and almost none of a face's motion at capture rates. The fit's bound: what the dataset's
global fit leaves at the markers holds the noise, so it bounds sigma from above at any frame
spacing. The take's spectrum (`lgi.plan.denoise.bulk_noise`): what the take's own few directions of
motion leave, which frame spacing does not enter; where it is the smallest it is the estimate.
Otherwise, when the tracks read motion (frames far apart; independent noise moves one marker,
motion moves its neighbours with it, so their second differences are correlated), the markers
left out: the sigma with which the noise-aware solve best predicts markers left out of it, no
larger than the other two (what the dataset cannot explain, which both of them count as
noise, is not noise to the solve). docs/concepts.md explains it; docs/results.md measures it."""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

import lgi._lgi as _lgi
from lgi.errors import InputError, LgiWarning
from lgi.plan.denoise import bulk_noise
from lgi.plan.leave_out import LOOKS, Looks, leave_markers_out, solved_in_chunks, take_frames

if TYPE_CHECKING:
    from lgi.solve.model import Model

__all__ = [
    "MOTION_CORRELATION",
    "NOISE_BOUND_FRAMES",
    "NOISE_FLOOR",
    "NOISE_LEFT_OUT_FRAMES",
    "NOISE_LEFT_OUT_PER_FRAME",
    "NOISE_STEP_SIGNIFICANCE",
    "estimate_marker_noise",
    "fit_noise_bound",
    "tracks_correlation",
]

NOISE_BOUND_FRAMES = 100
"""Frames of a take the fit's noise bound reads at most (spread evenly over the take)."""

MOTION_CORRELATION = 0.3
"""Correlation of neighbouring markers' second differences above which the tracks read motion:
independent noise gives about 0 (0.00-0.18 measured on takes at capture rate with 0.2-0.5 mm
noise), motion between frames far apart 0.45-0.91 (docs/results.md)."""

NOISE_LEFT_OUT_FRAMES = 12
"""Frames the left-out reading solves (spread over the take)."""

NOISE_LEFT_OUT_PER_FRAME = 20
"""Markers left out one at a time on each of them."""

NOISE_STEP_SIGNIFICANCE = 2.0
"""Standard errors of the mean per-frame saving that a halved sigma must clear."""

NOISE_FLOOR = 1e-5
"""Noise below this share of the face's size (its bounding-box diagonal; 5 um on ICT's 47.5
cm head) is not worth a left-out reading: the left-out reading neither starts under it nor
halves below it."""

_HALVINGS = 8
"""The left-out reading's smallest sigma: its start over 2^this."""


def estimate_marker_noise(frames: ArrayLike, model: Model | None = None) -> float:
    """Estimates the markers' noise sigma (data units, per coordinate) from a take (F, B, 3), NaN
    rows missing.

    From the take's tracks: the second difference of a sample, x[f+1] - 2 x[f] + x[f-1],
    holds 6 sigma^2 of independent noise and almost none of a face's motion at capture frame
    rates; its median absolute value (robust to the odd jump) gives sigma. When frames are far
    apart (a take sampled sparsely, every n-th frame), motion changes within three frames and
    this reads motion as noise.

    With `model`, also from what the dataset's global fit leaves at the markers (each frame's
    jaw pose from the fit, as `solve` finds it; up to 100 frames spread over the take): noise
    is part of that residual, so its scale (the residual's root mean square per coordinate,
    over the rows less the fit's rank) bounds sigma from above whatever the frame spacing.
    The smaller of the two is the estimate, unless what the take's own directions of motion
    leave (`lgi.plan.denoise.bulk_noise`, its dropouts filled at that estimate) is smaller still:
    then that is the estimate. Otherwise, where the tracks read motion (their second
    differences correlated between neighbouring markers above `MOTION_CORRELATION`) and it is
    above `NOISE_FLOOR` of the face: then markers are left out of `NOISE_LEFT_OUT_FRAMES`
    frames and that sigma is halved while the noise-aware solve, given the halved sigma,
    predicts them significantly better (`NOISE_STEP_SIGNIFICANCE`). A warning says so when
    the estimate is under 1/1.5 of the tracks' reading (frames too far apart to tell noise
    from motion). With a model, one frame is enough; without, at least 3
    are needed."""
    arr = np.asarray(frames, dtype=np.float64)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise InputError(f"frames: expected shape (F, B, 3), got {arr.shape}")
    if np.isinf(arr).any():
        raise InputError("frames: infinite coordinate")
    if model is None and arr.shape[0] < 3:
        raise InputError(f"frames: need at least 3 frames to estimate noise, got {arr.shape[0]}")
    tracks = _track_noise(arr) if arr.shape[0] >= 3 else None
    if model is None:
        if tracks is None:
            raise InputError("frames: no marker is present in 3 consecutive frames")
        return tracks
    bound = fit_noise_bound(model, arr)
    if tracks is None:
        if bound is None:
            raise InputError("frames: too few markers to estimate noise from the take or the fit")
        return bound
    if bound is None:
        return tracks
    sigma = min(tracks, bound)
    how = "more than the dataset's fit leaves at the markers"
    floor = NOISE_FLOOR * model.diagonal
    bulk = bulk_noise(arr, sigma)
    if bulk is not None and bulk < sigma:
        # What the take's own directions of motion leave: frame spacing does not enter it, so
        # no left-out reading follows.
        sigma, how = bulk, "but what the take's own directions of motion leave is"
    elif sigma > floor and tracks_correlation(arr, model.markers_rest) > MOTION_CORRELATION:
        try:
            sigma = _left_out_noise(model, arr, sigma, floor)
            how = "but markers left out of the solve are predicted best with"
        except InputError:
            pass  # no frame can spare a marker: the two readings stand
    if tracks > 1.5 * sigma:
        unit = f" {model.units}" if model.units else " data units"
        warnings.warn(
            f"marker noise: the take's tracks give {tracks:.4g}{unit}, {how} "
            f"{sigma:.4g}{unit}: frames too far apart to tell noise from motion; using "
            f"{sigma:.4g}{unit}",
            LgiWarning,
            stacklevel=2,
        )
    return float(sigma)


def _track_noise(arr: NDArray[np.float64]) -> float | None:
    """Sigma from the second differences of the tracks (F >= 3); None when no marker is
    present in 3 consecutive frames."""
    d2 = (arr[2:] - 2.0 * arr[1:-1] + arr[:-2]).ravel()
    d2 = d2[np.isfinite(d2)]
    if d2.size == 0:
        return None
    # 1.4826 MAD is the standard deviation of a normal variable; the median of |d2| is its MAD.
    return float(1.4826 * np.median(np.abs(d2)) / np.sqrt(6.0))


def tracks_correlation(frames: ArrayLike, rest: ArrayLike, neighbours: int = 3) -> float:
    """The correlation of each marker's second differences (frames (F, B, 3), NaN missing) with
    those of its `neighbours` nearest markers at `rest` (B, 3), over every coordinate and frame
    present: about 0 where the second differences are independent noise, near 1 where they are
    the face's motion (0 when there is nothing to correlate)."""
    arr = np.asarray(frames, dtype=np.float64)
    at = np.asarray(rest, dtype=np.float64)
    if arr.shape[0] < 3 or at.shape[0] < 2:
        return 0.0
    apart = np.linalg.norm(at[:, None] - at[None], axis=2)
    np.fill_diagonal(apart, np.inf)
    near = np.argsort(apart, axis=1)[:, : min(neighbours, at.shape[0] - 1)]
    d2 = arr[2:] - 2.0 * arr[1:-1] + arr[:-2]
    # One neighbour rank at a time: a take's (F, B, 3) at most, not (F, B, neighbours, 3).
    cross = own_sq = other_sq = 0.0
    for rank in range(near.shape[1]):
        other = d2[:, near[:, rank]]
        both = np.isfinite(d2) & np.isfinite(other)
        a, b = d2[both], other[both]
        cross += float((a * b).sum())
        own_sq += float((a * a).sum())
        other_sq += float((b * b).sum())
    scale = float(np.sqrt(own_sq * other_sq))
    return cross / scale if scale > 0 else 0.0


def _left_out_noise(model: Model, arr: NDArray[np.float64], start: float, floor: float) -> float:
    """Halving sigma from `start` while the noise-aware solve's surface passes nearer the
    markers left out of it: the mean per-frame saving in distance (over the same rows for
    every sigma) must exceed `NOISE_STEP_SIGNIFICANCE` standard errors, so a flat stretch
    keeps the larger sigma (too small a sigma costs more than too large: the solve then
    follows the noise)."""
    rows = leave_markers_out(arr, NOISE_LEFT_OUT_FRAMES, NOISE_LEFT_OUT_PER_FRAME, "marker noise")
    jaw = _fit_jaw(model)
    looks = Looks(rows)
    every = np.arange(rows.marker.size)

    def distances(sigma: float) -> NDArray[np.float64]:
        out = np.empty(rows.marker.size)
        for part, res in solved_in_chunks(model, rows, jaw=jaw, marker_noise=sigma):
            out[part] = looks.distances(every[part], res.bundle_positions)
        return out

    best, at_best = start, distances(start)
    for _ in range(_HALVINGS):
        if best / 2.0 < floor:
            break
        half = distances(best / 2.0)
        # Every look at once: the per-frame mean saving over all the rows' frames.
        saved, spread, seen = looks.saving(at_best, half, LOOKS - 1)
        if seen < 2 or saved <= NOISE_STEP_SIGNIFICANCE * spread:
            break
        best, at_best = best / 2.0, half
    return best


def _fit_jaw(model: Model) -> str | None:
    """The jaw the noise readings solve with: each frame's pose from the fit, as `solve`
    finds it (none without a jaw rig)."""
    return "fit" if model.jaw_rig is not None else None


def fit_noise_bound(model: Model, frames: ArrayLike) -> float | None:
    """The scale of what the dataset's global fit leaves at the markers of `frames` (F, B, 3),
    per coordinate: sqrt(sum of squared residuals / (rows - the fit's rank)), over up to
    `NOISE_BOUND_FRAMES` frames spread over the take, each with its jaw pose from the fit (as
    `solve` finds it). Independent marker noise is part of the residual, so this bounds the
    noise sigma from above; what the dataset cannot explain adds to it. None when no frame
    has more present rows than the fit's rank, or none has the solve's minimum of present
    markers."""
    arr = take_frames(frames, model)
    # Frames the fit can read (the solve's minimum of present markers), spread over the take.
    usable = np.flatnonzero(np.isfinite(arr).all(axis=2).sum(axis=1) >= _lgi.MIN_PRESENT_MARKERS)
    if usable.size == 0:
        return None
    at = np.unique(np.linspace(0, usable.size - 1, NOISE_BOUND_FRAMES).round().astype(int))
    pick = usable[at]
    residuals, ranks = model.core.fit_residuals(arr[pick], jaw=_fit_jaw(model))
    present = np.isfinite(residuals[..., 0])
    rows = 3 * present.sum(axis=1)
    dof = np.maximum(rows - np.minimum(ranks, rows), 0)
    if dof.sum() == 0:
        return None
    return float(np.sqrt(np.nansum(residuals**2) / dof.sum()))
