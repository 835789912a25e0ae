"""Markers seen by one camera only: a ray, not a point, kept as a post-process constraint (the
paper's §7.4). The frame is solved without the marker, the marker's reconstructed surface point
is moved to the closest point of its ray, and the frame is solved again with that point as the
marker: the surface then passes through the ray there, and the correction spreads over the
face with the same natural-neighbour interpolation as the solve's residual pass.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi._lgi import SolveResult
from lgi.capture.camera import Rays
from lgi.capture.stabilize import Alignment
from lgi.errors import InputError
from lgi.solve.model import Model

F64 = NDArray[np.float64]

__all__ = ["RaySolve", "solve_with_rays", "to_rest_space"]


def to_rest_space(rays: Rays, alignment: Alignment) -> Rays:
    """Rays (F, B, 3) in capture (camera-rig) space taken into the rest layout's space by the
    head transforms a stabilisation removed: origin `R^T (o - t)`, direction `R^T d`."""
    rot, t = alignment.rotations, alignment.translations
    o = np.asarray(rays.origins, dtype=np.float64)
    d = np.asarray(rays.directions, dtype=np.float64)
    if o.ndim != 3 or o.shape != d.shape or o.shape[0] != rot.shape[0] or o.shape[2] != 3:
        raise InputError(
            f"rays: expected origins and directions (F={rot.shape[0]}, B, 3), got "
            f"{o.shape} and {d.shape}"
        )
    return Rays(
        origins=np.einsum("fbi,fij->fbj", o - t[:, None], rot),
        directions=np.einsum("fbi,fij->fbj", d, rot),
    )


@dataclass(frozen=True)
class RaySolve:
    """The solve with ray constraints, and where the ray markers were put."""

    result: SolveResult
    """The final solve."""
    frames: F64
    """(F, B, 3) the frames solved last: the input with each ray marker at its ray point."""
    on_ray: NDArray[np.bool_]
    """(F, B) markers that were missing and constrained to their ray."""
    ray_distance: F64
    """(F, B) distance of each ray marker's final surface point to its ray; NaN elsewhere."""


def _closest_on_ray(p: F64, o: F64, d: F64) -> F64:
    s = np.maximum(np.einsum("nd,nd->n", p - o, d), 0.0)
    return o + s[:, None] * d


def solve_with_rays(
    model: Model, frames: ArrayLike, rays: Rays, *, rounds: int = 2, **solve: Any
) -> RaySolve:
    """Solves frames (F, B, 3) (NaN = missing) so that each missing marker with a ray (`rays`
    in the frames' space, e.g. `to_rest_space(triangulation.rays, alignment)`; NaN rows for
    no ray) lies on its ray: `rounds` times, the missing marker takes the point of its ray
    closest to its current surface point and the frame is solved again. Keyword arguments go
    to `Model.solve` (e.g. `marker_noise`)."""
    x = np.array(frames, dtype=np.float64)  # a copy: the caller's frames stay as given
    if x.ndim != 3 or x.shape[1:] != (model.num_bundles, 3):
        raise InputError(f"frames: expected shape (F, {model.num_bundles}, 3), got {x.shape}")
    o = np.asarray(rays.origins, dtype=np.float64)
    d = np.asarray(rays.directions, dtype=np.float64)
    if o.shape != x.shape or d.shape != x.shape:
        raise InputError(f"rays: expected origins and directions {x.shape}, got {o.shape}")
    if rounds < 1:
        raise InputError(f"rounds must be >= 1, got {rounds}")
    norm = np.linalg.norm(d, axis=2)
    has_ray = np.isfinite(o).all(axis=2) & np.isfinite(d).all(axis=2) & (norm > 0)
    on_ray = np.isnan(x).any(axis=2) & has_ray
    d = d / np.where(norm > 0, norm, 1.0)[..., None]
    result = model.solve(x, **solve)
    for _ in range(rounds):
        if not on_ray.any():
            break
        p = result.bundle_positions[on_ray]
        x[on_ray] = _closest_on_ray(p, o[on_ray], d[on_ray])
        result = model.solve(x, **solve)
    dist = np.full(x.shape[:2], np.nan)
    if on_ray.any():
        p = result.bundle_positions[on_ray]
        dist[on_ray] = np.linalg.norm(p - _closest_on_ray(p, o[on_ray], d[on_ray]), axis=1)
    return RaySolve(result=result, frames=x, on_ray=on_ray, ray_distance=dist)
