"""The jaw skinning formula (paper Eq. 2) written out in numpy: the test oracle of the core's
skinning (`lgi.solve.jaw.JawRig`, `lgi_core::jaw`), which the library itself no longer repeats.

theta = (open, lateral, forward) maps p to F R F^T (p - pivot) + pivot + F (0, 0, forward) with
R = R_y(lateral) @ R_x(open) and F the rig's frame; a point with jaw weight w moves to
p + w (T(p) - p), and `unskin` solves that blended affine map per point.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

F64 = NDArray[np.float64]


def jaw_transform(theta: ArrayLike, frame: ArrayLike | None = None) -> tuple[F64, F64]:
    """World rotation R and translation t of the jaw: T(p) = R (p - pivot) + pivot + t."""
    th = np.asarray(theta, dtype=np.float64)
    ca, sa = np.cos(th[0]), np.sin(th[0])
    cb, sb = np.cos(th[1]), np.sin(th[1])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]])
    ry = np.array([[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]])
    f = np.eye(3) if frame is None else np.asarray(frame, dtype=np.float64)
    return f @ ry @ rx @ f.T, f[:, 2] * th[2]


def skin_jaw(
    points: ArrayLike,
    theta: ArrayLike,
    pivot: ArrayLike,
    weights: ArrayLike,
    frame: ArrayLike | None = None,
) -> F64:
    """Two-bone linear blend skinning, written as p + w (T(p) - p)."""
    p = np.asarray(points, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)
    r, t = jaw_transform(theta, frame)
    moved = (p - np.asarray(pivot, dtype=np.float64)) @ (r - np.eye(3)).T + t
    return p + w[:, None] * moved


def unskin_jaw(
    points: ArrayLike,
    theta: ArrayLike,
    pivot: ArrayLike,
    weights: ArrayLike,
    frame: ArrayLike | None = None,
) -> F64:
    """The inverse of `skin_jaw`: solves ((1 - w) I + w R) q = y - pivot - w t per point."""
    y = np.asarray(points, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)
    piv = np.asarray(pivot, dtype=np.float64)
    r, t = jaw_transform(theta, frame)
    m = np.eye(3)[None] + w[:, None, None] * (r - np.eye(3))[None]
    q = np.linalg.solve(m, (y - piv - w[:, None] * t)[:, :, None])[:, :, 0]
    out = piv + q
    out[w == 0] = y[w == 0]
    return out
