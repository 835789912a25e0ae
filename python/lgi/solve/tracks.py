"""A marker's track read against its nearest markers': skin carries a marker with its
neighbours, a fault (a spike, a swapped label, a marker off its track) moves it alone. The
neighbours are the nearest in the take's median pose; a marker's step between two frames less
its neighbours' median step between the same frames is what the fault finder
(`lgi.solve.diagnose`) reads as the marker leaving its track, and its neighbours' median
motion is how the skin around it moved."""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "NEIGHBOURS",
    "RELATIVE_STEP_NOISE",
    "nearest_markers",
    "relative_steps",
    "skin_track",
]

NEIGHBOURS = 4
"""Markers whose mean a marker's track is read against (its nearest in the take's median
pose): skin moves them together, a fault moves one alone."""

RELATIVE_STEP_NOISE = 1.61
"""The noise of a marker's step against its neighbours (`relative_steps`) per coordinate, in
units of the markers' sigma: its own step's (variance 2) and its `NEIGHBOURS` neighbours' median
step's (the median of 4 normals: 0.30 of their variance 2), sqrt(2 x 1.30)."""


def nearest_markers(x: NDArray[np.float64]) -> NDArray[np.int64]:
    """(B, B - 1) each marker's other markers, nearest first in the take's median pose; a
    marker never seen is nobody's near neighbour (it sorts last) and has no order of its own
    (all -1)."""
    b = x.shape[1]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a marker never seen: NaN, left out
        pose = np.nanmedian(x, axis=0) if x.shape[0] else np.full((b, 3), np.nan)
    d = np.linalg.norm(pose[:, None] - pose[None], axis=2)
    d[~np.isfinite(d)] = np.inf
    np.fill_diagonal(d, -1.0)  # itself first, then dropped
    order = np.argsort(d, axis=1, kind="stable")[:, 1:]
    order[~np.isfinite(pose).all(axis=1)] = -1
    return order


def _median_seen(values: NDArray[np.float64], seen: NDArray[np.bool_]) -> NDArray[np.float64]:
    """(S, 3) the median over axis 1 of `values` (S, N, 3) where `seen` (S, N), each row with
    at least one seen: the mean of the middle two of an even count, as `np.nanmedian` (the same
    values, without its per-call cost)."""
    ranked = np.sort(np.where(seen[..., None], values, np.inf), axis=1)
    count = seen.sum(axis=1)
    rows = np.arange(values.shape[0])
    low = ranked[rows, (count - 1) // 2]
    high = ranked[rows, count // 2]
    return np.asarray((low + high) / 2.0)


def relative_steps(
    x: NDArray[np.float64],
    nearest: NDArray[np.int64],
    *,
    per_frame: bool = True,
    only: NDArray[np.bool_] | None = None,
) -> NDArray[np.float64]:
    """(F, B) each marker's step between the frames it is seen in, less the median step of its
    `NEIGHBOURS` nearest markers (`nearest_markers`) seen in both, per frame elapsed (`per_frame`;
    else whole); NaN where none of them is. Skin carries a marker with its neighbours; a
    fault moves it alone. (A neighbour's dropout changes which neighbours are averaged, not
    the step: each neighbour's own step is taken between the same two frames.) `only` (F, B):
    the steps read, by the frame they end at (the rest NaN)."""
    f, b = x.shape[:2]
    steps = np.full((f, b), np.nan)
    idx = np.flatnonzero(nearest[:, 0] >= 0) if b > 1 else np.zeros(0, np.int64)
    if idx.size <= NEIGHBOURS:
        return steps
    near = nearest[idx, :NEIGHBOURS]
    present: NDArray[np.bool_] = np.asarray(np.isfinite(x).all(axis=2))
    for i, k in enumerate(idx):
        seen = np.flatnonzero(present[:, k])
        if seen.size < 2:
            continue
        p, q = seen[:-1], seen[1:]
        if only is not None:
            asked = only[q, k]
            if not asked.any():
                continue
            p, q = p[asked], q[asked]
        own = x[q, k] - x[p, k]  # (S, 3)
        nb = near[i][None, :]
        both = present[p[:, None], nb] & present[q[:, None], nb]  # (S, N)
        moved = x[q[:, None], nb] - x[p[:, None], nb]  # (S, N, 3), NaN where one is missing
        keep = both.any(axis=1)
        # The neighbours' median step: one faulty neighbour does not move the reference.
        skin = _median_seen(moved[keep], both[keep])
        apart = (q - p)[keep] if per_frame else 1
        steps[q[keep], k] = np.linalg.norm(own[keep] - skin, axis=1) / apart
    return steps


def skin_track(x: NDArray[np.float64], nearest: NDArray[np.int64], b: int) -> NDArray[np.float64]:
    """(F, 3) the median position of marker `b`'s `NEIGHBOURS` nearest markers, each less its
    own median over the take (NaN where none is seen): how the skin around `b` moved."""
    near = nearest[b, :NEIGHBOURS]
    if (near < 0).any():
        return np.full((x.shape[0], 3), np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a frame none of them is seen in
        moved = x[:, near] - np.nanmedian(x[:, near], axis=0)
        return np.asarray(np.nanmedian(moved, axis=1))
