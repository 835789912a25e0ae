"""How much of the dataset's detail between the markers a solve keeps (`detail_weight`).

A solved surface is split in two: its smooth part, the biharmonic interpolation (phi(r) = r
with a linear polynomial, `lgi.lab.baselines.DisplacementInterpolation`'s rule) of its own
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
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

import lgi._lgi as _lgi

if TYPE_CHECKING:
    from lgi.solve.model import Model

F64 = NDArray[np.float64]

__all__ = ["blend_detail", "bundle_interpolator", "rest_positions", "surface_interpolator"]


# Per model (made on first use, dropped with the model): the two interpolators below.
_SURFACE: weakref.WeakKeyDictionary[Model, _lgi.RbfInterpolator] = weakref.WeakKeyDictionary()
_BUNDLES: weakref.WeakKeyDictionary[Model, _lgi.RbfInterpolator] = weakref.WeakKeyDictionary()


def surface_interpolator(model: Model) -> _lgi.RbfInterpolator:
    """The biharmonic interpolation of values at the bundles over the mesh's vertices, each
    bundle's constraint sampled like the mesh samples it (so it passes through the bundles)."""
    made = _SURFACE.get(model)
    if made is None:
        sp = model.core.bundle_surface_points()
        tris = np.asarray(model.dataset.triangles, dtype=np.int64)[np.asarray(sp["triangles"])]
        made = _lgi.RbfInterpolator(model.dataset.neutral, tris, sp["barycentrics"])
        _SURFACE[model] = made
    return made


def bundle_interpolator(model: Model) -> _lgi.RbfInterpolator:
    """The same interpolation evaluated at the bundles' rest points only (the estimate's)."""
    made = _BUNDLES.get(model)
    if made is None:
        b = model.num_bundles
        at = np.repeat(np.arange(b, dtype=np.int64)[:, None], 3, axis=1)
        one = np.zeros((b, 3))
        one[:, 0] = 1.0
        made = _lgi.RbfInterpolator(rest_positions(model), at, one)
        _BUNDLES[model] = made
    return made


def rest_positions(model: Model) -> F64:
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
    rest = rest_positions(model)
    values = np.where(missing[..., None], np.nan, positions - rest[None])
    smooth = surface_interpolator(model).interpolate(values)
    smooth += np.asarray(model.dataset.neutral, dtype=np.float64)[None]
    vertices *= weight
    vertices += (1.0 - weight) * smooth
    return vertices
