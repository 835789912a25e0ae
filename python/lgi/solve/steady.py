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
"""Frames steadied at once (memory: two blocks of vertices beside the take's)."""


def _filtered(x: F64) -> F64:
    return np.asarray(
        gaussian_filter1d(x, SIGMA_FRAMES, axis=0, mode="nearest", truncate=_TRUNCATE)
    )


def steadied(
    model: Model,
    vertices: F64,
    *,
    before: F64 | None = None,
    after: F64 | None = None,
) -> F64:
    """`vertices` (F, V, 3), a take's solved frames in order, with their detail steadied in
    place (returned). `before` and `after`: up to `RADIUS` solved frames just before and after
    them (unsteadied; a chunk's neighbours), none at the take's ends."""
    f = vertices.shape[0]
    if f + (0 if before is None else len(before)) + (0 if after is None else len(after)) < 2:
        return vertices
    interp = np.asarray(surface_interpolator(model).matrix)  # (V, B)
    tail = np.zeros((0, *vertices.shape[1:])) if before is None else before[-RADIUS:].copy()
    ahead_all = np.zeros((0, *vertices.shape[1:])) if after is None else after[:RADIUS]
    for s in range(0, f, _BLOCK):
        e = min(f, s + _BLOCK)
        ahead = vertices[e : e + RADIUS]
        if ahead.shape[0] < RADIUS:
            ahead = np.concatenate([ahead, ahead_all[: RADIUS - ahead.shape[0]]])
        window = np.concatenate([tail, vertices[s:e], ahead])
        mid = slice(tail.shape[0], tail.shape[0] + (e - s))
        next_tail = np.concatenate([tail, vertices[s:e]])[-RADIUS:].copy()
        p = model.bundle_positions(window)
        rough = p[mid] - _filtered(p)[mid]  # (n, B, 3): what the filter takes off the markers
        vertices[s:e] = _filtered(window)[mid]
        for i in range(e - s):  # frame by frame: the same arithmetic whatever the blocks
            vertices[s + i] += interp @ rough[i]
        tail = next_tail
    return vertices
