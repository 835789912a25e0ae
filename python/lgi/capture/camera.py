"""Cameras with OpenCV's conventions: calibrated camera models that project and un-project.

`FisheyeCamera` is `cv2.fisheye`'s Kannala-Brandt model and `PinholeCamera` `cv2.projectPoints`'s
radial-tangential model; both map world points with `x_cam = R X + t` (R, t world to camera, as
OpenCV's rvec/tvec), so calibrations from OpenCV drop in (their files: `lgi.capture.calibration`).
Everything is vectorised numpy; OpenCV itself is only the tests' reference. Un-projection
inverts the distortion by Newton's method to machine precision (OpenCV's fixed-count iteration
is weak near the image border).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi.errors import InputError

F64 = NDArray[np.float64]

__all__ = ["Camera", "FisheyeCamera", "PinholeCamera", "Rays", "rodrigues"]

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
