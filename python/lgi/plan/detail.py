"""How much of the dataset's detail a take keeps (`detail_weight`, applied by
`lgi.solve.detail.blend_detail`), read from the take's own markers left out: each present
marker predicted by the solve without it and by the smooth interpolation through the others;
the least-squares weight of the two (stacking, Breiman 1996), kept only where it clearly saves
left-out error. docs/concepts.md explains it."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi.plan.leave_out import leave_markers_out, solved_in_chunks, take_frames
from lgi.solve.detail import bundle_interpolator, rest_positions

if TYPE_CHECKING:
    from lgi.solve.model import Model

F64 = NDArray[np.float64]

__all__ = ["DETAIL_FRAMES", "SIGNIFICANCE", "estimate_detail_weight"]

DETAIL_FRAMES = 8
"""Frames of a take (spread evenly over it) whose left-out markers the estimate reads."""

SIGNIFICANCE = 2.0
"""Standard errors the left-out error saved must exceed for a weight below 1 to be kept (the
usual ~95 % level)."""


def estimate_detail_weight(
    frames: ArrayLike,
    model: Model,
    *,
    marker_noise: float | None = None,
    jaw: str | None = "auto",
    frames_used: int = DETAIL_FRAMES,
    fit: bool | str | None = None,
) -> float:
    """The detail weight of a take (F, B, 3; NaN rows missing) for `model` solved with
    `marker_noise`, `jaw` and `fit` (as the take will be solved): on up to `frames_used` frames
    spread over the take, every present marker left out in turn (frames with at least one
    more marker than the solve needs), predicted by the solve without it and by the smooth
    part through the others; the least-squares weight of the two, clipped to [0, 1]. It is
    kept when the squared left-out error it saves, summed per frame, averages more than
    `SIGNIFICANCE` standard errors of that mean over the frames; otherwise (and with fewer
    than 2 frames, or predictions that agree everywhere) 1. One solve of about
    `frames_used` x B frames."""
    arr = take_frames(frames, model)
    out = leave_markers_out(arr, frames_used, what="detail weight")
    pick, batch, left = out.picked, out.frames, out.marker
    pos = np.empty(batch.shape)
    for rows, solved in solved_in_chunks(model, out, jaw=jaw, marker_noise=marker_noise, fit=fit):
        pos[rows] = np.asarray(solved.bundle_positions)
    rest = rest_positions(model)
    gone = np.asarray(~np.isfinite(batch).all(axis=2))
    values = np.where(gone[..., None], np.nan, pos - rest[None])
    smooth = bundle_interpolator(model).interpolate(values)
    k = np.arange(len(left))
    by_solve = pos[k, left]
    by_smooth = rest[left] + smooth[k, left]
    of, truth = out.frame, out.given
    d = by_solve - by_smooth
    dd = float((d * d).sum())
    if dd == 0.0 or pick.size < 2:
        return 1.0
    w = float(np.clip(((truth - by_smooth) * d).sum() / dd, 0.0, 1.0))
    blended = w * by_solve + (1.0 - w) * by_smooth
    saved = ((truth - by_solve) ** 2).sum(axis=1) - ((truth - blended) ** 2).sum(axis=1)
    per_frame = np.array([saved[of == f].sum() for f in pick])
    error = per_frame.std(ddof=1) / np.sqrt(per_frame.size)
    return w if per_frame.mean() > SIGNIFICANCE * error else 1.0
