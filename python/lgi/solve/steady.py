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
chunk, given its neighbours' frames) equals the take steadied whole. The filter is narrower
(`LOCAL_SIGMA_FRAMES`) where the detail is the local fits' (`lgi.solve.local`): a blend fitted
to each window's markers, continuous in them, flips far less than a pick of pieces, and a
wider filter then only takes away a blink's real one-frame change.

Where a noise-aware solve put a marker more than `PULL_SIGMAS` sigma from where the take has it,
the marker's miss is more than its noise explains: motion the dataset does not reach (a blink
the dataset lacks; a fault is repaired before, `lgi.solve.repair`). The surface then follows
the marker to within `PULL_SIGMAS` sigma of it (`marker_pulls`: the excess, added at the
markers with their share, unfiltered), so the face moves as its markers do where the dataset
cannot, and eases back as the marker comes back within its noise."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter1d

from lgi.solve.detail import surface_interpolator
from lgi.solve.diagnose import NOISE_SIGMAS
from lgi.solve.options import SolveOptions, local_bounds

if TYPE_CHECKING:
    from lgi.solve.model import Model

__all__ = [
    "LOCAL_SIGMA_FRAMES",
    "PULL_SIGMAS",
    "RADIUS",
    "SIGMA_FRAMES",
    "marker_pulls",
    "steadied",
    "width_for",
]

F64 = NDArray[np.float64]

SIGMA_FRAMES = 1.0
"""The time filter's width for the core's pieces: the least that spreads a one-frame flip over
its neighbours (0.7 to 2 frames measured alike on the capture protocol's takes'
mean errors, docs/reliability.md; 0.7 and 0.5 frames popped more on three of the four pop takes,
docs/journal/2026-12-07-local-fits-steadied.md)."""

LOCAL_SIGMA_FRAMES = 0.7
"""The width for the local fits' detail: 0.7 frames popped less than 1 frame on all four pop
takes (ICT and scans, two seeds) with an equal or lower mean error, and on the takes held out
of that choice; 0.5 frames popped more on one of the four
(docs/journal/2026-12-07-local-fits-steadied.md)."""

_TRUNCATE = 4.0
RADIUS = int(_TRUNCATE * SIGMA_FRAMES + 0.5)
"""Frames either side that a frame's steady detail reads."""

_BLOCK = 64
"""Frames steadied at once, in blocks aligned to the take's frame numbers: the markers' share is
one (V, B) x (B, 3 x 64) product per block, the same arithmetic for a frame whichever chunk it
came in (memory: a block of vertices beside the take's)."""

PULL_SIGMAS = NOISE_SIGMAS
"""How far (in the solve's marker noise sigma) a steady surface may stay from a marker: the 5
sigma a residual must exceed to be a finding (`lgi.solve.diagnose`), beyond which a Gaussian
marker lies once in 65,000 samples."""

Frames = tuple[F64, F64]
"""Solved frames and their markers' positions on them: (n, V, 3), (n, B, 3)."""


def width_for(opts: SolveOptions) -> float:
    """The time filter's width for a solve with options `opts`: `LOCAL_SIGMA_FRAMES` where its
    detail is the local fits', else the core's pieces' `SIGMA_FRAMES`."""
    return LOCAL_SIGMA_FRAMES if local_bounds(opts.local_fits) is not None else SIGMA_FRAMES


def _filtered(x: F64, width: float) -> F64:
    return np.asarray(gaussian_filter1d(x, width, axis=0, mode="nearest", truncate=_TRUNCATE))


def _spread(interp: F64, values: F64) -> F64:
    """Values at the markers (n, B, 3) interpolated over the mesh by `interp` (V, B): (n, V, 3),
    one (V, B) x (B, 3n) product."""
    n, nb = values.shape[:2]
    out = interp @ values.transpose(1, 0, 2).reshape(nb, -1)
    return out.reshape(-1, n, 3).transpose(1, 0, 2)


def marker_pulls(frames: F64, positions: F64, sigma: float | None) -> F64 | None:
    """(F, B, 3): how far the surface moves at each marker to come within `PULL_SIGMAS` sigma
    of it, where the take's sample (`frames`; NaN: missing, no pull) is further than that
    from where the solve put it (`positions`); 0 elsewhere. None without a noise (an exact
    solve interpolates its markers)."""
    if not sigma:
        return None
    seen = np.asarray(~np.isnan(frames).any(axis=2))
    miss = np.where(seen[..., None], frames - positions, 0.0)
    far = np.linalg.norm(miss, axis=2)
    reach = PULL_SIGMAS * float(sigma)
    beyond = far > reach
    share = np.where(beyond, 1.0 - reach / np.where(beyond, far, 1.0), 0.0)
    return np.asarray(miss * share[..., None])


def steadied(
    model: Model,
    vertices: F64,
    positions: F64,
    *,
    first: int = 0,
    before: Frames | None = None,
    after: Frames | None = None,
    misses: F64 | None = None,
    pulls: F64 | None = None,
    width: float = SIGMA_FRAMES,
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
    round-off) with one pass of `S` over the mesh instead of two.

    `pulls` (F, B, 3; `marker_pulls`): each marker of `vertices`' frames is moved by its pull,
    with the markers' share (`S`, unfiltered in time: a frame's pull is its own).

    `width`: the time filter's sigma in frames, at most `SIGMA_FRAMES` (`LOCAL_SIGMA_FRAMES` for
    the local fits' detail)."""
    if not 0.0 < width <= SIGMA_FRAMES:
        raise ValueError(f"steadied: width must be in (0, {SIGMA_FRAMES}] frames, got {width}")
    f = vertices.shape[0]
    if misses is not None and (before is not None or after is not None):
        raise ValueError("steadied: misses are read over a whole take, without neighbours")
    if f + (0 if before is None else len(before[0])) + (0 if after is None else len(after[0])) < 2:
        moved = [m for m in (misses, pulls) if m is not None]
        if moved and f:
            interp = np.asarray(surface_interpolator(model).matrix)
            vertices += _spread(interp, np.sum(moved, axis=0))
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
        rough[at] = window_p[mid] - _filtered(window_p, width)[mid]
        if misses is not None:
            # The same frames' misses (no neighbours outside the take: `tail_v`'s frames).
            lo = s - tail_v.shape[0]
            window_m = misses[lo : lo + window_v.shape[0]]
            rough[at] += _filtered(window_m, width)[mid]
        if pulls is not None:
            rough[at] += pulls[s:e]
        vertices[s:e] = _filtered(window_v, width)[mid] + _spread(interp, rough)[at]
        tail_v, tail_p = next_v, next_p
        s = e
    return vertices
