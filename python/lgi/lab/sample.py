"""The shipped sample: a synthetic face, its expression shapes, a marker layout and a performance.

Everything is generated from a seed by this module (no external data), so `lgi demo` and the
tests always have a dataset with holes (mouth, eyes), real jaw rotation and expression-only folds.

Conventions: centimetres, +y up, +z forward (like ICT). "Left" is the character's left, +x.

How the ground truth of the performance is made (per frame f, weights w = truth_weights[f]):

    theta_f   = sum over jaw shapes k of  w_k * shape_jaw_theta[k]
    pre_f     = neutral + sum over non-jaw k of ( w_k * (shapes[k] - wrinkles[k])
                                                  + w_k ** 1.5 * wrinkles[k] )
    truth[f]  = pre_f + jaw_weights * (T(theta_f)(pre_f) - pre_f)      (jaw skinning, LBS)

with T(theta)(p) = R_y(theta[1]) @ R_x(theta[0]) @ (p - jaw_pivot) + jaw_pivot + (0, 0, theta[2]),
computed by the core's skinning (`lgi.jaw.JawRig.skin` with the identity frame).
`shapes` and `wrinkles` enter promoted from their float32 storage, so the truth is reproducible
from the saved arrays. The jaw shapes themselves are `T(shape_jaw_theta[k])` applied with full
LBS to the neutral: a weight of 1 reproduces the shape, a weight of 0.5 is a rotation by half the
angle (not half the displacement), and the fine folds (`wrinkles`) grow like w**1.5, so no frame
is in the linear span of the shapes.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lgi import _lgi
from lgi.errors import DatasetError, DatasetFileError, InputError
from lgi.jaw import JawRig

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

__all__ = [
    "Sample",
    "describe",
    "dropout_mask",
    "load_sample",
    "make_sample",
    "save_sample",
]

# Face layout (cm). The patch spans x in [-7, 7] and y in [-8, 8].
_HALF_WIDTH = 7.0
_HALF_HEIGHT = 8.0
_MOUTH_Y = -3.4  # snapped to the nearest grid row
_MOUTH_HALF_WIDTH = 2.4  # snapped to a grid column
_MOUTH_HALF_GAP = 0.03  # lips are 0.6 mm apart at the centre of the neutral
_EYE_CX = 3.1
_EYE_CY = 2.6
_EYE_A = 1.35
_EYE_B = 0.55
_JAW_PIVOT = (0.0, -1.5, 3.0)
_JAW_OPEN = np.deg2rad(25.0)
_JAW_LATERAL = 0.12  # rad; the chin moves about 7 mm sideways
_JAW_FORWARD = 0.6  # cm
_WRINKLE_POWER = 1.5
_MIN_RESOLUTION = 40
# About 0.83 r^2 vertices: 800 rows are ~530,000 vertices, beyond any test or demo.
_MAX_RESOLUTION = 800


@dataclass(frozen=True, eq=False, repr=False)
class Sample:
    """A complete synthetic capture: dataset, markers, performance and its ground truth.

    See the module documentation for exactly how `truth` is made from `truth_weights`.
    """

    neutral: F64
    """(V, 3) neutral vertex positions, cm, +y up, +z forward."""
    triangles: I64
    """(T, 3) vertex indices, counter-clockwise seen from the front (+z)."""
    uvs: F64
    """(U, 2) texture coordinates: a planar projection of the face (one chart)."""
    uv_triangles: I64
    """(T, 3) uv indices per triangle corner (equal to `triangles`: one uv per vertex)."""
    shapes: NDArray[np.float32]
    """(S, V, 3) displacements of each expression shape from the neutral."""
    names: list[str]
    """S ARKit-style shape names."""
    markers_rest: F64
    """(B, 3) marker positions on the neutral surface."""
    marker_names: list[str]
    """B marker names."""
    performance: F64
    """(F, B, 3) captured marker positions: truth + Gaussian noise, NaN rows where dropped."""
    truth: F64
    """(F, V, 3) ground-truth meshes of the performance (no noise)."""
    truth_weights: F64
    """(F, S) shape weights that made each frame (jaw shapes act through `jaw_theta`)."""
    jaw_theta: F64
    """(F, 3) true jaw parameters per frame: open angle (rad), lateral angle (rad), forward (cm)."""
    jaw_pivot: F64
    """(3,) centre of the jaw rotation."""
    jaw_weights: F64
    """(V,) jaw skinning weight of each vertex in [0, 1] (1 on chin and lower lip)."""
    shape_jaw_theta: F64
    """(S, 3) jaw parameters of each shape (zero for shapes that are not jaw shapes)."""
    seed: int
    """The seed the sample was made from."""
    marker_triangles: I64
    """(B,) triangle of the neutral each marker was placed on."""
    marker_barycentrics: F64
    """(B, 3) barycentric coordinates of each marker in its triangle."""
    wrinkles: NDArray[np.float32]
    """(S, V, 3) the fine-fold part of each shape (included in `shapes`), grows like w**1.5."""

    def __repr__(self) -> str:
        return (
            f"Sample(seed={self.seed}, vertices={self.num_vertices}, shapes={self.num_shapes}, "
            f"markers={self.num_markers}, frames={self.num_frames})"
        )

    @property
    def num_vertices(self) -> int:
        """Number of vertices V."""
        return int(self.neutral.shape[0])

    @property
    def num_shapes(self) -> int:
        """Number of expression shapes S."""
        return int(self.shapes.shape[0])

    @property
    def num_markers(self) -> int:
        """Number of markers B."""
        return int(self.markers_rest.shape[0])

    @property
    def num_frames(self) -> int:
        """Number of performance frames F."""
        return int(self.performance.shape[0])


# --------------------------------------------------------------------------------------------
# Small smooth building blocks.


def _sstep(t: F64) -> F64:
    """C1 smoothstep of t clipped to [0, 1]."""
    s = np.clip(t, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def _gauss(x: F64, y: F64, cx: float, cy: float, sx: float, sy: float) -> F64:
    return np.exp(-0.5 * (((x - cx) / sx) ** 2 + ((y - cy) / sy) ** 2))


def _window(v: F64, lo: float, hi: float, soft: float) -> F64:
    """1 inside [lo, hi], falling smoothly to 0 over `soft` outside."""
    return _sstep((v - lo + soft) / soft) * _sstep((hi - v + soft) / soft)


def _vec(mask: F64, dx: float, dy: float, dz: float) -> F64:
    return mask[:, None] * np.array([dx, dy, dz])


# --------------------------------------------------------------------------------------------
# The neutral surface.


def _height(x: F64, y: F64) -> F64:
    """Depth z of the face at (x, y): a head ellipsoid with nose, brows, cheeks, lips, chin."""
    z = 10.0 * np.sqrt(np.maximum(1.0 - (x / 10.0) ** 2 - ((y - 0.5) / 14.0) ** 2, 0.02))
    z = z - 1.2 * _sstep((-6.6 - y) / 1.4)  # under the chin the face recedes
    # Nose: a ridge that rises from the bridge to the tip and drops to the upper lip.
    t = _sstep((2.8 - y) / 3.2)
    top = 1.0 - _sstep((y - 2.6) / 1.0)
    below = 1.0 - _sstep((-0.3 - y) / 1.0)
    width = 0.5 + 0.45 * t
    z = z + (0.35 + 1.9 * t) * top * below * np.exp(-0.5 * (x / width) ** 2)
    ym = _MOUTH_Y
    lip_w = np.exp(-((x / 2.0) ** 4))
    ax = np.abs(x)
    z = (
        z
        + 0.45 * _gauss(ax, y, 1.0, -0.95, 0.42, 0.38)  # nose alae
        + 0.4 * np.exp(-(((y - 4.15 - 0.03 * x * x) / 0.45) ** 2)) * _window(ax, 0.5, 5.3, 0.6)
        + 0.15 * _gauss(x, y, 0.0, 4.0, 0.8, 0.8)  # glabella
        - 0.9 * _gauss(ax, y, _EYE_CX, _EYE_CY, 1.5, 0.95)  # eye sockets
        + 0.35 * _gauss(ax, y, _EYE_CX, _EYE_CY, 1.0, 0.6)  # eyeballs under the lids
        + 0.65 * _gauss(ax, y, 3.7, -0.1, 1.4, 1.1)  # cheekbones
        + 0.42 * np.exp(-(((y - (ym + 0.42)) / 0.32) ** 2)) * lip_w  # upper lip
        + 0.45 * np.exp(-(((y - (ym - 0.5)) / 0.38) ** 2)) * lip_w  # lower lip
        - 0.12 * np.exp(-(((y - ym) / 0.14) ** 2)) * lip_w  # lips meet in a crease
        - 0.25 * np.exp(-(((y - (ym - 1.35)) / 0.35) ** 2)) * np.exp(-((x / 2.2) ** 2))
        + 0.55 * _gauss(x, y, 0.0, -6.1, 1.5, 0.95)  # chin
    )
    return z


def _normals(x: F64, y: F64) -> F64:
    """Unit normals of the height field (analytic in position, so both lips agree at the slit)."""
    h = 1e-4
    zx = (_height(x + h, y) - _height(x - h, y)) / (2 * h)
    zy = (_height(x, y + h) - _height(x, y - h)) / (2 * h)
    n = np.stack([-zx, -zy, np.ones_like(x)], axis=1)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


@dataclass(frozen=True)
class _Face:
    positions: F64
    triangles: I64
    slit_side: NDArray[np.int8]  # +1 upper lip on the slit, -1 its lower-lip duplicate, else 0
    mouth_y: float
    mouth_half_width: float


def _build_face(resolution: int) -> _Face:
    """Grid of quads over the patch, eye quads removed, mouth row cut open."""
    ny = resolution
    step = 2.0 * _HALF_HEIGHT / (ny - 1)
    half = round(_HALF_WIDTH / step)
    nx = 2 * half + 1  # odd, so that x = 0 is a column and the mesh is mirror symmetric
    xs = (np.arange(nx) - half) * (_HALF_WIDTH / half)
    ys = -_HALF_HEIGHT + np.arange(ny) * step
    jm = round((_MOUTH_Y + _HALF_HEIGHT) / step)
    k = max(round(_MOUTH_HALF_WIDTH / (_HALF_WIDTH / half)), 2)
    mouth_y = float(ys[jm])
    mouth_hw = float(xs[half + k])

    gx, gy = np.meshgrid(xs, ys)  # (ny, nx)
    gid = np.arange(nx * ny, dtype=np.int64).reshape(ny, nx)
    slit_cols = np.arange(half - k + 1, half + k)  # interior of the cut, corners excluded
    lower = gid.copy()
    lower[jm, slit_cols] = nx * ny + np.arange(slit_cols.size)

    def inside_eye(px: F64, py: F64) -> NDArray[np.bool_]:
        return (((np.abs(px) - _EYE_CX) / _EYE_A) ** 2 + ((py - _EYE_CY) / _EYE_B) ** 2) < 1.0

    eye_vertex = inside_eye(gx, gy)
    removed = eye_vertex[:-1, :-1] | eye_vertex[:-1, 1:] | eye_vertex[1:, :-1] | eye_vertex[1:, 1:]
    qj, qi = np.nonzero(~removed)
    a = gid[qj, qi]
    b = gid[qj, qi + 1]
    below_cut = qj == jm - 1
    c = np.where(below_cut, lower[qj + 1, qi + 1], gid[qj + 1, qi + 1])
    d = np.where(below_cut, lower[qj + 1, qi], gid[qj + 1, qi])
    # Diagonals mirror across x = 0 so the triangulation is symmetric like the face.
    left = (qi < half)[:, None]
    t1 = np.where(left, np.stack([a, b, c], 1), np.stack([a, b, d], 1))
    t2 = np.where(left, np.stack([a, c, d], 1), np.stack([b, c, d], 1))
    tris = np.stack([t1, t2], axis=1).reshape(-1, 3)

    px = np.concatenate([gx.ravel(), xs[slit_cols]])
    py = np.concatenate([gy.ravel(), np.full(slit_cols.size, mouth_y)])
    side = np.zeros(px.size, dtype=np.int8)
    side[gid[jm, slit_cols]] = 1
    side[nx * ny :] = -1
    gap = _MOUTH_HALF_GAP * (1.0 - (px / mouth_hw) ** 2)
    py = py + side * gap

    used = np.unique(tris)
    remap = np.full(px.size, -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    px, py, side = px[used], py[used], side[used]
    positions = np.stack([px, py, _height(px, py)], axis=1)
    return _Face(positions, remap[tris], side, mouth_y, mouth_hw)


def _lowerness(face: _Face, growth: float, rise: float, corner: float, cap: float) -> F64:
    """1 below the mouth, 0 above; a step across the cut, continuous everywhere else.

    Inside the mouth's width the transition band is narrower than a grid row, so the lips are
    split by the cut; lateral to the corners it widens linearly (a wedge from each corner, up
    to `cap` cm) and follows a line that rises by `rise` towards the side of the face. Within
    `corner` cm of a mouth corner the field relaxes to 0.5, so the corners stretch over a
    region instead of tearing a few triangles apart.
    """
    x, y = face.positions[:, 0], face.positions[:, 1]
    ax = np.abs(x)
    hw = face.mouth_half_width
    spread = 0.2 * np.logaddexp(0.0, (ax - hw) / 0.2)
    band = cap * np.tanh((0.04 + growth * spread) / cap)
    line = face.mouth_y + rise * _sstep((ax - hw) / (_HALF_WIDTH - hw))
    yy = np.where(face.slit_side > 0, face.mouth_y + band, y)
    yy = np.where(face.slit_side < 0, face.mouth_y - band, yy)
    sharp = _sstep(0.5 - (yy - line) / (2.0 * band))
    r = np.hypot(ax - hw, y - face.mouth_y)
    return 0.5 + (sharp - 0.5) * _sstep(r / corner)


# --------------------------------------------------------------------------------------------
# Expression shapes: each is a smooth part plus a "wrinkle" part (folds that only expressions
# have); both are (V, 3) float64 displacements.


class _Shapes:
    def __init__(self, face: _Face) -> None:
        p = face.positions
        self.x, self.y = p[:, 0], p[:, 1]
        self.n = _normals(self.x, self.y)
        self.ym = face.mouth_y
        self.hw = face.mouth_half_width
        self.lower = _lowerness(face, growth=0.45, rise=0.0, corner=1.2, cap=3.0)
        self.upper = 1.0 - self.lower
        self.lip_side = self.upper - self.lower  # +1 upper lip, -1 lower lip
        self.lips = np.exp(-((self.x / 2.6) ** 4)) * np.exp(-(((self.y - self.ym) / 1.1) ** 2))
        self.zero = np.zeros_like(p)

    def along_normal(self, h: F64) -> F64:
        return h[:, None] * self.n

    def crease(
        self,
        a: tuple[float, float],
        b: tuple[float, float],
        side: float,
        depth: float,
        width: float,
        bulge: float,
        bulge_offset: float,
        bulge_width: float,
    ) -> F64:
        """Height of a sharp fold along segment a-b: a narrow valley and a bulge on one side."""
        ax_, ay_ = a
        dx, dy = b[0] - ax_, b[1] - ay_
        length = np.hypot(dx, dy)
        ux, uy = dx / length, dy / length
        rx, ry = self.x - ax_, self.y - ay_
        t = (rx * ux + ry * uy) / length
        d = side * (rx * -uy + ry * ux)
        taper = np.sin(np.pi * np.clip(t, 0.0, 1.0)) ** 0.7
        profile = -depth * np.exp(-((d / width) ** 2)) + bulge * np.exp(
            -(((d - bulge_offset) / bulge_width) ** 2)
        )
        return taper * profile

    def eye(self, s: float) -> tuple[F64, F64, F64, F64]:
        """(lid profile, upper-lid share, distance above the upper lid, below the lower lid).

        The profile is 1 mid-lid and falls to 0 at the corners of the eye faster than the
        opening does, so the corners (where upper and lower lid meet) do not tear.
        """
        u = (self.x - s * _EYE_CX) / _EYE_A
        opening = _EYE_B * np.sqrt(np.maximum(1.0 - u * u, 0.0))
        profile = np.maximum(1.0 - u * u, 0.0) ** 0.75
        upper = _sstep((self.y - _EYE_CY) / 0.3 + 0.5)
        return profile, upper, self.y - (_EYE_CY + opening), (_EYE_CY - opening) - self.y

    # -- jaw-free shapes, by ARKit name ------------------------------------------------------

    def mouth_smile(self, s: float) -> tuple[F64, F64]:
        x, y = self.x, self.y
        smooth = _vec(_gauss(x, y, s * self.hw, self.ym, 1.3, 1.1), s * 0.55, 0.8, -0.45)
        smooth += _vec(_gauss(x, y, s * 3.3, self.ym + 2.2, 1.3, 1.2), s * 0.1, 0.45, 0.3)
        fold = self.crease((s * 1.55, -1.15), (s * 3.3, -4.7), s, 0.22, 0.11, 0.3, 0.42, 0.3)
        return smooth, self.along_normal(fold)

    def mouth_frown(self, s: float) -> tuple[F64, F64]:
        x, y = self.x, self.y
        smooth = _vec(_gauss(x, y, s * self.hw, self.ym, 1.2, 1.0), s * 0.1, -0.55, -0.1)
        smooth += _vec(_gauss(x, y, s * 2.6, self.ym - 1.6, 1.0, 1.0), 0.0, -0.25, 0.1)
        fold = self.crease(
            (s * (self.hw + 0.2), self.ym - 0.3),
            (s * 2.9, self.ym - 2.6),
            s,
            0.12,
            0.1,
            0.1,
            0.3,
            0.25,
        )
        return smooth, self.along_normal(fold)

    def perioral_lines(self, amplitude: float, count: int) -> F64:
        """Radial fine lines around the mouth (pursed lips)."""
        ex, ey = self.x / 2.6, (self.y - self.ym) / 1.0
        rho = np.hypot(ex, ey)
        phi = np.arctan2(ey, ex)
        return amplitude * np.cos(count * phi) * _window(rho, 0.95, 1.55, 0.25)

    def mouth_pucker(self) -> tuple[F64, F64]:
        m = self.lips
        smooth = np.stack([-0.3 * self.x * m, 0.0 * m, 0.85 * m], axis=1)
        return smooth, self.along_normal(self.perioral_lines(0.055, 22))

    def mouth_funnel(self) -> tuple[F64, F64]:
        m = self.lips
        smooth = np.stack([-0.15 * self.x * m, 0.28 * self.lip_side * m, 0.6 * m], axis=1)
        return smooth, self.along_normal(self.perioral_lines(0.035, 18))

    def mouth_press(self, s: float) -> tuple[F64, F64]:
        x, y = self.x, self.y
        m = _gauss(x, y, s * 1.2, self.ym, 1.5, 0.6)
        smooth = np.stack([0.0 * m, -0.12 * self.lip_side * m, -0.18 * m], axis=1)
        lines = 0.03 * np.cos(2 * np.pi * x / 0.32) * np.exp(-(((y - self.ym) / 0.35) ** 2))
        return smooth, self.along_normal(lines * _gauss(x, y, s * 1.2, self.ym, 1.3, 5.0))

    def mouth_roll(self, upper: bool) -> tuple[F64, F64]:
        x, y = self.x, self.y
        sgn = 1.0 if upper else -1.0
        part = self.upper if upper else self.lower
        m = np.exp(-((x / 2.4) ** 4)) * np.exp(-(((y - self.ym) / 0.45) ** 2)) * part
        smooth = _vec(m, 0.0, -0.12 * sgn, -0.45)
        edge = self.ym + (0.45 if upper else -0.5)
        border = -0.08 * np.exp(-(((y - edge) / 0.09) ** 2)) * np.exp(-((x / 2.2) ** 4)) * part
        return smooth, self.along_normal(border)

    def mouth_shrug_upper(self) -> tuple[F64, F64]:
        x, y = self.x, self.y
        m = np.exp(-((x / 2.4) ** 2)) * np.exp(-(((y - self.ym - 0.5) / 0.7) ** 2)) * self.upper
        return _vec(m, 0.0, 0.25, 0.15), self.zero

    def mouth_shrug_lower(self) -> tuple[F64, F64]:
        x, y = self.x, self.y
        m = np.exp(-((x / 2.5) ** 2)) * _window(y, -7.5, self.ym, 1.0) * self.lower
        dimples = 0.045 * np.sin(2 * np.pi * x / 0.55) * np.sin(2 * np.pi * y / 0.6)
        return _vec(m, 0.0, 0.35, 0.25), self.along_normal(
            dimples * _gauss(x, y, 0.0, -5.8, 1.2, 0.9)
        )

    def mouth_side(self, s: float) -> tuple[F64, F64]:
        x, y = self.x, self.y
        m = np.exp(-((x / 3.2) ** 4)) * np.exp(-(((y - self.ym) / 1.6) ** 2))
        return _vec(m, s * 0.7, 0.05, 0.0), self.zero

    def mouth_stretch(self, s: float) -> tuple[F64, F64]:
        x, y = self.x, self.y
        smooth = _vec(_gauss(x, y, s * self.hw, self.ym, 1.4, 1.2), s * 0.5, -0.35, -0.15)
        folds = 0.04 * np.cos(2 * np.pi * (s * x - self.hw) / 0.4)
        return smooth, self.along_normal(folds * _gauss(x, y, s * 3.5, self.ym - 1.2, 0.9, 1.0))

    def mouth_dimple(self, s: float) -> tuple[F64, F64]:
        x, y = self.x, self.y
        smooth = _vec(_gauss(x, y, s * self.hw, self.ym, 0.9, 0.8), s * 0.25, 0.05, -0.3)
        pit = -0.18 * _gauss(x, y, s * (self.hw + 0.55), self.ym - 0.1, 0.16, 0.22)
        return smooth, self.along_normal(pit)

    def mouth_upper_up(self, s: float) -> tuple[F64, F64]:
        x, y = self.x, self.y
        m = _gauss(x, y, s * 1.0, self.ym + 0.5, 0.9, 0.6) * self.upper
        fold = self.crease((s * 1.55, -1.15), (s * 2.6, -3.0), s, 0.11, 0.11, 0.12, 0.4, 0.3)
        return _vec(m, 0.0, 0.45, 0.15), self.along_normal(fold)

    def mouth_lower_down(self, s: float) -> tuple[F64, F64]:
        m = _gauss(self.x, self.y, s * 1.0, self.ym - 0.5, 0.9, 0.6) * self.lower
        return _vec(m, 0.0, -0.45, 0.1), self.zero

    def mouth_close(self) -> tuple[F64, F64]:
        m = self.lips
        return np.stack([0.0 * m, -0.25 * self.lip_side * m, 0.1 * m], axis=1), self.zero

    def cheek_puff(self) -> tuple[F64, F64]:
        x, y = self.x, self.y
        h = 0.9 * (_gauss(x, y, 3.4, -2.6, 1.5, 1.4) + _gauss(x, y, -3.4, -2.6, 1.5, 1.4))
        # Inflate along the head's broad normal: the lips' crease normals would tear the slit.
        out = np.stack([x / 100.0, (y - 0.5) / 196.0, np.full_like(x, 0.1)], axis=1)
        out /= np.linalg.norm(out, axis=1, keepdims=True)
        return h[:, None] * out + _vec(self.lips, 0.0, 0.0, 0.2), self.zero

    def cheek_squint(self, s: float) -> tuple[F64, F64]:
        x, y = self.x, self.y
        smooth = _vec(_gauss(x, y, s * 3.5, 0.5, 1.4, 1.0), s * 0.05, 0.35, 0.15)
        rr = np.hypot((x - s * _EYE_CX) / 1.6, (y - _EYE_CY) / 0.95)
        fold = -0.07 * np.exp(-(((rr - 1.0) / 0.12) ** 2)) * _sstep((_EYE_CY - y) / 0.3)
        return smooth, self.along_normal(fold)

    def nose_sneer(self, s: float) -> tuple[F64, F64]:
        x, y = self.x, self.y
        smooth = _vec(_gauss(x, y, s * 1.05, -0.9, 0.6, 0.6), s * 0.05, 0.35, 0.05)
        smooth += _vec(_gauss(x, y, s * 0.7, 1.0, 0.6, 0.9), 0.0, 0.2, 0.0)
        smooth += _vec(_gauss(x, y, s * 0.9, self.ym + 0.6, 0.7, 0.5) * self.upper, 0, 0.15, 0)
        bunny = 0.065 * np.cos(2 * np.pi * (y + 0.6 * s * x) / 0.42)
        bunny = bunny * _gauss(x, y, s * 0.75, 1.7, 0.45, 0.55)
        # Fine folds fanning from the inner corner of the eye, like crow's feet mirrored.
        cx, cy = s * (_EYE_CX - _EYE_A - 0.1), _EYE_CY
        r = np.hypot(x - cx, y - cy)
        phi = np.arctan2(y - cy, -s * (x - cx))
        fan = 0.04 * np.cos(11 * phi) * _window(r, 0.45, 1.1, 0.25) * _sstep((cy - y) / 0.2 + 0.5)
        return smooth, self.along_normal(bunny + fan)

    def forehead_furrows(self, cx: float, sx: float) -> F64:
        """Horizontal forehead furrows, curving down away from their centre cx."""
        x, y = self.x, self.y
        q = y - 0.035 * (x - cx) ** 2
        return (
            0.085
            * np.cos(2 * np.pi * (q - 5.0) / 0.8)
            * np.exp(-0.5 * ((x - cx) / sx) ** 2)
            * _window(y, 5.0, 7.4, 0.5)
        )

    def brow_inner_up(self) -> tuple[F64, F64]:
        x, y = self.x, self.y
        smooth = _vec(_gauss(x, y, 0.0, 4.2, 1.9, 0.9), 0.0, 0.85, 0.05)
        smooth += _vec(_gauss(x, y, 0.0, 5.8, 2.5, 1.5), 0.0, 0.35, 0.0)
        return smooth, self.along_normal(self.forehead_furrows(0.0, 2.3))

    def brow_outer_up(self, s: float) -> tuple[F64, F64]:
        x, y = self.x, self.y
        smooth = _vec(_gauss(x, y, s * 3.4, 4.1, 1.4, 0.9), s * 0.05, 0.8, 0.0)
        smooth += _vec(_gauss(x, y, s * 3.0, 5.8, 1.8, 1.5), 0.0, 0.3, 0.0)
        return smooth, self.along_normal(self.forehead_furrows(s * 3.0, 1.6))

    def brow_down(self, s: float) -> tuple[F64, F64]:
        x, y = self.x, self.y
        smooth = _vec(_gauss(x, y, s * 1.9, 4.2, 1.5, 0.8), -s * 0.25, -0.55, 0.1)
        band = _window(y, 3.6, 5.1, 0.35)
        glabella = (
            -0.16 * np.exp(-(((x - s * 0.42) / 0.085) ** 2))
            + 0.08 * np.exp(-(((x - s * 0.75) / 0.22) ** 2))
        ) * band
        procerus = -0.06 * np.exp(-(((y - 3.0) / 0.09) ** 2)) * _gauss(x, y, s * 0.2, 3.0, 0.5, 9)
        return smooth, self.along_normal(glabella + procerus)

    def eye_blink(self, s: float) -> tuple[F64, F64]:
        profile, up, above, below = self.eye(s)
        upper = up * profile * (1.0 - _sstep(above / 1.7))
        lower = (1.0 - up) * profile * (1.0 - _sstep(below / 0.8))
        dy = -1.75 * _EYE_B * upper + 0.1 * lower
        dz = 0.12 * upper
        return np.stack([0.0 * dy, dy, dz], axis=1), self.zero

    def eye_squint(self, s: float) -> tuple[F64, F64]:
        x, y = self.x, self.y
        profile, up, above, below = self.eye(s)
        dy = -0.15 * up * profile * (1.0 - _sstep(above / 1.2))
        dy += 0.3 * (1.0 - up) * profile * (1.0 - _sstep(below / 1.0))
        smooth = np.stack([0.0 * dy, dy, 0.0 * dy], axis=1)
        cx, cy = s * (_EYE_CX + _EYE_A + 0.15), _EYE_CY
        r = np.hypot(x - cx, y - cy)
        phi = np.arctan2(y - cy, s * (x - cx))
        feet = (
            0.06
            * np.cos(11 * phi)
            * _window(r, 0.55, 1.6, 0.35)
            * _sstep((np.cos(phi) - 0.15) / 0.35)
        )
        return smooth, self.along_normal(feet)

    def eye_wide(self, s: float) -> tuple[F64, F64]:
        profile, up, above, _ = self.eye(s)
        dy = 0.3 * up * profile * (1.0 - _sstep(above / 1.2))
        smooth = np.stack([0.0 * dy, dy, 0.0 * dy], axis=1)
        smooth += _vec(_gauss(self.x, self.y, s * _EYE_CX, 4.1, 1.5, 0.8), 0.0, 0.15, 0.0)
        return smooth, self.zero


_JAW_SHAPES: dict[str, tuple[float, float, float]] = {
    "jawOpen": (_JAW_OPEN, 0.0, 0.0),
    "jawLeft": (0.0, _JAW_LATERAL, 0.0),
    "jawRight": (0.0, -_JAW_LATERAL, 0.0),
    "jawForward": (0.0, 0.0, _JAW_FORWARD),
}


def _expression_fields(face: _Face) -> tuple[list[str], list[tuple[F64, F64]]]:
    """Names and (smooth, wrinkle) displacement fields of the non-jaw shapes."""
    sh = _Shapes(face)
    out: list[tuple[str, tuple[F64, F64]]] = [
        ("mouthClose", sh.mouth_close()),
        ("mouthFunnel", sh.mouth_funnel()),
        ("mouthPucker", sh.mouth_pucker()),
        ("mouthLeft", sh.mouth_side(1.0)),
        ("mouthRight", sh.mouth_side(-1.0)),
        ("mouthRollLower", sh.mouth_roll(upper=False)),
        ("mouthRollUpper", sh.mouth_roll(upper=True)),
        ("mouthShrugLower", sh.mouth_shrug_lower()),
        ("mouthShrugUpper", sh.mouth_shrug_upper()),
        ("browInnerUp", sh.brow_inner_up()),
        ("cheekPuff", sh.cheek_puff()),
    ]
    sided = [
        ("mouthSmile", sh.mouth_smile),
        ("mouthFrown", sh.mouth_frown),
        ("mouthDimple", sh.mouth_dimple),
        ("mouthStretch", sh.mouth_stretch),
        ("mouthPress", sh.mouth_press),
        ("mouthLowerDown", sh.mouth_lower_down),
        ("mouthUpperUp", sh.mouth_upper_up),
        ("browDown", sh.brow_down),
        ("browOuterUp", sh.brow_outer_up),
        ("cheekSquint", sh.cheek_squint),
        ("noseSneer", sh.nose_sneer),
        ("eyeBlink", sh.eye_blink),
        ("eyeSquint", sh.eye_squint),
        ("eyeWide", sh.eye_wide),
    ]
    for base, fn in sided:
        out.append((base + "Left", fn(1.0)))
        out.append((base + "Right", fn(-1.0)))
    return [n for n, _ in out], [f for _, f in out]


# --------------------------------------------------------------------------------------------
# Markers.


def _marker_layout() -> tuple[list[str], F64]:
    """About 100 named marker positions (x, y) on the face, designed off the holes."""
    ym = _MOUTH_Y
    ex, ey, ea, eb = _EYE_CX, _EYE_CY, _EYE_A, _EYE_B
    # fmt: off
    centre: list[tuple[str, float, float]] = [
        ("foreheadC1", 0.0, 7.2), ("foreheadC2", 0.0, 6.3), ("foreheadC3", 0.0, 5.4),
        ("glabella", 0.0, 3.95), ("noseBridge", 0.0, 2.5), ("noseRidge", 0.0, 1.3),
        ("noseTip", 0.0, -0.3), ("philtrum", 0.0, ym + 0.95), ("upperLipC", 0.0, ym + 0.25),
        ("lowerLipC", 0.0, ym - 0.3), ("lowerLipBelowC", 0.0, ym - 1.0),
        ("chinTop", 0.0, -5.4), ("chinC", 0.0, -6.6), ("chinBottom", 0.0, -7.5),
    ]
    sided: list[tuple[str, float, float]] = [
        ("forehead1", 1.8, 7.2), ("forehead2", 3.6, 7.2), ("forehead3", 1.8, 6.3),
        ("forehead4", 3.6, 6.3), ("forehead5", 5.2, 6.0), ("forehead6", 1.8, 5.4),
        ("forehead7", 3.6, 5.4),
        ("brow1", 0.9, 4.2), ("brow2", 2.0, 4.35), ("brow3", 3.1, 4.45), ("brow4", 4.2, 4.35),
        ("lidUpper", ex, ey + eb + 0.35), ("lidLower", ex, ey - eb - 0.35),
        ("eyeInner", ex - ea - 0.35, ey), ("eyeOuter", ex + ea + 0.35, ey),
        ("crowsFoot1", ex + ea + 1.0, ey + 0.3), ("crowsFoot2", ex + ea + 0.9, ey - 0.6),
        ("lidLowerInner", ex - 0.8, ey - eb - 0.5), ("lidLowerOuter", ex + 0.8, ey - eb - 0.5),
        ("noseSide", 0.9, 0.8), ("nostril", 1.1, -0.9),
        ("cheek1", 2.8, 0.6), ("cheek2", 4.2, 0.8), ("cheek3", 5.6, 1.2), ("cheek4", 3.6, -0.9),
        ("cheek5", 5.0, -0.6), ("cheek6", 6.3, -0.3), ("cheek7", 3.4, -2.4),
        ("cheek8", 4.6, -2.4), ("cheek9", 5.9, -2.2),
        ("nasolabial1", 2.0, -1.9), ("nasolabial2", 2.6, -3.0),
        ("upperLip1", 0.8, ym + 0.25), ("upperLip2", 1.6, ym + 0.22),
        ("upperLipTop", 1.0, ym + 0.9),
        ("mouthCorner", 2.65, ym),
        ("lowerLip1", 0.8, ym - 0.3), ("lowerLip2", 1.6, ym - 0.28),
        ("lowerLipBelow", 1.2, ym - 1.0),
        ("chin1", 1.3, -5.6), ("chin2", 1.6, -6.9),
        ("jaw1", 3.6, -5.2), ("jaw2", 5.0, -4.4), ("jaw3", 6.3, -3.6), ("jaw4", 4.3, -6.6),
        ("jaw5", 3.0, -7.4),
    ]
    # fmt: on
    names = [n for n, _, _ in centre]
    pts = [(x, y) for _, x, y in centre]
    for name, x, y in sided:
        names += [name + "_L", name + "_R"]
        pts += [(x, y), (-x, y)]
    return names, np.array(pts, dtype=np.float64)


def _locate_2d(points: F64, positions: F64, triangles: I64) -> tuple[I64, F64]:
    """Triangle and barycentrics of each (x, y) point in the height field's xy projection.

    Returns triangle -1 for a point over a hole or outside the patch.
    """
    a = positions[triangles[:, 0], :2]
    b = positions[triangles[:, 1], :2]
    c = positions[triangles[:, 2], :2]
    e1, e2 = b - a, c - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    tri = np.full(points.shape[0], -1, dtype=np.int64)
    bary = np.zeros((points.shape[0], 3))
    for i, p in enumerate(points):
        r = p - a
        l1 = (r[:, 0] * e2[:, 1] - r[:, 1] * e2[:, 0]) / det
        l2 = (e1[:, 0] * r[:, 1] - e1[:, 1] * r[:, 0]) / det
        l0 = 1.0 - l1 - l2
        inside = np.nonzero((l0 >= 0) & (l1 >= 0) & (l2 >= 0))[0]
        if inside.size:
            t = int(inside[0])
            tri[i] = t
            bary[i] = (l0[t], l1[t], l2[t])
    return tri, bary


def _place_markers(face: _Face, rng: np.random.Generator) -> tuple[list[str], I64, F64]:
    names, pts = _marker_layout()
    jitter = np.clip(rng.normal(0.0, 0.04, pts.shape), -0.08, 0.08)
    tri, bary = _locate_2d(pts + jitter, face.positions, face.triangles)
    missing = tri < 0
    if missing.any():  # a jitter that fell off the surface: use the designed position
        tri_m, bary_m = _locate_2d(pts[missing], face.positions, face.triangles)
        tri[missing], bary[missing] = tri_m, bary_m
    if (tri < 0).any():
        raise AssertionError("marker layout has a point off the face")  # a bug, not user input
    return names, tri, bary


# --------------------------------------------------------------------------------------------
# Performance.


def _weight_curves(names: list[str], num_frames: int, rng: np.random.Generator) -> F64:
    """Smooth, sparse shape-weight curves: sums of sin^2 pulses, rest pose for 4 frames."""
    s = len(names)
    w = np.zeros((num_frames, s))
    index = {n: k for k, n in enumerate(names)}
    frames = np.arange(num_frames, dtype=np.float64)
    first = 4

    def pulse(k: int, start: float, duration: float, amp: float) -> None:
        t = (frames - start) / duration
        w[:, k] += amp * np.where((t > 0) & (t < 1), np.sin(np.pi * t) ** 2, 0.0)

    def random_start(duration: float) -> float:
        return float(rng.uniform(first, max(first, num_frames - duration)))

    # One full jaw opening (25 degrees) mid-performance, other openings at random.
    duration = min(30.0, max(num_frames - first - 1.0, 2.0))
    peak_start = min(0.6 * num_frames, num_frames - 1.0) - duration / 2.0
    pulse(index["jawOpen"], max(peak_start, float(first)), duration, 1.0)
    for _ in range(max(1, num_frames // 50)):
        d = float(rng.uniform(15, 40))
        pulse(index["jawOpen"], random_start(d), d, float(rng.uniform(0.2, 0.7)))
    for name in ("jawLeft", "jawRight", "jawForward"):
        if rng.uniform() < 0.8:
            d = float(rng.uniform(20, 45))
            pulse(index[name], random_start(d), d, float(rng.uniform(0.3, 0.8)))
    others = [k for k, n in enumerate(names) if n not in _JAW_SHAPES]
    for _ in range(max(1, num_frames // 8)):
        k = int(rng.choice(others))
        d = float(rng.uniform(15, 45))
        start = random_start(d)
        amp = float(rng.uniform(0.3, 1.0))
        pulse(k, start, d, amp)
        name = names[k]
        mirror = (
            name[:-4] + "Right"
            if name.endswith("Left")
            else name[:-5] + "Left"
            if name.endswith("Right")
            else None
        )
        if mirror is not None and mirror in index and rng.uniform() < 0.5:
            pulse(index[mirror], start + rng.uniform(-2, 2), d, amp * float(rng.uniform(0.6, 1)))
    w[:first] = 0.0
    return np.clip(w, 0.0, 1.0)


def dropout_mask(
    num_frames: int, num_markers: int, fraction: float, rng: np.random.Generator
) -> NDArray[np.bool_]:
    """(F, B) mask of lost markers, in runs of 2 to 8 frames; frame 0 is always complete."""
    mask = np.zeros((num_frames, num_markers), dtype=bool)
    target = round(fraction * num_frames * num_markers)
    if num_frames < 2 or target <= 0:
        return mask
    while int(mask.sum()) < target:
        b = int(rng.integers(num_markers))
        length = int(rng.integers(2, 9))
        start = int(rng.integers(1, num_frames))
        mask[start : start + length, b] = True
    return mask


def _truth(
    neutral: F64,
    shapes: F64,
    wrinkles: F64,
    weights: F64,
    jaw: NDArray[np.bool_],
    shape_theta: F64,
    pivot: F64,
    jaw_weights: F64,
) -> tuple[F64, F64]:
    """Ground-truth meshes (F, V, 3) and jaw parameters (F, 3); see the module documentation."""
    f, v = weights.shape[0], neutral.shape[0]
    wn = weights[:, ~jaw]
    smooth = (shapes[~jaw] - wrinkles[~jaw]).reshape(-1, v * 3)
    detail = wrinkles[~jaw].reshape(-1, v * 3)
    pre = neutral.reshape(1, -1) + wn @ smooth + (wn**_WRINKLE_POWER) @ detail
    pre = pre.reshape(f, v, 3)
    theta = weights[:, jaw] @ shape_theta[jaw]
    return JawRig(pivot, jaw_weights).skin(pre, theta), theta


# --------------------------------------------------------------------------------------------
# Public API.


def make_sample(
    seed: int = 0,
    resolution: int = 120,
    num_frames: int = 150,
    noise_mm: float = 0.2,
    dropout: float = 0.02,
) -> Sample:
    """Generate the sample deterministically from `seed`.

    `resolution` is the number of vertex rows over the 16 cm of the face (default 120: about
    12,000 vertices); `noise_mm` the standard deviation of the marker noise per coordinate in
    millimetres; `dropout` the fraction of (frame, marker) entries lost (NaN), in short runs.
    """
    resolution = _lgi.check_count(resolution, "resolution")
    if not _MIN_RESOLUTION <= resolution <= _MAX_RESOLUTION:
        raise InputError(
            f"resolution must be an integer from {_MIN_RESOLUTION} to {_MAX_RESOLUTION}, "
            f"got {resolution}"
        )
    if int(num_frames) != num_frames or num_frames < 1:
        raise InputError(f"num_frames must be a positive integer, got {num_frames}")
    if not np.isfinite(noise_mm) or noise_mm < 0:
        raise InputError(f"noise_mm must be finite and >= 0, got {noise_mm}")
    if not np.isfinite(dropout) or not 0 <= dropout < 0.5:
        raise InputError(f"dropout must be in [0, 0.5), got {dropout}")
    rng = np.random.default_rng(seed)
    face = _build_face(int(resolution))
    neutral = face.positions
    pivot = np.array(_JAW_PIVOT)
    jaw_weights = _lowerness(face, growth=1.0, rise=2.0, corner=1.6, cap=2.0)

    expr_names, fields = _expression_fields(face)
    names = list(_JAW_SHAPES) + expr_names
    s, v = len(names), neutral.shape[0]
    shapes = np.zeros((s, v, 3), dtype=np.float32)
    wrinkles = np.zeros((s, v, 3), dtype=np.float32)
    shape_theta = np.zeros((s, 3))
    rig = JawRig(pivot, jaw_weights)
    for k, params in enumerate(_JAW_SHAPES.values()):
        shape_theta[k] = params
        shapes[k] = rig.skin(neutral, shape_theta[k]) - neutral
    for k, (smooth, detail) in enumerate(fields, start=len(_JAW_SHAPES)):
        shapes[k] = smooth + detail
        wrinkles[k] = detail
    jaw = np.zeros(s, dtype=bool)
    jaw[: len(_JAW_SHAPES)] = True

    marker_names, marker_tri, marker_bary = _place_markers(face, rng)
    corners = face.triangles[marker_tri]
    markers_rest = np.einsum("bc,bcd->bd", marker_bary, neutral[corners])

    weights = _weight_curves(names, int(num_frames), rng)
    truth, theta = _truth(
        neutral,
        shapes.astype(np.float64),
        wrinkles.astype(np.float64),
        weights,
        jaw,
        shape_theta,
        pivot,
        jaw_weights,
    )
    clean = np.einsum("bc,fbcd->fbd", marker_bary, truth[:, corners])
    performance = clean + rng.normal(0.0, noise_mm / 10.0, clean.shape)
    lost = dropout_mask(int(num_frames), len(marker_names), dropout, rng)
    performance[lost] = np.nan

    uvs = np.stack(
        [
            (neutral[:, 0] + _HALF_WIDTH) / (2 * _HALF_WIDTH),
            (neutral[:, 1] + _HALF_HEIGHT) / (2 * _HALF_HEIGHT),
        ],
        axis=1,
    )
    return Sample(
        neutral=neutral,
        triangles=face.triangles,
        uvs=uvs,
        uv_triangles=face.triangles.copy(),
        shapes=shapes,
        names=names,
        markers_rest=markers_rest,
        marker_names=marker_names,
        performance=performance,
        truth=truth,
        truth_weights=weights,
        jaw_theta=theta,
        jaw_pivot=pivot,
        jaw_weights=jaw_weights,
        shape_jaw_theta=shape_theta,
        seed=int(seed),
        marker_triangles=marker_tri,
        marker_barycentrics=marker_bary,
        wrinkles=wrinkles,
    )


_ARRAY_FIELDS = (
    "neutral",
    "triangles",
    "uvs",
    "uv_triangles",
    "shapes",
    "markers_rest",
    "performance",
    "truth",
    "truth_weights",
    "jaw_theta",
    "jaw_pivot",
    "jaw_weights",
    "shape_jaw_theta",
    "marker_triangles",
    "marker_barycentrics",
    "wrinkles",
)
_FORMAT = "lgi-sample-1"


def save_sample(sample: Sample, path: str | Path) -> None:
    """Write the sample to a compressed `.npz` (no pickled objects)."""
    payload: dict[str, Any] = {name: np.asarray(getattr(sample, name)) for name in _ARRAY_FIELDS}
    payload["format"] = np.array(_FORMAT)
    payload["names"] = np.array(sample.names, dtype=np.str_)
    payload["marker_names"] = np.array(sample.marker_names, dtype=np.str_)
    payload["seed"] = np.array(sample.seed, dtype=np.int64)
    np.savez_compressed(Path(path), **payload)


def load_sample(path: str | Path) -> Sample:
    """Read a sample written by `save_sample`."""
    p = Path(path)
    try:
        z = np.load(p, allow_pickle=False)
    except FileNotFoundError as e:
        raise DatasetFileError(f"{p}: sample file not found") from e
    except (OSError, ValueError) as e:
        raise DatasetError(f"{p}: not a readable .npz sample ({e})") from e
    with z:
        wanted = (*_ARRAY_FIELDS, "format", "names", "marker_names", "seed")
        missing = [k for k in wanted if k not in z.files]
        if missing:
            raise DatasetError(f"{p}: not an lgi sample, missing {', '.join(missing)}")
        if str(z["format"]) != _FORMAT:
            raise DatasetError(f"{p}: unsupported sample format {str(z['format'])!r}")
        arrays = {name: z[name] for name in _ARRAY_FIELDS}
        return Sample(
            names=[str(n) for n in z["names"]],
            marker_names=[str(n) for n in z["marker_names"]],
            seed=int(z["seed"]),
            **arrays,
        )


def describe(sample: Sample) -> str:
    """A short multi-line summary of the sample."""
    lo, hi = sample.neutral.min(axis=0), sample.neutral.max(axis=0)
    size = hi - lo
    lost = np.isnan(sample.performance).any(axis=2)
    open_deg = np.rad2deg(sample.jaw_theta[:, 0].max()) if sample.num_frames else 0.0
    return "\n".join(
        [
            f"lgi sample (seed {sample.seed})",
            f"  vertices   {sample.num_vertices}",
            f"  triangles  {sample.triangles.shape[0]}",
            f"  shapes     {sample.num_shapes}",
            f"  markers    {sample.num_markers}",
            f"  frames     {sample.num_frames} (jaw opens up to {open_deg:.1f} deg)",
            f"  dropouts   {int(lost.sum())} of {lost.size} marker samples "
            f"({100.0 * lost.mean():.1f}%)"
            if lost.size
            else "  dropouts   0",
            f"  size       {size[0]:.1f} x {size[1]:.1f} x {size[2]:.1f} cm (w x h x d)",
        ]
    )
