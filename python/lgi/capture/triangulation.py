"""Triangulation of 2D marker tracks from calibrated cameras into 3D bundles: a linear (DLT)
start from the undistorted rays, then Gauss-Newton on the reprojection error in pixels, with
mistracked views rejected and single-view markers kept as rays (`Triangulation`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi.capture.camera import Camera, Rays
from lgi.errors import InputError

F64 = NDArray[np.float64]

__all__ = ["Triangulation", "triangulate"]


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
        raise InputError("cameras: expected a non-empty sequence of lgi.capture.camera cameras")
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
