"""Missing marker samples filled from the take before the per-frame solve.

A frame solved alone with one marker missing leans on local geometry that its neighbouring
frames, which have the marker, do not use: the surface moves off and back, a pop. Skin carries a
marker with its neighbours, so a missing sample is read from what the take says about it: the
marker's position relative to its `NEIGHBOURS` nearest markers (their median displacement from
rest) is interpolated linearly in time across the gap, from the frames on either side where it
was seen, and the neighbours' displacement at the missing frame is added back. A gap longer
than `MAX_GAP` frames, a frame where none of the neighbours is seen, a frame where fewer than
`MIN_SEEN` of the markers are seen (a frame lost, not a dropout: the solve says so) and a
marker never seen stay missing (the solve's own estimate). Filled samples stay missing in the result
(`SolveResult.missing`, residual 0): they are the take's estimate, not a measurement.

Everything a filled sample depends on lies within `MAX_GAP + 1` frames of it, so a take filled
in chunks with that many frames of context either side equals the take filled whole
(`Model.solve_iter`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["CONTEXT", "MAX_GAP", "MIN_SEEN", "NEIGHBOURS", "filled", "nearest"]

F64 = NDArray[np.float64]

NEIGHBOURS = 4
"""Markers a missing sample is read against: its nearest at rest (skin moves them together)."""

MAX_GAP = 30
"""Longest run of missing frames filled (half a second at 60 Hz); a longer gap is no longer
a dropout but a marker gone, and stays the solve's."""

MIN_SEEN = 0.5
"""The share of a frame's markers that must be seen for its dropouts to be filled."""

CONTEXT = MAX_GAP + 1
"""Frames either side of a chunk that its fill reads (see the module's note)."""


def nearest(rest: F64) -> NDArray[np.int64]:
    """(B, k) each marker's `NEIGHBOURS` nearest other markers at `rest` (B, 3), nearest
    first (k = min(NEIGHBOURS, B - 1))."""
    b = rest.shape[0]
    d = np.linalg.norm(rest[:, None] - rest[None], axis=2)
    np.fill_diagonal(d, np.inf)
    return np.argsort(d, axis=1, kind="stable")[:, : min(NEIGHBOURS, b - 1)]


def _runs(flags: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """The [start, stop) ranges where `flags` (F,) is True."""
    edges = np.diff(np.concatenate(([0], flags.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


def filled(frames: F64, rest: F64) -> tuple[F64, NDArray[np.bool_]]:
    """`frames` (F, B, 3; NaN rows missing) with the missing samples the take can fill filled
    (a new array; present samples as given), and the (F, B) mask of the samples filled.
    `rest`: the markers' rest positions (B, 3) the neighbours are found at."""
    x = np.array(frames, dtype=np.float64)
    f, b = x.shape[:2]
    done = np.zeros((f, b), dtype=bool)
    seen: NDArray[np.bool_] = np.asarray(np.isfinite(x).all(axis=2))
    if f < 2 or b < 2 or seen.all():
        return x, done
    near = nearest(np.asarray(rest, dtype=np.float64))
    frame_kept: NDArray[np.bool_] = np.asarray(
        seen.mean(axis=1) >= MIN_SEEN
    )  # frames that are there, a few markers lost
    moved = x - rest[None]  # each marker's displacement from rest; NaN where missing
    frames_at = np.arange(f)
    for k in np.flatnonzero(~seen.all(axis=0)):
        around = moved[:, near[k]]  # (F, k, 3)
        with_neighbour: NDArray[np.bool_] = np.asarray(seen[:, near[k]].any(axis=1))
        carried = np.zeros((f, 3))
        carried[with_neighbour] = np.nanmedian(around[with_neighbour], axis=1)
        usable = seen[:, k] & with_neighbour  # frames that say where the marker sits
        if not usable.any():
            continue
        offset = x[:, k] - carried  # the marker relative to its neighbours
        for a, z in _runs(~usable):
            if z - a > MAX_GAP:
                continue
            gone = np.flatnonzero(~seen[a:z, k] & with_neighbour[a:z] & frame_kept[a:z]) + a
            if gone.size == 0:
                continue
            # The run's bounds are usable frames (or the take's ends, held constant).
            lo, hi = max(a - 1, 0), min(z, f - 1)
            ends = [t for t in (lo, hi) if usable[t]]
            value = np.stack(
                [np.interp(frames_at[gone], ends, offset[ends, c]) for c in range(3)], axis=1
            )
            x[gone, k] = value + carried[gone]
            done[gone, k] = True
    return x, done
