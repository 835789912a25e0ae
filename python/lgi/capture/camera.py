"""Cameras with OpenCV's conventions and triangulation of 2D marker tracks into 3D bundles.

`FisheyeCamera` is `cv2.fisheye`'s Kannala-Brandt model and `PinholeCamera` `cv2.projectPoints`'s
radial-tangential model; both map world points with `x_cam = R X + t` (R, t world to camera, as
OpenCV's rvec/tvec), so calibrations from OpenCV drop in. Everything is vectorised numpy; OpenCV
itself is only the tests' reference. Un-projection inverts the distortion by Newton's method to
machine precision (OpenCV's fixed-count iteration is weak near the image border).
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi.errors import InputError

F64 = NDArray[np.float64]

__all__ = [
    "Camera",
    "FisheyeCamera",
    "PinholeCamera",
    "Rays",
    "Triangulation",
    "load_cameras",
    "rodrigues",
    "save_cameras",
    "triangulate",
]

_NEWTON_STEPS = 50
_NEWTON_TOL = 1e-15
# A ray is accepted when its re-distortion matches the input to this (normalised units).
_INVERSE_TOL = 1e-10


def rodrigues(rvec: ArrayLike) -> F64:
    """The rotation matrix of a rotation vector (axis times angle, OpenCV's `rvec`)."""
    r = np.asarray(rvec, dtype=np.float64).reshape(3)
    angle = float(np.linalg.norm(r))
    if angle < 1e-300:
        return np.eye(3)
    k = r / angle
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * (kx @ kx)


def _matrix(value: ArrayLike, shape: tuple[int, ...], what: str) -> F64:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InputError(f"{what}: not a numeric array ({e})") from None
    if a.size != int(np.prod(shape)):
        raise InputError(f"{what}: expected {shape}, got shape {a.shape}")
    a = a.reshape(shape)
    if not np.all(np.isfinite(a)):
        raise InputError(f"{what}: contains NaN or infinity")
    return a


def _points(x: ArrayLike, dim: int, what: str) -> tuple[F64, tuple[int, ...]]:
    """(N, dim) float64 view of `x` (..., dim) and the leading shape to restore."""
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InputError(f"{what}: not a numeric array ({e})") from None
    if a.ndim < 1 or a.shape[-1] != dim:
        raise InputError(f"{what}: expected shape (..., {dim}), got {a.shape}")
    if np.isinf(a).any():
        raise InputError(f"{what}: contains infinity (NaN marks a missing point)")
    return a.reshape(-1, dim), a.shape[:-1]


@dataclass(frozen=True)
class Rays:
    """Rays in world space: `origins + s * directions`, s >= 0; NaN rows where no ray exists."""

    origins: F64
    """(..., 3) the camera centre for each ray."""
    directions: F64
    """(..., 3) unit directions."""


class Camera:
    """A calibrated camera: intrinsics K (3x3), distortion D, pose `x_cam = R X + t`, and the
    image size (width, height) in pixels. Subclasses define the distortion model."""

    model: ClassVar[str] = ""
    _num_coefficients: ClassVar[tuple[int, ...]] = ()

    def __init__(
        self,
        K: ArrayLike,
        D: ArrayLike,
        R: ArrayLike | None = None,
        t: ArrayLike | None = None,
        image_size: Sequence[int] = (1920, 1080),
    ) -> None:
        k = _matrix(K, (3, 3), "K")
        if k[0, 0] <= 0 or k[1, 1] <= 0:
            raise InputError(f"K: focal lengths must be > 0, got fx={k[0, 0]}, fy={k[1, 1]}")
        if k[1, 0] != 0 or k[2, 0] != 0 or k[2, 1] != 0 or k[2, 2] != 1:
            raise InputError("K: expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]]")
        try:
            d = np.asarray(D, dtype=np.float64).ravel()
        except (TypeError, ValueError) as e:
            raise InputError(f"D: not a numeric array ({e})") from None
        if d.size not in self._num_coefficients:
            raise InputError(
                f"D: the {self.model} model takes {' or '.join(map(str, self._num_coefficients))}"
                f" coefficients, got {d.size}"
            )
        if not np.all(np.isfinite(d)):
            raise InputError("D: contains NaN or infinity")
        r = np.eye(3) if R is None else np.asarray(R, dtype=np.float64)
        if r.size == 3:
            r = rodrigues(_matrix(r, (3,), "R (rotation vector)"))
        r = _matrix(r, (3, 3), "R")
        if np.abs(r @ r.T - np.eye(3)).max() > 1e-6 or np.linalg.det(r) < 0:
            raise InputError("R: not a rotation matrix (orthonormal, determinant +1)")
        tt = np.zeros(3) if t is None else _matrix(t, (3,), "t")
        try:
            size = tuple(int(v) for v in image_size)
        except (TypeError, ValueError):
            raise InputError(f"image_size: expected (width, height), got {image_size!r}") from None
        if (
            len(size) != 2
            or min(size) <= 0
            or any(v != s for v, s in zip(size, image_size, strict=False))
        ):
            raise InputError(f"image_size: expected (width, height) > 0, got {image_size!r}")
        self.K, self.D, self.R, self.t = k, self._coefficients(d), r, tt
        self.image_size: tuple[int, int] = (size[0], size[1])
        for a in (self.K, self.D, self.R, self.t):
            a.setflags(write=False)

    def _coefficients(self, d: F64) -> F64:
        return d.copy()

    # The distortion model, in normalised coordinates (subclasses).
    def _distort(self, xy: F64) -> tuple[F64, F64]:
        """Distorted normalised points (N, 2) and d(distorted)/d(xy) (N, 2, 2) of the ideal
        normalised points xy = (X/Z, Y/Z)."""
        raise NotImplementedError

    def _undistort_direction(self, xd: F64) -> F64:
        """(N, 3) unit camera-space directions of distorted normalised points; NaN rows where
        the model has no inverse."""
        raise NotImplementedError

    @property
    def center(self) -> F64:
        """(3,) the camera centre in world coordinates, `-R^T t`."""
        return -self.R.T @ self.t

    def __repr__(self) -> str:
        fx, fy = self.K[0, 0], self.K[1, 1]
        return (
            f"{type(self).__name__}(f=({fx:.6g}, {fy:.6g}), D={np.round(self.D, 6).tolist()}, "
            f"center={np.round(self.center, 6).tolist()}, image_size={self.image_size})"
        )

    def _pixels(self, xd: F64) -> F64:
        k = self.K
        u = k[0, 0] * xd[:, 0] + k[0, 1] * xd[:, 1] + k[0, 2]
        v = k[1, 1] * xd[:, 1] + k[1, 2]
        return np.stack([u, v], axis=1)

    def _from_pixels(self, uv: F64) -> F64:
        k = self.K
        y = (uv[:, 1] - k[1, 2]) / k[1, 1]
        x = (uv[:, 0] - k[0, 2] - k[0, 1] * y) / k[0, 0]
        return np.stack([x, y], axis=1)

    def project_with_jacobian(self, points: ArrayLike) -> tuple[F64, F64]:
        """Pixels (N, 2) of world points (N, 3) and d(pixel)/d(point) (N, 2, 3). Points on or
        behind the camera plane (z <= 0 in camera space) and NaN points give NaN."""
        x, _ = _points(points, 3, "points")
        y = x @ self.R.T + self.t
        z = y[:, 2]
        front = z > 0
        zs = np.where(front, z, np.nan)
        xy = y[:, :2] / zs[:, None]
        xd, jd = self._distort(xy)
        uv = self._pixels(xd)
        # d(xy)/d(y_cam) then d(y_cam)/dX = R; pixels: the K rows.
        jn = np.zeros((x.shape[0], 2, 3))
        jn[:, 0, 0] = 1 / zs
        jn[:, 1, 1] = 1 / zs
        jn[:, :, 2] = -xy / zs[:, None]
        kk = self.K[:2, :2]
        jac = np.einsum("ij,njk,nkl,lm->nim", kk, jd, jn, self.R, optimize=True)
        return uv, jac

    def project(self, points: ArrayLike) -> F64:
        """Pixels (..., 2) of world points (..., 3), as OpenCV projects them; NaN for points on
        or behind the camera plane and for NaN points."""
        x, lead = _points(points, 3, "points")
        return self.project_with_jacobian(x)[0].reshape(*lead, 2)

    def normalized(self, uv: ArrayLike) -> F64:
        """Undistorted normalised coordinates (X/Z, Y/Z) (..., 2) of pixels (..., 2): what
        `cv2.undistortPoints` / `cv2.fisheye.undistortPoints` return without R and P."""
        d = self.camera_directions(uv)
        return d[..., :2] / d[..., 2:3]

    def camera_directions(self, uv: ArrayLike) -> F64:
        """Unit ray directions in camera space (..., 3) of pixels (..., 2); NaN where the
        pixel has no ray (NaN input, or outside the range where the distortion is invertible)."""
        p, lead = _points(uv, 2, "uv")
        return self._undistort_direction(self._from_pixels(p)).reshape(*lead, 3)

    def unproject(self, uv: ArrayLike) -> Rays:
        """World-space rays (origins at the camera centre, unit directions) of pixels (..., 2)."""
        d = self.camera_directions(uv)
        world = d @ self.R  # R^T d, row-wise
        origins = np.broadcast_to(self.center, world.shape).copy()
        origins[np.isnan(world).any(axis=-1)] = np.nan
        return Rays(origins=origins, directions=world)

    def in_image(self, uv: ArrayLike) -> NDArray[np.bool_]:
        """(...,) True where pixels lie inside the image (pixel centres 0..w-1, 0..h-1 span
        [-0.5, w - 0.5))."""
        p = np.asarray(uv, dtype=np.float64)
        w, h = self.image_size
        with np.errstate(invalid="ignore"):
            return (
                (p[..., 0] >= -0.5)
                & (p[..., 0] < w - 0.5)
                & (p[..., 1] >= -0.5)
                & (p[..., 1] < h - 0.5)
            )

    def to_dict(self) -> dict[str, Any]:
        """Plain values: model, K, D, R, t, image_size (what the calibration files hold)."""
        return {
            "model": self.model,
            "K": self.K.tolist(),
            "D": self.D.tolist(),
            "R": self.R.tolist(),
            "t": self.t.tolist(),
            "image_size": list(self.image_size),
        }

    @staticmethod
    def from_dict(d: dict[str, Any]) -> Camera:
        """The camera `to_dict` described (`model` picks the class)."""
        cls = _MODELS.get(str(d.get("model")))
        if cls is None:
            raise InputError(
                f"camera model must be one of {sorted(_MODELS)}, got {d.get('model')!r}"
            )
        missing = [k for k in ("K", "D", "image_size") if k not in d]
        if missing:
            raise InputError(f"camera: missing {', '.join(missing)}")
        return cls(d["K"], d["D"], d.get("R"), d.get("t"), d["image_size"])


class FisheyeCamera(Camera):
    """OpenCV's `cv2.fisheye` model (Kannala-Brandt): with θ = atan(r), r = |(X/Z, Y/Z)|,
    θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸), the distorted point is (θ_d / r)(X/Z, Y/Z);
    pixels u = fx (x_d + alpha y_d) + cx, v = fy y_d + cy with the skew alpha = K[0, 1] / fx (OpenCV
    `alpha`, as `cv2.fisheye.calibrate` writes it into K). D = (k1, k2, k3, k4)."""

    model = "fisheye"
    _num_coefficients = (4,)

    @property
    def alpha(self) -> float:
        """The skew coefficient in OpenCV's `cv2.fisheye` sense (K[0, 1] / fx)."""
        return float(self.K[0, 1] / self.K[0, 0])

    def _theta_d(self, theta: F64) -> tuple[F64, F64]:
        k1, k2, k3, k4 = self.D
        t2 = theta * theta
        poly = 1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))
        dpoly = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
        return theta * poly, dpoly

    def _distort(self, xy: F64) -> tuple[F64, F64]:
        r = np.hypot(xy[:, 0], xy[:, 1])
        theta = np.arctan(r)
        td, dtd = self._theta_d(theta)
        small = r <= 1e-8  # OpenCV's own cut-off: the identity near the axis
        rs = np.where(small, 1.0, r)
        s = np.where(small, 1.0, td / rs)
        # ds/dr = (θ_d'(θ) θ'(r) - s) / r, and dr/dxy = xy / r.
        ds = np.where(small, 0.0, (dtd / (1 + r * r) - s) / rs)
        unit = xy / rs[:, None]
        jac = s[:, None, None] * np.eye(2)[None] + (xy * ds[:, None])[:, :, None] * unit[:, None, :]
        return xy * s[:, None], jac

    def _undistort_direction(self, xd: F64) -> F64:
        td = np.hypot(xd[:, 0], xd[:, 1])
        theta = td.copy()
        with np.errstate(invalid="ignore", over="ignore"):
            for _ in range(_NEWTON_STEPS):
                f, df = self._theta_d(theta)
                step = (f - td) / df
                theta = theta - step
                if not np.any(np.abs(step) > _NEWTON_TOL):
                    break
            f, df = self._theta_d(theta)
            ok = (np.abs(f - td) <= _INVERSE_TOL * np.maximum(1, td)) & (df > 0)
            ok &= (theta >= 0) & (theta < np.pi / 2)
        small = td <= 1e-12
        unit = xd / np.where(small, 1.0, td)[:, None]
        d = np.concatenate([np.sin(theta)[:, None] * unit, np.cos(theta)[:, None]], axis=1)
        d[small] = np.concatenate([xd[small], np.ones((int(small.sum()), 1))], axis=1)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        d[~(ok | small)] = np.nan
        return d


class PinholeCamera(Camera):
    """OpenCV's `cv2.projectPoints` model with radial-tangential distortion, D = (k1, k2, p1,
    p2[, k3]) (4 coefficients mean k3 = 0): with (x, y) = (X/Z, Y/Z), r² = x² + y²,
    x_d = x (1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2 x²),
    y_d = y (1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2 y²) + 2 p2 x y; u = fx x_d + cx,
    v = fy y_d + cy. K's skew must be 0 (OpenCV's pinhole projection has none)."""

    model = "pinhole"
    _num_coefficients = (4, 5)

    def __init__(
        self,
        K: ArrayLike,
        D: ArrayLike,
        R: ArrayLike | None = None,
        t: ArrayLike | None = None,
        image_size: Sequence[int] = (1920, 1080),
    ) -> None:
        super().__init__(K, D, R, t, image_size)
        if self.K[0, 1] != 0:
            raise InputError("K: the pinhole model has no skew; K[0, 1] must be 0")

    def _coefficients(self, d: F64) -> F64:
        return np.concatenate([d, np.zeros(5 - d.size)])

    def _distort(self, xy: F64) -> tuple[F64, F64]:
        k1, k2, p1, p2, k3 = self.D
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        drad = k1 + r2 * (2 * k2 + 3 * k3 * r2)  # d(radial)/d(r2)
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        jac = np.empty((xy.shape[0], 2, 2))
        jac[:, 0, 0] = radial + 2 * x * x * drad + 2 * p1 * y + 6 * p2 * x
        jac[:, 0, 1] = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y
        jac[:, 1, 0] = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y
        jac[:, 1, 1] = radial + 2 * y * y * drad + 6 * p1 * y + 2 * p2 * x
        return np.stack([xd, yd], axis=1), jac

    def _undistort_direction(self, xd: F64) -> F64:
        xy = xd.copy()
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            for _ in range(_NEWTON_STEPS):
                f, jac = self._distort(xy)
                step = np.linalg.solve(jac, (f - xd)[:, :, None])[:, :, 0]
                step[~np.isfinite(step)] = np.nan
                xy = xy - step
                if not np.any(np.abs(step) > _NEWTON_TOL * np.maximum(1, np.abs(xy))):
                    break
            f, jac = self._distort(xy)
            err = np.abs(f - xd).max(axis=1)
            ok = (err <= _INVERSE_TOL * np.maximum(1, np.abs(xd).max(axis=1))) & (
                np.linalg.det(jac) > 0
            )
        d = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        d[~ok] = np.nan
        return d


_MODELS: dict[str, type[Camera]] = {"fisheye": FisheyeCamera, "pinhole": PinholeCamera}


# ---------------------------------------------------------------------------------------------
# Calibration files: OpenCV FileStorage's YAML and JSON layouts, one camera per key prefix
# `cam<i>_`, so `cv2.FileStorage` reads what we write and we read what it writes.

_MATRICES = ("K", "D", "R", "t")


def _storage_values(cameras: Sequence[Camera]) -> dict[str, Any]:
    out: dict[str, Any] = {"camera_count": len(cameras)}
    for i, cam in enumerate(cameras):
        out[f"cam{i}_model"] = cam.model
        out[f"cam{i}_image_width"] = cam.image_size[0]
        out[f"cam{i}_image_height"] = cam.image_size[1]
        for name in _MATRICES:
            a = getattr(cam, name)
            out[f"cam{i}_{name}"] = a if a.ndim == 2 else a.reshape(-1, 1)
    return out


def _cameras_from_values(values: dict[str, Any], where: str) -> list[Camera]:
    try:
        count = int(values["camera_count"])
    except (KeyError, TypeError, ValueError):
        raise InputError(f"{where}: no integer camera_count") from None
    cams = []
    for i in range(count):
        p = f"cam{i}_"
        need = [p + k for k in ("model", "image_width", "image_height", *_MATRICES)]
        missing = [k for k in need if k not in values]
        if missing:
            raise InputError(f"{where}: camera {i}: missing {', '.join(missing)}")
        d = {k: values[p + k] for k in ("model", *_MATRICES)}
        d["image_size"] = (values[p + "image_width"], values[p + "image_height"])
        try:
            cams.append(Camera.from_dict(d))
        except InputError as e:
            raise InputError(f"{where}: camera {i}: {e}") from None
    return cams


def _yaml_scalar(v: Any) -> str:
    if isinstance(v, str):
        return v
    return repr(int(v)) if isinstance(v, (int, np.integer)) else repr(float(v))


def _write_yaml(values: dict[str, Any]) -> str:
    lines = ["%YAML:1.0", "---"]
    for k, v in values.items():
        if isinstance(v, np.ndarray):
            data = ", ".join(repr(float(x)) for x in v.ravel())
            lines += [
                f"{k}: !!opencv-matrix",
                f"   rows: {v.shape[0]}",
                f"   cols: {v.shape[1]}",
                "   dt: d",
                f"   data: [ {data} ]",
            ]
        else:
            lines.append(f"{k}: {_yaml_scalar(v)}")
    return "\n".join(lines) + "\n"


def _parse_scalar(text: str) -> Any:
    s = text.strip()
    if len(s) >= 2 and s[0] == s[-1] and s[0] in "\"'":
        return s[1:-1]
    for conv in (int, float):
        try:
            return conv(s)
        except ValueError:
            pass
    return s


def _read_yaml(text: str, where: str) -> dict[str, Any]:
    """The flat subset of OpenCV FileStorage YAML that calibrations use: `key: scalar` and
    `key: !!opencv-matrix` blocks (rows, cols, dt, data: [...] over one or more lines)."""
    values: dict[str, Any] = {}
    lines = text.splitlines()
    i = 0
    key_re = re.compile(r"^([A-Za-z_][\w]*)\s*:\s*(.*)$")
    while i < len(lines):
        raw = lines[i].split("#", 1)[0].rstrip()
        i += 1
        if not raw.strip() or raw.startswith("%YAML") or raw.strip() == "---":
            continue
        m = key_re.match(raw)
        if m is None or raw[0].isspace():
            raise InputError(f"{where}, line {i}: expected 'key: value', got {raw.strip()!r}")
        key, rest = m.group(1), m.group(2).strip()
        if rest != "!!opencv-matrix":
            values[key] = _parse_scalar(rest)
            continue
        start = i
        block: dict[str, str] = {}
        while i < len(lines) and (lines[i].startswith(" ") or not lines[i].strip()):
            sub = lines[i].strip()
            i += 1
            if not sub:
                continue
            m2 = key_re.match(sub)
            if m2 is None:
                raise InputError(f"{where}, line {i}: cannot read {sub!r} in matrix {key}")
            name, val = m2.group(1), m2.group(2)
            if name == "data":
                while "]" not in val and i < len(lines):
                    val += " " + lines[i].strip()
                    i += 1
            block[name] = val
        values[key] = _matrix_from_block(block, f"{where}, line {start}: matrix {key}")
    return values


def _matrix_from_block(block: dict[str, Any], where: str) -> F64:
    try:
        rows, cols = int(block["rows"]), int(block["cols"])
        data = block["data"]
        if isinstance(data, str):
            data = [float(x) for x in data.strip().strip("[]").split(",") if x.strip()]
        a = np.asarray(data, dtype=np.float64)
    except (KeyError, TypeError, ValueError) as e:
        raise InputError(f"{where}: needs rows, cols and numeric data ({e})") from None
    if a.size != rows * cols:
        raise InputError(f"{where}: {rows}x{cols} needs {rows * cols} values, got {a.size}")
    return a.reshape(rows, cols)


def save_cameras(path: str | os.PathLike[str], cameras: Sequence[Camera]) -> None:
    """Writes a calibration (one or more cameras) as OpenCV FileStorage YAML (`.yaml`, `.yml`)
    or JSON (`.json`): keys `camera_count` and per camera `cam<i>_model`, `cam<i>_K`,
    `cam<i>_D`, `cam<i>_R`, `cam<i>_t` (matrices), `cam<i>_image_width`, `cam<i>_image_height`."""
    p = Path(path)
    if not cameras or not all(isinstance(c, Camera) for c in cameras):
        raise InputError("cameras: expected a non-empty sequence of lgi.camera cameras")
    values = _storage_values(cameras)
    suffix = p.suffix.lower()
    if suffix in (".yaml", ".yml"):
        p.write_text(_write_yaml(values))
    elif suffix == ".json":
        out = {
            k: (
                {
                    "type_id": "opencv-matrix",
                    "rows": v.shape[0],
                    "cols": v.shape[1],
                    "dt": "d",
                    "data": v.ravel().tolist(),
                }
                if isinstance(v, np.ndarray)
                else v
            )
            for k, v in values.items()
        }
        p.write_text(json.dumps(out, indent=4) + "\n")
    else:
        raise InputError(f"{p}: calibration files are .yaml, .yml or .json")


def load_cameras(path: str | os.PathLike[str]) -> list[Camera]:
    """Reads what `save_cameras` (or `cv2.FileStorage` with the same keys) wrote."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as e:
        raise InputError(f"{p}: cannot read the calibration ({e.strerror})") from None
    suffix = p.suffix.lower()
    if suffix in (".yaml", ".yml"):
        values = _read_yaml(text, str(p))
    elif suffix == ".json":
        try:
            raw = json.loads(text)
        except json.JSONDecodeError as e:
            raise InputError(f"{p}, line {e.lineno}: not JSON ({e.msg})") from None
        if not isinstance(raw, dict):
            raise InputError(f"{p}: expected a JSON object at the top")
        values = {
            k: _matrix_from_block(v, f"{p}: {k}") if isinstance(v, dict) else v
            for k, v in raw.items()
        }
    else:
        raise InputError(f"{p}: calibration files are .yaml, .yml or .json")
    return _cameras_from_values(values, str(p))


# ---------------------------------------------------------------------------------------------
# Triangulation


@dataclass(frozen=True)
class Triangulation:
    """Bundles triangulated from 2D tracks, with what each one rests on."""

    points: F64
    """(F, B, 3) world points; NaN where fewer than two cameras saw the marker or it was
    rejected."""
    reprojection_error: F64
    """(F, B) RMS reprojection error over the views used (pixels); NaN where no point."""
    residuals: F64
    """(F, B, C) per-camera reprojection error (pixels) of the point; NaN where unseen."""
    views: NDArray[np.int64]
    """(F, B) how many cameras saw the marker."""
    rejected: NDArray[np.bool_]
    """(F, B) seen by two or more cameras but rejected (reprojection error above the limit)."""
    rays: Rays
    """(F, B, 3) the ray of each marker seen by exactly one camera; NaN elsewhere."""

    @property
    def missing(self) -> NDArray[np.bool_]:
        """(F, B) markers with no point (NaN in `points`)."""
        return np.isnan(self.points[..., 0])

    @property
    def failed(self) -> NDArray[np.bool_]:
        """(F, B) seen by two or more cameras, not rejected, yet without a point (parallel
        rays, or a solution behind a camera)."""
        return self.missing & (self.views >= 2) & ~self.rejected

    def summary(self) -> str:
        """One line: how many samples were triangulated, single-view, unseen, rejected or
        failed."""
        n = self.views.size
        ok = ~self.missing
        err = self.reprojection_error[ok]
        med = f"{np.median(err):.3g}" if err.size else "n/a"
        failed = int(self.failed.sum())
        return (
            f"{int(ok.sum())}/{n} marker samples triangulated (median reprojection error "
            f"{med} px); {int((self.views == 1).sum())} seen by one camera (rays), "
            f"{int((self.views == 0).sum())} unseen, {int(self.rejected.sum())} rejected"
            + (f", {failed} failed (parallel rays or behind a camera)" if failed else "")
        )


def triangulate(
    cameras: Sequence[Camera],
    uv: ArrayLike,
    *,
    max_error: float | None = None,
    iterations: int = 20,
) -> Triangulation:
    """Triangulates 2D tracks uv (F, B, C, 2) in pixels (NaN where camera c does not see
    marker b in frame f): a linear (DLT) initialisation from the undistorted rays, then
    Gauss-Newton on the reprojection error in pixels. Markers seen by fewer than two cameras
    get no point (NaN) and are reported (`views`, and `rays` for single-view markers).

    `max_error` (pixels): a marker whose RMS reprojection error exceeds it is rejected (a
    mistracked sample); with three or more views its worst view is dropped first and the
    marker kept when the rest agree."""
    cams = list(cameras)
    if not cams or not all(isinstance(c, Camera) for c in cams):
        raise InputError("cameras: expected a non-empty sequence of lgi.camera cameras")
    try:
        a = np.asarray(uv, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InputError(f"uv: not a numeric array ({e})") from None
    if a.ndim != 4 or a.shape[2] != len(cams) or a.shape[3] != 2:
        raise InputError(f"uv: expected shape (F, B, {len(cams)}, 2), got {a.shape}")
    if np.isinf(a).any():
        raise InputError("uv: contains infinity (NaN marks an unseen marker)")
    if max_error is not None and not (np.isfinite(max_error) and max_error > 0):
        raise InputError(f"max_error must be > 0 pixels, got {max_error}")
    nf, nb, nc, _ = a.shape
    flat = a.reshape(nf * nb, nc, 2)
    seen: NDArray[np.bool_] = np.asarray(~np.isnan(flat).any(axis=2))  # (P, C)
    dirs = np.stack([c.camera_directions(flat[:, i]) for i, c in enumerate(cams)], axis=1)
    seen &= ~np.isnan(dirs).any(axis=2)  # a pixel with no ray is not a view
    views = seen.sum(axis=1)

    points, res = _solve_points(cams, flat, dirs, seen, iterations)
    rejected = np.zeros(points.shape[0], dtype=bool)
    if max_error is not None:
        rms = _rms(res, seen)
        bad = (rms > max_error) & (views >= 2)
        retry = bad & (views >= 3)
        if retry.any():
            worst = np.argmax(np.where(seen[retry], res[retry], -1.0), axis=1)
            seen_r = seen[retry].copy()
            seen_r[np.arange(seen_r.shape[0]), worst] = False
            p2, r2 = _solve_points(cams, flat[retry], dirs[retry], seen_r, iterations)
            keep = _rms(r2, seen_r) <= max_error
            idx = np.flatnonzero(retry)[keep]
            points[idx], res[idx] = p2[keep], r2[keep]
            seen[idx] = seen_r[keep]
            bad[idx] = False
        rejected = bad
        points[bad] = np.nan
    res = np.where(seen, res, np.nan)
    valid = (seen.sum(axis=1) >= 2) & ~rejected & np.isfinite(points).all(axis=1)
    points[~valid] = np.nan
    rms = np.where(valid, _rms(np.nan_to_num(res), seen), np.nan)

    # Single-view markers: their ray (the paper's §7.4 post-process constraint).
    single = views == 1
    origins = np.full((flat.shape[0], 3), np.nan)
    directions = np.full((flat.shape[0], 3), np.nan)
    for i, c in enumerate(cams):
        m = single & seen[:, i]
        if m.any():
            origins[m] = c.center
            directions[m] = dirs[m, i] @ c.R
    return Triangulation(
        points=points.reshape(nf, nb, 3),
        reprojection_error=rms.reshape(nf, nb),
        residuals=res.reshape(nf, nb, nc),
        views=views.reshape(nf, nb).astype(np.int64),
        rejected=rejected.reshape(nf, nb),
        rays=Rays(origins=origins.reshape(nf, nb, 3), directions=directions.reshape(nf, nb, 3)),
    )


def _rms(res: F64, seen: NDArray[np.bool_]) -> F64:
    n = np.maximum(seen.sum(axis=1), 1)
    return np.sqrt(np.where(seen, res * res, 0.0).sum(axis=1) / n)


def _solve_points(
    cams: list[Camera], uv: F64, dirs: F64, seen: NDArray[np.bool_], iterations: int
) -> tuple[F64, F64]:
    """Points (P, 3) and per-view pixel errors (P, C) for P markers with >= 2 views."""
    npts, nc = seen.shape
    # DLT: d x (R X + t) = 0 per view, two independent rows each, inhomogeneous least squares.
    rows_a = np.zeros((npts, 3 * nc, 3))
    rows_b = np.zeros((npts, 3 * nc))
    for i, c in enumerate(cams):
        d = np.where(seen[:, i : i + 1], np.nan_to_num(dirs[:, i]), 0.0)
        dx = np.zeros((npts, 3, 3))  # the cross-product matrix [d]x
        dx[:, 0, 1], dx[:, 0, 2], dx[:, 1, 2] = -d[:, 2], d[:, 1], -d[:, 0]
        dx[:, 1, 0], dx[:, 2, 0], dx[:, 2, 1] = d[:, 2], -d[:, 1], d[:, 0]
        rows_a[:, 3 * i : 3 * i + 3] = dx @ c.R
        rows_b[:, 3 * i : 3 * i + 3] = -(dx @ c.t)
    ata = np.einsum("pki,pkj->pij", rows_a, rows_a)
    atb = np.einsum("pki,pk->pi", rows_a, rows_b)
    enough = seen.sum(axis=1) >= 2
    # Two parallel rays (or one view) leave the system rank-deficient: no point.
    cond_ok = np.linalg.cond(np.where(enough[:, None, None], ata, np.eye(3))) < 1e12
    ok = enough & cond_ok
    x = np.full((npts, 3), np.nan)
    if ok.any():
        x[ok] = np.linalg.solve(ata[ok], atb[ok][:, :, None])[:, :, 0]
    # Gauss-Newton on pixel residuals, with a tiny Levenberg damping for safety.
    for _ in range(iterations):
        h = np.zeros((npts, 3, 3))
        g = np.zeros((npts, 3))
        for i, c in enumerate(cams):
            m = ok & seen[:, i]
            if not m.any():
                continue
            proj, jac = c.project_with_jacobian(x[m])
            r = proj - uv[m, i]
            h[m] += np.einsum("pki,pkj->pij", jac, jac)
            g[m] += np.einsum("pki,pk->pi", jac, r)
        live = ok & np.isfinite(h).all(axis=(1, 2)) & np.isfinite(g).all(axis=1)
        ok &= live
        if not ok.any():
            break
        damp = 1e-12 * np.trace(h[ok], axis1=1, axis2=2)[:, None, None] * np.eye(3)
        step = np.linalg.solve(h[ok] + damp, g[ok][:, :, None])[:, :, 0]
        x[ok] -= step
        scale = np.maximum(1.0, np.abs(x[ok]).max(axis=1))
        if np.all(np.abs(step).max(axis=1) <= 1e-14 * scale):
            break
    x[~ok] = np.nan
    res = np.full((npts, nc), np.nan)
    for i, c in enumerate(cams):
        res[:, i] = np.linalg.norm(c.project(x) - uv[:, i], axis=1)
    return x, res
