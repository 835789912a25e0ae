"""The sample's face (`lgi.lab.sample`): a synthetic neutral and its expression shapes, made
from formulas alone. The neutral is a height field over a grid patch with holes (the mouth
slit, the eyes); each expression shape is a smooth displacement plus its "wrinkle" part, fine
folds that only expressions have; the jaw shapes are rotations about `JAW_PIVOT`.

Conventions: centimetres, +y up, +z forward (like ICT). "Left" is the character's left, +x.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

__all__ = [
    "EYE_A",
    "EYE_B",
    "EYE_CX",
    "EYE_CY",
    "HALF_HEIGHT",
    "HALF_WIDTH",
    "JAW_PIVOT",
    "JAW_SHAPES",
    "MOUTH_Y",
    "Face",
    "build_face",
    "expression_fields",
    "lowerness",
]


# Face layout (cm). The patch spans x in [-7, 7] and y in [-8, 8].
HALF_WIDTH = 7.0
HALF_HEIGHT = 8.0
MOUTH_Y = -3.4  # snapped to the nearest grid row
_MOUTH_HALF_WIDTH = 2.4  # snapped to a grid column
_MOUTH_HALF_GAP = 0.03  # lips are 0.6 mm apart at the centre of the neutral
EYE_CX = 3.1
EYE_CY = 2.6
EYE_A = 1.35
EYE_B = 0.55
JAW_PIVOT = (0.0, -1.5, 3.0)
_JAW_OPEN = np.deg2rad(25.0)
_JAW_LATERAL = 0.12  # rad; the chin moves about 7 mm sideways
_JAW_FORWARD = 0.6  # cm


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
    ym = MOUTH_Y
    lip_w = np.exp(-((x / 2.0) ** 4))
    ax = np.abs(x)
    z = (
        z
        + 0.45 * _gauss(ax, y, 1.0, -0.95, 0.42, 0.38)  # nose alae
        + 0.4 * np.exp(-(((y - 4.15 - 0.03 * x * x) / 0.45) ** 2)) * _window(ax, 0.5, 5.3, 0.6)
        + 0.15 * _gauss(x, y, 0.0, 4.0, 0.8, 0.8)  # glabella
        - 0.9 * _gauss(ax, y, EYE_CX, EYE_CY, 1.5, 0.95)  # eye sockets
        + 0.35 * _gauss(ax, y, EYE_CX, EYE_CY, 1.0, 0.6)  # eyeballs under the lids
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
class Face:
    """The neutral's mesh and where its mouth slit lies."""

    positions: F64
    triangles: I64
    slit_side: NDArray[np.int8]  # +1 upper lip on the slit, -1 its lower-lip duplicate, else 0
    mouth_y: float
    mouth_half_width: float


def build_face(resolution: int) -> Face:
    """Grid of quads over the patch, eye quads removed, mouth row cut open."""
    ny = resolution
    step = 2.0 * HALF_HEIGHT / (ny - 1)
    half = round(HALF_WIDTH / step)
    nx = 2 * half + 1  # odd, so that x = 0 is a column and the mesh is mirror symmetric
    xs = (np.arange(nx) - half) * (HALF_WIDTH / half)
    ys = -HALF_HEIGHT + np.arange(ny) * step
    jm = round((MOUTH_Y + HALF_HEIGHT) / step)
    k = max(round(_MOUTH_HALF_WIDTH / (HALF_WIDTH / half)), 2)
    mouth_y = float(ys[jm])
    mouth_hw = float(xs[half + k])

    gx, gy = np.meshgrid(xs, ys)  # (ny, nx)
    gid = np.arange(nx * ny, dtype=np.int64).reshape(ny, nx)
    slit_cols = np.arange(half - k + 1, half + k)  # interior of the cut, corners excluded
    lower = gid.copy()
    lower[jm, slit_cols] = nx * ny + np.arange(slit_cols.size)

    def inside_eye(px: F64, py: F64) -> NDArray[np.bool_]:
        return (((np.abs(px) - EYE_CX) / EYE_A) ** 2 + ((py - EYE_CY) / EYE_B) ** 2) < 1.0

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
    return Face(positions, remap[tris], side, mouth_y, mouth_hw)


def lowerness(face: Face, growth: float, rise: float, corner: float, cap: float) -> F64:
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
    line = face.mouth_y + rise * _sstep((ax - hw) / (HALF_WIDTH - hw))
    yy = np.where(face.slit_side > 0, face.mouth_y + band, y)
    yy = np.where(face.slit_side < 0, face.mouth_y - band, yy)
    sharp = _sstep(0.5 - (yy - line) / (2.0 * band))
    r = np.hypot(ax - hw, y - face.mouth_y)
    return 0.5 + (sharp - 0.5) * _sstep(r / corner)


# --------------------------------------------------------------------------------------------
# Expression shapes: each is a smooth part plus a "wrinkle" part (folds that only expressions
# have); both are (V, 3) float64 displacements.


class _Shapes:
    def __init__(self, face: Face) -> None:
        p = face.positions
        self.x, self.y = p[:, 0], p[:, 1]
        self.n = _normals(self.x, self.y)
        self.ym = face.mouth_y
        self.hw = face.mouth_half_width
        self.lower = lowerness(face, growth=0.45, rise=0.0, corner=1.2, cap=3.0)
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
        u = (self.x - s * EYE_CX) / EYE_A
        opening = EYE_B * np.sqrt(np.maximum(1.0 - u * u, 0.0))
        profile = np.maximum(1.0 - u * u, 0.0) ** 0.75
        upper = _sstep((self.y - EYE_CY) / 0.3 + 0.5)
        return profile, upper, self.y - (EYE_CY + opening), (EYE_CY - opening) - self.y

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
        rr = np.hypot((x - s * EYE_CX) / 1.6, (y - EYE_CY) / 0.95)
        fold = -0.07 * np.exp(-(((rr - 1.0) / 0.12) ** 2)) * _sstep((EYE_CY - y) / 0.3)
        return smooth, self.along_normal(fold)

    def nose_sneer(self, s: float) -> tuple[F64, F64]:
        x, y = self.x, self.y
        smooth = _vec(_gauss(x, y, s * 1.05, -0.9, 0.6, 0.6), s * 0.05, 0.35, 0.05)
        smooth += _vec(_gauss(x, y, s * 0.7, 1.0, 0.6, 0.9), 0.0, 0.2, 0.0)
        smooth += _vec(_gauss(x, y, s * 0.9, self.ym + 0.6, 0.7, 0.5) * self.upper, 0, 0.15, 0)
        bunny = 0.065 * np.cos(2 * np.pi * (y + 0.6 * s * x) / 0.42)
        bunny = bunny * _gauss(x, y, s * 0.75, 1.7, 0.45, 0.55)
        # Fine folds fanning from the inner corner of the eye, like crow's feet mirrored.
        cx, cy = s * (EYE_CX - EYE_A - 0.1), EYE_CY
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
        dy = -1.75 * EYE_B * upper + 0.1 * lower
        dz = 0.12 * upper
        return np.stack([0.0 * dy, dy, dz], axis=1), self.zero

    def eye_squint(self, s: float) -> tuple[F64, F64]:
        x, y = self.x, self.y
        profile, up, above, below = self.eye(s)
        dy = -0.15 * up * profile * (1.0 - _sstep(above / 1.2))
        dy += 0.3 * (1.0 - up) * profile * (1.0 - _sstep(below / 1.0))
        smooth = np.stack([0.0 * dy, dy, 0.0 * dy], axis=1)
        cx, cy = s * (EYE_CX + EYE_A + 0.15), EYE_CY
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
        smooth += _vec(_gauss(self.x, self.y, s * EYE_CX, 4.1, 1.5, 0.8), 0.0, 0.15, 0.0)
        return smooth, self.zero


JAW_SHAPES: dict[str, tuple[float, float, float]] = {
    "jawOpen": (_JAW_OPEN, 0.0, 0.0),
    "jawLeft": (0.0, _JAW_LATERAL, 0.0),
    "jawRight": (0.0, -_JAW_LATERAL, 0.0),
    "jawForward": (0.0, 0.0, _JAW_FORWARD),
}


def expression_fields(face: Face) -> tuple[list[str], list[tuple[F64, F64]]]:
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
