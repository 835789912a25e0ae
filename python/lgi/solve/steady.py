"""The dataset's detail kept steady across the frames of a take.

Each frame picks its pieces of local geometry alone. Where the dataset does not reach the
motion, two pieces can explain a frame about equally well and the pick flips from one frame to
the next: the surface between the markers jumps while the markers barely move (a pop). A
solved surface is its smooth part, the biharmonic interpolation of its own markers'
positions (`lgi.solve.detail`), plus the dataset's detail; the detail is averaged over
neighbouring frames with a Gaussian of `SIGMA_FRAMES` frames, the smooth part is not. Since the
interpolation is linear, `steady = G*v + S (p - G*p)` for vertices `v`, marker positions `p`
and the interpolation `S`: every marker stays exactly where the solve put it, and the time
filter `G` reaches `RADIUS` frames either side, so a take steadied in blocks (or chunk by
chunk, given its neighbours' frames) equals the take steadied whole."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter1d

from lgi.solve.detail import surface_interpolator

if TYPE_CHECKING:
    from lgi.solve.model import Model

__all__ = ["RADIUS", "SIGMA_FRAMES", "steadied"]

F64 = NDArray[np.float64]

SIGMA_FRAMES = 1.0
"""The time filter's width: the least that spreads a one-frame flip over its neighbours
(0.7 to 2 frames measured alike on the capture protocol's takes: docs/reliability.md)."""

_TRUNCATE = 4.0
RADIUS = int(_TRUNCATE * SIGMA_FRAMES + 0.5)
"""Frames either side that a frame's steady detail reads."""

_BLOCK = 64
"""Frames steadied at once, in blocks aligned to the take's frame numbers: the markers' share is
one (V, B) x (B, 3 x 64) product per block, the same arithmetic for a frame whichever chunk it
came in (memory: a block of vertices beside the take's)."""

Frames = tuple[F64, F64]
"""Solved frames and their markers' positions on them: (n, V, 3), (n, B, 3)."""


def _filtered(x: F64) -> F64:
    return np.asarray(
        gaussian_filter1d(x, SIGMA_FRAMES, axis=0, mode="nearest", truncate=_TRUNCATE)
    )


def _spread(interp: F64, values: F64) -> F64:
    """Values at the markers (n, B, 3) interpolated over the mesh by `interp` (V, B): (n, V, 3),
    one (V, B) x (B, 3n) product."""
    n, nb = values.shape[:2]
    out = interp @ values.transpose(1, 0, 2).reshape(nb, -1)
    return out.reshape(-1, n, 3).transpose(1, 0, 2)


def steadied(
    model: Model,
    vertices: F64,
    positions: F64,
    *,
    first: int = 0,
    before: Frames | None = None,
    after: Frames | None = None,
    misses: F64 | None = None,
) -> F64:
    """`vertices` (F, V, 3), a take's solved frames in order from its frame `first`, with their
    detail steadied in place (returned); `positions` (F, B, 3): the markers' positions on them
    (`SolveResult.bundle_positions`). `before` and `after`: up to `RADIUS` solved frames just
    before and after them with their positions (unsteadied; a chunk's neighbours), none at the
    take's ends.

    `misses` (F, B, 3; a whole take, no `before` or `after`): `vertices` are the solve less
    the interpolation `S m` of these values at the markers (the local fits' corrective,
    `lgi.solve.local.LocalPieces.posed_and_misses`), and `positions` the whole solve's. Then
    `steady = G*u + S (G*m + p - G*p)` for those vertices `u`: the same surface (to
    round-off) with one pass of `S` over the mesh instead of two."""
    f = vertices.shape[0]
    if misses is not None and (before is not None or after is not None):
        raise ValueError("steadied: misses are read over a whole take, without neighbours")
    if f + (0 if before is None else len(before[0])) + (0 if after is None else len(after[0])) < 2:
        if misses is not None and f:
            vertices += _spread(np.asarray(surface_interpolator(model).matrix), misses)
        return vertices
    interp = np.asarray(surface_interpolator(model).matrix)  # (V, B)
    nb = positions.shape[1]

    def ends(got: Frames | None, head: bool) -> Frames:
        if got is None:
            return np.zeros((0, *vertices.shape[1:])), np.zeros((0, nb, 3))
        pick = slice(-RADIUS, None) if head else slice(0, RADIUS)
        return got[0][pick].copy(), got[1][pick].copy()

    tail_v, tail_p = ends(before, True)
    more_v, more_p = ends(after, False)
    s = 0
    while s < f:
        e = min(f, s + _BLOCK - (first + s) % _BLOCK)
        ahead_v, ahead_p = vertices[e : e + RADIUS], positions[e : e + RADIUS]
        short = RADIUS - ahead_v.shape[0]
        if short > 0:
            ahead_v = np.concatenate([ahead_v, more_v[:short]])
            ahead_p = np.concatenate([ahead_p, more_p[:short]])
        window_v = np.concatenate([tail_v, vertices[s:e], ahead_v])
        window_p = np.concatenate([tail_p, positions[s:e], ahead_p])
        mid = slice(tail_v.shape[0], tail_v.shape[0] + (e - s))
        next_v = np.concatenate([tail_v, vertices[s:e]])[-RADIUS:].copy()
        next_p = np.concatenate([tail_p, positions[s:e]])[-RADIUS:].copy()
        rough = np.zeros((_BLOCK, nb, 3))  # what the filter takes off the markers
        at = (first + s) % _BLOCK + np.arange(e - s)
        rough[at] = window_p[mid] - _filtered(window_p)[mid]
        if misses is not None:
            # The same frames' misses (no neighbours outside the take: `tail_v`'s frames).
            lo = s - tail_v.shape[0]
            window_m = misses[lo : lo + window_v.shape[0]]
            rough[at] += _filtered(window_m)[mid]
        vertices[s:e] = _filtered(window_v)[mid] + _spread(interp, rough)[at]
        tail_v, tail_p = next_v, next_p
        s = e
    return vertices
