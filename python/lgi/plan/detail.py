"""How much of the dataset's detail between the markers a solve keeps (`detail_weight`).

A solved surface is split in two: its smooth part, the biharmonic interpolation (phi(r) = r
with a linear polynomial, `lgi.baselines.DisplacementInterpolation`'s rule) of its own
present markers' displacements from rest, and the dataset's detail, what the solve adds between
the markers beyond that. Keeping a weight w of the detail gives
`w * solved + (1 - w) * smooth`: w = 1 is the solve as it is, w = 0 the smooth interpolation
through the same marker positions; every present marker stays where the solve put it.

When the dataset is the performer's own face, its detail is right and w is ~1. When it is not
(a real take retargeted onto a generic face), part of the detail is another face's, and
`estimate_detail_weight` reads how much from the take itself: on a few frames each present
marker is left out in turn and predicted twice, by the solve without it (the surface at its
rest point) and by the smooth part through the others' solved positions; w is the
least-squares weight of the two predictions against the marker (stacking, Breiman 1996),
clipped to [0, 1], kept only when the left-out error it saves is clear of its own noise (more
than two standard errors over the frames read; otherwise 1: no evidence against the
dataset). Nothing is tuned to a take: the weight is what the take's own left-out markers say.
docs/concepts.md explains it; docs/results.md measures it."""

from __future__ import annotations

import weakref
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

import lgi._lgi as _lgi
from lgi.errors import InputError
from lgi.leave_out import leave_markers_out, solved_in_chunks, take_frames

if TYPE_CHECKING:
    from lgi.model import Model

F64 = NDArray[np.float64]

__all__ = [
    "DETAIL_FRAMES",
    "SIGNIFICANCE",
    "blend_detail",
    "check_detail_weight",
    "estimate_detail_weight",
]

DETAIL_FRAMES = 8
"""Frames of a take (spread evenly over it) whose left-out markers the estimate reads."""

SIGNIFICANCE = 2.0
"""Standard errors the left-out error saved must exceed for a weight below 1 to be kept (the
usual ~95 % level)."""


def check_detail_weight(weight: Any) -> float:
    """A detail weight as a float in [0, 1], or InputError naming it."""
    try:
        w = float(weight)
    except (TypeError, ValueError):
        raise InputError(f"detail_weight: expected a number in [0, 1], got {weight!r}") from None
    if not 0.0 <= w <= 1.0:
        raise InputError(f"detail_weight: expected a number in [0, 1], got {w}")
    return w


# Per model (made on first use, dropped with the model): the two interpolators below.
_SURFACE: weakref.WeakKeyDictionary[Model, _lgi.RbfInterpolator] = weakref.WeakKeyDictionary()
_BUNDLES: weakref.WeakKeyDictionary[Model, _lgi.RbfInterpolator] = weakref.WeakKeyDictionary()


def _surface_interpolator(model: Model) -> _lgi.RbfInterpolator:
    """The biharmonic interpolation of values at the bundles over the mesh's vertices, each
    bundle's constraint sampled like the mesh samples it (so it passes through the bundles)."""
    made = _SURFACE.get(model)
    if made is None:
        sp = model.core.bundle_surface_points()
        tris = np.asarray(model.dataset.triangles, dtype=np.int64)[np.asarray(sp["triangles"])]
        made = _lgi.RbfInterpolator(model.dataset.neutral, tris, sp["barycentrics"])
        _SURFACE[model] = made
    return made


def _bundle_interpolator(model: Model) -> _lgi.RbfInterpolator:
    """The same interpolation evaluated at the bundles' rest points only (the estimate's)."""
    made = _BUNDLES.get(model)
    if made is None:
        b = model.num_bundles
        at = np.repeat(np.arange(b, dtype=np.int64)[:, None], 3, axis=1)
        one = np.zeros((b, 3))
        one[:, 0] = 1.0
        made = _lgi.RbfInterpolator(_rest(model), at, one)
        _BUNDLES[model] = made
    return made


def _rest(model: Model) -> F64:
    """The bundles' rest positions (B, 3): their surface points on the neutral."""
    return model.bundle_positions(np.asarray(model.dataset.neutral, dtype=np.float64))


def blend_detail(
    model: Model, vertices: F64, positions: F64, missing: NDArray[np.bool_], weight: float
) -> F64:
    """`weight * vertices + (1 - weight) * smooth` in place in `vertices` (F, V, 3), the smooth
    part interpolating the present markers' solved `positions` (F, B, 3; `missing` (F, B)
    left out) from rest; returns `vertices`."""
    if weight == 1.0:
        return vertices
    rest = _rest(model)
    values = np.where(missing[..., None], np.nan, positions - rest[None])
    smooth = _surface_interpolator(model).interpolate(values)
    smooth += np.asarray(model.dataset.neutral, dtype=np.float64)[None]
    vertices *= weight
    vertices += (1.0 - weight) * smooth
    return vertices


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
    rest = _rest(model)
    gone = np.asarray(~np.isfinite(batch).all(axis=2))
    values = np.where(gone[..., None], np.nan, pos - rest[None])
    smooth = _bundle_interpolator(model).interpolate(values)
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
