"""A mesh drawn headless as a picture: matplotlib's Agg backend, projected triangles sorted
back to front (painter's algorithm), so no OpenGL or display is needed. The report's heat maps
and the lab's figures draw with it."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

F64 = NDArray[np.float64]

__all__ = ["draw_mesh"]

_LIGHT = np.array([0.3, 0.4, 1.0]) / np.linalg.norm([0.3, 0.4, 1.0])


def _rotate_y(points: F64, yaw_deg: float, centre: F64) -> F64:
    a = np.deg2rad(yaw_deg)
    r = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    return (points - centre) @ r.T


def draw_mesh(
    ax,  # type: ignore[no-untyped-def]
    vertices: ArrayLike,
    triangles: ArrayLike,
    values: ArrayLike | None,
    norm,  # type: ignore[no-untyped-def]
    cmap,  # type: ignore[no-untyped-def]
    yaw_deg: float = 0.0,
    centre: ArrayLike | None = None,
) -> None:
    """Draws the mesh seen from +z after a rotation by `yaw_deg` about +y (orthographic),
    coloured by per-vertex `values` (grey when None), shaded by a fixed light."""
    from matplotlib.collections import PolyCollection

    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    c = v.mean(axis=0) if centre is None else np.asarray(centre, dtype=np.float64)
    p = _rotate_y(v, yaw_deg, c)
    tri = p[t]  # (T, 3, 3)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    visible = n[:, 2] > 0  # back faces are hidden by front ones anyway; culling halves the work
    order = np.argsort(tri[:, :, 2].mean(axis=1))  # farthest first
    order = order[visible[order]]
    if values is None:
        rgb = np.full((len(t), 3), 0.8)
    else:
        val = np.asarray(values, dtype=np.float64)[t].mean(axis=1)
        rgb = np.asarray(cmap(norm(val)))[:, :3]
    shade = 0.35 + 0.65 * np.clip(n @ _LIGHT, 0.0, 1.0)
    colours = np.clip(rgb * shade[:, None], 0, 1)
    pc = PolyCollection(
        list(tri[order][:, :, :2]), facecolors=colours[order], edgecolors="none", antialiaseds=False
    )
    ax.add_collection(pc)
    lo, hi = p[:, :2].min(axis=0), p[:, :2].max(axis=0)
    pad = 0.03 * float(np.max(hi - lo))
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.set_axis_off()
