"""Rigid stabilisation: removes the head's motion from triangulated bundles.

Each frame's markers are aligned to the rest layout by a weighted Kabsch fit inside an
iteratively reweighted loop (Tukey's biweight on the residuals, scale from their median), so
markers that move with expressions and gross outliers stop pulling the fit. The per-frame
rotation and translation (the head transform, `capture = R rest + t`) are kept for export.
`stable_weights` derives per-marker weights from how rigidly each marker moves over a take,
the paper's forehead / nose bridge / cheek weighting found from data. `despike` drops the
one-frame jumps a mistracked 2D point leaves in stabilised bundles (with two cameras, a
mistrack along the epipolar line keeps a small reprojection error but moves the point in depth).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi.errors import InputError

F64 = NDArray[np.float64]

__all__ = ["Alignment", "align", "despike", "kabsch", "stable_weights"]

_TUKEY = 4.685  # biweight tuning constant: 95 % efficiency on Gaussian residuals
_MAD = 1.4826  # median absolute deviation to standard deviation (Gaussian)


@dataclass(frozen=True)
class Alignment:
    """Frames aligned to the rest layout and the head transforms that were removed."""

    frames: F64
    """(F, B, 3) markers in the rest layout's space, `R^T (x - t)`; NaN where missing."""
    rotations: F64
    """(F, 3, 3) head rotation per frame: capture = R rest + t."""
    translations: F64
    """(F, 3) head translation per frame."""
    inliers: NDArray[np.bool_]
    """(F, B) markers the final fit treated as rigid with the head (False for missing)."""
    rms: F64
    """(F,) RMS distance of the inliers to their rest positions after alignment."""


def _frames(frames: ArrayLike, rest: F64) -> F64:
    try:
        x = np.asarray(frames, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InputError(f"frames: not a numeric array ({e})") from None
    if x.ndim == 2:
        x = x[None]
    if x.ndim != 3 or x.shape[1:] != rest.shape:
        raise InputError(f"frames: expected shape (F, {rest.shape[0]}, 3), got {x.shape}")
    if np.isinf(x).any():
        raise InputError("frames: contains infinity (NaN marks a missing marker)")
    return x


def _rest(rest: ArrayLike) -> F64:
    r = np.asarray(rest, dtype=np.float64)
    if r.ndim != 2 or r.shape[1] != 3 or r.shape[0] < 3:
        raise InputError(f"rest: expected shape (B, 3) with B >= 3, got {r.shape}")
    if not np.isfinite(r).all():
        raise InputError("rest: contains NaN or infinity")
    return r


def _weights(weights: ArrayLike | None, n: int) -> F64:
    if weights is None:
        return np.ones(n)
    w = np.asarray(weights, dtype=np.float64)
    if w.shape != (n,):
        raise InputError(f"weights: expected shape ({n},), got {w.shape}")
    if not np.isfinite(w).all() or (w < 0).any() or not (w > 0).any():
        raise InputError("weights: must be finite, >= 0 and not all zero")
    return w


def _weighted_median(values: F64, weights: F64) -> F64:
    """Per row, the weighted median of values (F, B) with weights (F, B) (zero = ignored)."""
    order = np.argsort(np.where(weights > 0, values, np.inf), axis=1)
    v = np.take_along_axis(values, order, axis=1)
    cum = np.cumsum(np.take_along_axis(weights, order, axis=1), axis=1)
    idx = (cum < 0.5 * cum[:, -1:]).sum(axis=1)
    return v[np.arange(values.shape[0]), np.minimum(idx, values.shape[1] - 1)]


def kabsch(source: F64, target: F64, weights: F64) -> tuple[F64, F64]:
    """Batched weighted Kabsch: rotations (F, 3, 3) and translations (F, 3) minimising
    `sum_b w_fb |R source_b + t - target_fb|^2` for source (B, 3), target (F, B, 3) and
    weights (F, B) (0 for missing markers; NaN targets must carry weight 0)."""
    w = weights / np.maximum(weights.sum(axis=1, keepdims=True), 1e-300)
    tgt = np.nan_to_num(target)
    cs = np.einsum("fb,bd->fd", w, source)
    ct = np.einsum("fb,fbd->fd", w, tgt)
    h = np.einsum("fb,fbi,fbj->fij", w, source[None] - cs[:, None], tgt - ct[:, None])
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.einsum("fji,fkj->fik", vt, u)))
    d[d == 0] = 1.0
    fix = np.ones((w.shape[0], 3))
    fix[:, 2] = d
    rot = np.einsum("fji,fj,fkj->fik", vt, fix, u)  # V diag(1, 1, d) U^T
    t = ct - np.einsum("fij,fj->fi", rot, cs)
    return rot, t


def align(
    frames: ArrayLike,
    rest: ArrayLike,
    weights: ArrayLike | None = None,
    *,
    iterations: int = 30,
    threshold: float | None = None,
) -> Alignment:
    """Aligns each frame's markers (F, B, 3) (NaN = missing) to the rest layout (B, 3) by a
    weighted, outlier-robust rigid fit. `weights` (B,) say how much each marker is trusted to
    move with the skull (e.g. `stable_weights`); every marker's pull is further multiplied by
    Tukey's biweight of its residual, with the scale `4.685 * 1.4826 * median residual` (the
    median weighted by `weights`, so the trusted markers set it), until the fit stops
    changing. `threshold` (data units) caps that inlier scale (a residual above it is always
    an outlier). Raises InputError for a frame with fewer than 3 usable markers."""
    r = _rest(rest)
    x = _frames(frames, r)
    prior = _weights(weights, r.shape[0])
    if threshold is not None and not (np.isfinite(threshold) and threshold > 0):
        raise InputError(f"threshold must be > 0, got {threshold}")
    present = ~np.isnan(x).any(axis=2)
    base = np.where(present, prior[None], 0.0)
    usable = (base > 0).sum(axis=1)
    if (usable < 3).any():
        f = int(np.flatnonzero(usable < 3)[0])
        raise InputError(
            f"frames: frame {f} has {int(usable[f])} markers with weight > 0; a rigid "
            "alignment needs at least 3"
        )
    diag = float(np.linalg.norm(r.max(axis=0) - r.min(axis=0)))
    floor = 1e-9 * diag  # noise-free data: keep the scale from collapsing to zero
    w = base.copy()
    rot, t = kabsch(r, x, w)
    for _ in range(iterations):
        pred = np.einsum("fij,bj->fbi", rot, r) + t[:, None]
        e = np.linalg.norm(np.nan_to_num(x) - pred, axis=2)
        # The inlier scale from the markers trusted most: the prior-weighted median.
        scale = np.maximum(_MAD * _weighted_median(e, base), floor)
        c = _TUKEY * scale
        if threshold is not None:
            c = np.minimum(c, threshold)
        u = e / c[:, None]
        new_w = base * np.where(u < 1, (1 - u * u) ** 2, 0.0)
        starved = (new_w > 0).sum(axis=1) < 3
        new_w[starved] = base[starved]  # never fewer than 3: fall back to the prior weights
        rot_new, t_new = kabsch(r, x, new_w)
        change = np.abs(rot_new - rot).max() + np.abs(t_new - t).max() / max(diag, 1e-300)
        rot, t, w = rot_new, t_new, new_w
        if change < 1e-13:
            break
    aligned = np.einsum("fbi,fij->fbj", x - t[:, None], rot)  # R^T (x - t), row-wise
    resid = np.linalg.norm(aligned - r[None], axis=2)
    inliers = (w > 0) & present
    rms = np.sqrt(
        np.where(inliers, np.nan_to_num(resid) ** 2, 0).sum(axis=1)
        / np.maximum(inliers.sum(axis=1), 1)
    )
    return Alignment(frames=aligned, rotations=rot, translations=t, inliers=inliers, rms=rms)


def stable_weights(
    frames: ArrayLike, rest: ArrayLike, *, rounds: int = 3, scale: float | None = None
) -> F64:
    """Per-marker weights (B,) in (0, 1] from how rigidly each marker moves with the head over
    a take (F, B, 3): align, measure each marker's median distance from its rest position
    over the frames (its own motion once the head's is removed, blind to a few outliers),
    weight `1 / (1 + (m / s)^2)`, and re-align with those weights (`rounds` times). `s`
    defaults to the median motion, so markers moving less than the typical marker (forehead,
    nose bridge) weigh near 1 and lips and jaw little. Markers never seen get weight 0."""
    r = _rest(rest)
    x = _frames(frames, r)
    if rounds < 1:
        raise InputError(f"rounds must be >= 1, got {rounds}")
    if scale is not None and not (np.isfinite(scale) and scale > 0):
        raise InputError(f"scale must be > 0, got {scale}")
    seen = (~np.isnan(x).any(axis=2)).any(axis=0)
    w: F64 = np.asarray(seen, dtype=np.float64)
    for _ in range(rounds):
        al = align(x, r, w)
        dist = np.linalg.norm(al.frames - r[None], axis=2)
        # The median over frames: a marker's typical motion, blind to a few gross outliers.
        motion = np.zeros(r.shape[0])
        motion[seen] = np.nanmedian(dist[:, seen], axis=0)
        s = float(np.median(motion[seen])) if scale is None else scale
        s = max(s, 1e-12 * float(np.linalg.norm(np.ptp(r, axis=0))))
        w = np.asarray(np.where(seen, 1.0 / (1.0 + (motion / s) ** 2), 0.0))
        w /= w.max()
    return w


def despike(
    frames: ArrayLike, *, half_window: int = 2, threshold: float = 5.0
) -> tuple[F64, NDArray[np.bool_]]:
    """Stabilised bundles (F, B, 3) with one-frame jumps removed: a sample farther from the
    median of its marker's `half_window` neighbours on each side (itself excluded) than
    `threshold` times that marker's robust scale (1.4826 x the median such distance over the
    take) becomes NaN (missing, so the solve reconstructs it). Returns the cleaned copy and
    the (F, B) mask of removed samples. Run it on stabilised frames, where the head's motion
    no longer hides the markers' own smooth motion."""
    r = np.asarray(frames, dtype=np.float64)
    if r.ndim != 3 or r.shape[2] != 3:
        raise InputError(f"frames: expected shape (F, B, 3), got {r.shape}")
    if half_window < 1:
        raise InputError(f"half_window must be >= 1, got {half_window}")
    if not (np.isfinite(threshold) and threshold > 0):
        raise InputError(f"threshold must be > 0, got {threshold}")
    nf = r.shape[0]
    neighbours = []
    for off in range(-half_window, half_window + 1):
        if off == 0:
            continue
        idx = np.arange(nf) + off
        shifted = r[np.clip(idx, 0, nf - 1)].copy()
        shifted[(idx < 0) | (idx >= nf)] = np.nan
        neighbours.append(shifted)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN windows: no verdict
        med = np.nanmedian(np.stack(neighbours), axis=0)
        dist = np.linalg.norm(r - med, axis=2)
        scale = _MAD * np.nanmedian(dist, axis=0)
    with np.errstate(invalid="ignore"):
        spikes = dist > threshold * scale[None]
    out = r.copy()
    out[spikes] = np.nan
    return out, spikes
