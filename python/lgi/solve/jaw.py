"""Jaw rig tooling: the rig's estimation from a dataset's jaw shapes (offline, at build). The
skinning itself (two bones: skull fixed, jaw rigid about a pivot) and the pose fit are the Rust
core's: `JawRig` is `lgi._lgi.JawRig`, re-exported, with the rig's dataset-side tooling
(`unskin_displacements`, `bundle_weights`, `to_dict`/`from_dict`); each frame's pose in a solve
is a core stage too (`Model.solve(jaw=...)`).

The conventions are the core's (`lgi_core::jaw`): theta = (open angle rad, lateral angle rad,
forward translation) maps p to

    T(theta)(p) = F R(theta) F^T (p - pivot) + pivot + F (0, 0, forward),
    R(theta) = R_y(lateral) @ R_x(open),

with F the rig's `frame` (identity by default). A vertex with jaw weight w is skinned to
p + w (T(theta)(p) - p) (linear blend skinning, Eq. 2 of the paper); `unskin` inverts that
blended affine map exactly, and `fit_pose` fits theta to points by Gauss-Newton.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi._lgi import JawRig
from lgi.errors import InputError

if TYPE_CHECKING:
    from lgi.data.dataset import Dataset

F64 = NDArray[np.float64]

__all__ = [
    "JawRig",
    "RigReport",
    "auto_rig",
    "estimate_rig",
    "fit_rigid",
    "rotation_axis_angle",
]


def _points(points: ArrayLike, what: str = "points") -> F64:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"{what} must have shape (N, 3), got {p.shape}")
    return p


# --------------------------------------------------------------------------------------------
# Rigid fits.


def fit_rigid(source: ArrayLike, target: ArrayLike) -> tuple[F64, F64]:
    """Least-squares rigid motion (Kabsch): R, t minimising sum |R source + t - target|^2."""
    a = _points(source, "source")
    b = _points(target, "target")
    if a.shape != b.shape or a.shape[0] < 3:
        raise InputError(f"rigid fit needs two matching (N>=3, 3) arrays, got {a.shape}, {b.shape}")
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    h = (a - ca).T @ (b - cb)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return r, cb - r @ ca


def rotation_axis_angle(r: ArrayLike) -> tuple[F64, float]:
    """Unit axis and angle in [0, pi] of a rotation matrix (axis arbitrary for the identity)."""
    m = np.asarray(r, dtype=np.float64)
    skew = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    s = 0.5 * np.linalg.norm(skew)
    c = 0.5 * (np.trace(m) - 1.0)
    angle = float(np.arctan2(s, c))
    if s > 1e-12:
        return skew / (2.0 * s), angle
    if c > 0:
        return np.array([1.0, 0.0, 0.0]), 0.0
    # Half-turn: the axis is the dominant column of (R + I) / 2.
    sym = 0.5 * (m + np.eye(3))
    col = sym[:, int(np.argmax(np.diag(sym)))]
    return col / np.linalg.norm(col), angle


# --------------------------------------------------------------------------------------------
# Rig estimation from the dataset's jaw shapes.


def _find_rigid_set(x0: F64, disp: F64, iterations: int = 8) -> NDArray[np.int64]:
    """Vertices that jawOpen moves rigidly: start from the largest displacements, then keep the
    vertices consistent with the fitted rigid motion (trimmed refits)."""
    mag = np.linalg.norm(disp, axis=1)
    top = float(mag.max())
    moving = mag >= 0.2 * top
    n0 = max(10, int(0.02 * mag.size))
    idx = np.argsort(-mag)[: min(n0, int(moving.sum()))]
    if idx.size < 3:
        raise InputError("the jaw-open shape moves fewer than 3 vertices")
    for _ in range(iterations):
        r, t = fit_rigid(x0[idx], x0[idx] + disp[idx])
        res = np.linalg.norm(x0 @ r.T + t - (x0 + disp), axis=1)
        tol = max(3.0 * float(np.median(res[idx])), 1e-5 * top)
        new = np.flatnonzero(moving & (res <= tol))
        if new.size < 3 or np.array_equal(new, idx):
            break
        idx = new
    return idx


def _screw_pivot(r: F64, t: F64, axis: F64, near: F64) -> F64:
    """Point of the rotation axis of x -> R x + t closest to `near`."""
    # On the axis c: (I - R) c = t - (t . a) a; (I - R) is singular along a, so least squares.
    perp = t - (t @ axis) * axis
    c, *_ = np.linalg.lstsq(np.eye(3) - r, perp, rcond=None)
    return c + ((near - c) @ axis) * axis


def _closest_along(c: F64, a: F64, q: F64, b: F64) -> float | None:
    """Parameter s of the point c + s a of line (c, a) closest to line (q, b); None if parallel."""
    ab = float(a @ b)
    den = 1.0 - ab * ab
    if den < 1e-8:
        return None
    r = q - c
    return float((r @ a - ab * (r @ b)) / den)


def _laplacian_smooth(w: F64, triangles: NDArray[np.int64], iterations: int) -> F64:
    """Average each weight with its edge neighbours' mean, `iterations` times (alpha = 0.5)."""
    v = w.shape[0]
    e = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    deg = np.bincount(e.ravel(), minlength=v).astype(np.float64)
    out = w.copy()
    for _ in range(iterations):
        acc = np.bincount(e[:, 0], weights=out[e[:, 1]], minlength=v) + np.bincount(
            e[:, 1], weights=out[e[:, 0]], minlength=v
        )
        mean = np.where(deg > 0, acc / np.maximum(deg, 1.0), out)
        out = 0.5 * out + 0.5 * mean
    return np.clip(out, 0.0, 1.0)


def _orthonormal_frame(open_axis: F64, lateral_hint: F64) -> F64:
    a = open_axis / np.linalg.norm(open_axis)
    b = lateral_hint - (lateral_hint @ a) * a
    nb = np.linalg.norm(b)
    if nb < 1e-6:
        b = np.array([0.0, 1.0, 0.0]) - a[1] * a
        nb = np.linalg.norm(b)
    b = b / nb
    return np.stack([a, b, np.cross(a, b)], axis=1)


@dataclass(frozen=True)
class RigReport:
    """Diagnostics of `estimate_rig`, returned with `return_report=True`."""

    rigid_vertices: NDArray[np.int64]
    """Vertices treated as rigidly attached to the jaw."""
    open_axis: F64
    """Hinge axis of the jaw-open shape (unit, oriented towards +x)."""
    open_angle: float
    """Rotation angle of the jaw-open shape's rigid fit, radians."""
    rigid_rms: float
    """RMS residual of the jaw-open rigid fit over the rigid vertices."""
    jaw_theta: dict[str, F64]
    """Fitted theta of each named jaw shape present (open, left, right, forward)."""
    explained: F64
    """(S,) fraction of each shape's squared rigid-vertex displacement its theta fit explains."""


def estimate_rig(
    neutral: ArrayLike,
    shapes: ArrayLike,
    names: Sequence[str],
    jaw_open: str = "jawOpen",
    jaw_left: str = "jawLeft",
    jaw_right: str = "jawRight",
    jaw_forward: str = "jawForward",
    rigid_vertices: ArrayLike | None = None,
    triangles: ArrayLike | None = None,
    smooth_iterations: int = 1,
    estimate_frame: bool = False,
    huber: float | None = 1.345,
    min_explained: float = 0.8,
    return_report: bool = False,
) -> Any:
    """Estimate the jaw rig and every shape's theta from a dataset's jaw shapes.

    `shapes` are (S, V, 3) displacements from `neutral`. The jaw-open shape's rigid part (the
    `rigid_vertices`, e.g. the lower teeth; found automatically when None) gives the hinge axis,
    the pivot (the point of the hinge closest to the jawLeft/jawRight rotation axes, or to the
    rigid part's centroid when there are none) and per-vertex weights
    (projection of each vertex's displacement onto the rigid displacement field, clipped to
    [0, 1] and smoothed `smooth_iterations` times over the mesh edges when `triangles` is
    given). Each shape's theta is a robust Gauss-Newton fit of the rigid vertices
    (`JawRig.fit_pose`), kept only when
    the fitted rigid motion explains at least `min_explained` of the squared displacement of the
    rigid vertices (otherwise the shape deforms them non-rigidly and gets theta = 0).

    With `estimate_frame`, the rig's axes follow the estimated hinge (and the jawLeft/jawRight
    rotation axis for the lateral axis); by default they are x, y, z as in `lgi.lab.sample`.
    Returns (JawRig, shape_theta (S, 3)), plus a `RigReport` when `return_report`.
    """
    x0 = _points(neutral, "neutral")
    s = np.asarray(shapes, dtype=np.float64)
    if s.ndim != 3 or s.shape[1:] != x0.shape:
        raise InputError(f"shapes must have shape (S, {x0.shape[0]}, 3), got {s.shape}")
    names = list(names)
    if len(names) != s.shape[0]:
        raise InputError(f"{len(names)} names for {s.shape[0]} shapes")
    if jaw_open not in names:
        raise InputError(f"no jaw-open shape named {jaw_open!r} in the dataset")
    if not np.all(np.isfinite(s)) or not np.all(np.isfinite(x0)):
        raise InputError("neutral and shapes must be finite")
    d_open = s[names.index(jaw_open)]
    if rigid_vertices is None:
        rigid = _find_rigid_set(x0, d_open)
    else:
        rigid = np.unique(np.asarray(rigid_vertices, dtype=np.int64))
        if rigid.size < 3 or rigid.min() < 0 or rigid.max() >= x0.shape[0]:
            raise InputError("rigid_vertices must hold at least 3 valid vertex indices")
    r_open, t_open = fit_rigid(x0[rigid], x0[rigid] + d_open[rigid])
    fit_miss = x0[rigid] @ r_open.T + t_open - x0[rigid] - d_open[rigid]
    rms = float(np.sqrt(np.mean(np.sum(fit_miss**2, axis=1))))
    axis, angle = rotation_axis_angle(r_open)
    if axis[0] < 0:
        axis, angle = -axis, -angle
    if abs(angle) < 1e-9:
        raise InputError(f"the {jaw_open!r} shape does not rotate its rigid part")
    pivot = _screw_pivot(r_open, t_open, axis, x0[rigid].mean(axis=0))

    # The lateral shapes pin where along the hinge the pivot sits (the hinge alone cannot): the
    # pivot is the point of the hinge closest to the lateral rotation axes (averaged, so a
    # left/right pair stays symmetric). Their axes also give the frame's lateral direction.
    lateral_axes = []
    shifts = []
    for name in (jaw_left, jaw_right):
        if name not in names:
            continue
        d = s[names.index(name)]
        r_lat, t_lat = fit_rigid(x0[rigid], x0[rigid] + d[rigid])
        ax, ang = rotation_axis_angle(r_lat)
        if ang < 1e-6:
            continue
        ax = ax if ax[1] >= 0 else -ax
        lateral_axes.append(ax)
        on_axis = _screw_pivot(r_lat, t_lat, ax, pivot)
        shift = _closest_along(pivot, axis, on_axis, ax)
        if shift is not None:
            shifts.append(shift)
    if shifts:
        pivot = pivot + float(np.mean(shifts)) * axis

    frame = np.eye(3)
    if estimate_frame:
        hint = lateral_axes[0] if lateral_axes else np.array([0.0, 1.0, 0.0])
        frame = _orthonormal_frame(axis, hint)

    # Weights: project the jaw-open displacement onto the rigid field d_v = T(p_v) - p_v.
    field_ = x0 @ r_open.T + t_open - x0
    den = np.einsum("vi,vi->v", field_, field_)
    num = np.einsum("vi,vi->v", d_open, field_)
    tiny = den <= (1e-12 * float(den.max()) if den.size else 0.0)
    w = np.where(tiny, 0.0, num / np.where(tiny, 1.0, den))
    w = np.clip(w, 0.0, 1.0)
    if triangles is not None and smooth_iterations > 0:
        tri = np.asarray(triangles, dtype=np.int64)
        if tri.ndim != 2 or tri.shape[1] != 3 or tri.min() < 0 or tri.max() >= x0.shape[0]:
            raise InputError("triangles must be (T, 3) valid vertex indices")
        w = _laplacian_smooth(w, tri, smooth_iterations)
    w[rigid] = 1.0
    rig = JawRig(pivot=pivot, weights=w, frame=frame)

    shape_theta = np.zeros((s.shape[0], 3))
    ones = np.ones(rigid.size)
    explained = np.zeros(s.shape[0])
    for k in range(s.shape[0]):
        d = s[k][rigid]
        total = float(np.sum(d * d))
        if total == 0.0:
            continue
        th = rig.fit_pose(x0[rigid], x0[rigid] + d, huber=huber)
        miss = rig.skin(x0[rigid], th, ones) - x0[rigid] - d
        # A shape that deforms the rigid part non-rigidly (an expression pulling the chin skin)
        # has no jaw motion of its own; a rigid motion that explains little of it is spurious.
        explained[k] = 1.0 - float(np.sum(miss * miss)) / total
        if explained[k] >= min_explained:
            shape_theta[k] = th
    if return_report:
        named = {
            n: shape_theta[names.index(n)]
            for n in (jaw_open, jaw_left, jaw_right, jaw_forward)
            if n in names
        }
        return rig, shape_theta, RigReport(rigid, axis, float(angle), rms, named, explained)
    return rig, shape_theta


def auto_rig(dataset: Dataset) -> tuple[JawRig | None, NDArray[np.float64] | None]:
    """The rig `Model.build(jaw="auto")` uses: `estimate_rig` on the dataset's jaw shapes, or
    none when it has no `jawOpen` shape (or no rigid jaw is found in it: then a warning)."""
    if "jawOpen" not in dataset.names:
        return None, None
    try:
        rig, theta = estimate_rig(dataset.neutral, dataset.shapes, dataset.names)
    except InputError as e:
        warnings.warn(f"jaw='auto': no jaw rig ({e}); building without one", stacklevel=3)
        return None, None
    return rig, np.asarray(theta, dtype=np.float64)
