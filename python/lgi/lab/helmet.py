"""A synthetic helmet take: the paper's capture rig (two vertically stacked fisheye cameras on a
head-mounted boom) filming markers on a moving head, as 2D tracks with the faults real trackers
have (pixel noise, occlusions, a few mistracked points).

Seeded and scale-free: the rig is placed from the marker layout's size, so it works in the
built-in sample's units and in the ICT data's centimetres. The head moves relative to the
cameras (a helmet slips and the neck turns it) by rotations about a neck pivot and
translations; the truth of every stage (world points, head transforms, which samples were
occluded or mistracked) is kept so each stage of the chain can be scored. Occlusion is random
runs and the image border, not ray casting against the face.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi.capture.camera import FisheyeCamera, rodrigues
from lgi.errors import InputError
from lgi.lab.sample import dropout_mask

F64 = NDArray[np.float64]

__all__ = ["HeadMotion", "HelmetTake", "head_motion", "helmet_cameras", "make_helmet_take"]

LENS = (0.03, -0.01, 0.002, -0.0003)
"""Kannala-Brandt coefficients of the synthetic lenses (a mild, realistic fisheye)."""


def _layout(rest: ArrayLike) -> F64:
    r = np.asarray(rest, dtype=np.float64)
    if r.ndim != 2 or r.shape[1] != 3 or r.shape[0] < 3 or not np.isfinite(r).all():
        raise InputError(f"rest: expected finite marker positions (B, 3), got shape {r.shape}")
    return r


def helmet_cameras(
    rest: ArrayLike,
    *,
    image_size: tuple[int, int] = (1280, 1024),
    distance: float = 0.75,
    baseline: float = 0.5,
) -> list[FisheyeCamera]:
    """Two fisheye cameras stacked vertically in front of the face, both aimed at the marker
    layout's centre: `distance` (times the layout's height) in front of its frontmost marker,
    `baseline` (times the height) apart, centred on the layout's lower half (where the boom of a
    head-mounted camera sits). The face looks along +z with +y up (the ICT convention)."""
    r = _layout(rest)
    lo, hi = r.min(axis=0), r.max(axis=0)
    height = float(hi[1] - lo[1])
    target = 0.5 * (lo + hi)
    w, h = image_size
    # The image's half height covers 45° off axis: the face and its motion fill the frame.
    f = 0.5 * h / np.radians(45.0)
    k = np.array([[f, 0.0, 0.5 * (w - 1)], [0.0, f, 0.5 * (h - 1)], [0.0, 0.0, 1.0]])
    cams = []
    for dy in (0.5 * baseline, -0.5 * baseline):
        centre = np.array([target[0], target[1] + (dy - 0.15) * height, hi[2] + distance * height])
        fwd = target - centre
        fwd /= np.linalg.norm(fwd)
        right = np.cross([0.0, -1.0, 0.0], fwd)  # image rows run down the face (-y)
        right /= np.linalg.norm(right)
        down = np.cross(fwd, right)
        rot = np.stack([right, down, fwd])
        cams.append(FisheyeCamera(k, LENS, rot, -rot @ centre, image_size))
    return cams


@dataclass(frozen=True)
class HeadMotion:
    """Head transforms per frame: a rest-space point x is at `R x + t` in camera space."""

    rotations: F64
    """(F, 3, 3)."""
    translations: F64
    """(F, 3)."""

    def apply(self, points: ArrayLike) -> F64:
        """(F, B, 3) rest-space points moved by each frame's transform."""
        p = np.asarray(points, dtype=np.float64)
        return np.einsum("fij,fbj->fbi", self.rotations, p) + self.translations[:, None]


def head_motion(
    num_frames: int,
    rest: ArrayLike,
    *,
    seed: int,
    max_angle: float = 15.0,
    max_shift: float = 2.0,
) -> HeadMotion:
    """Smooth random head motion: per axis a sum of three slow sinusoids, scaled so the
    rotation (about a neck pivot below and behind the layout's centre) peaks at `max_angle`
    degrees and each coordinate of the shift at `max_shift` data units. Frame 0 is the rest
    pose."""
    if num_frames < 1:
        raise InputError(f"num_frames must be >= 1, got {num_frames}")
    r = _layout(rest)
    rng = np.random.default_rng(seed)
    lo, hi = r.min(axis=0), r.max(axis=0)
    height = float(hi[1] - lo[1])
    pivot = np.array([0.5 * (lo[0] + hi[0]), lo[1] - 0.3 * height, lo[2] - 0.3 * height])
    time = np.arange(num_frames) / max(num_frames - 1, 1)

    def curves(count: int) -> F64:
        out = np.zeros((num_frames, count))
        for c in range(count):
            for _ in range(3):
                freq, phase = rng.uniform(0.5, 2.5), rng.uniform(0, 2 * np.pi)
                out[:, c] += np.sin(2 * np.pi * freq * time + phase) - np.sin(phase)
            peak = np.abs(out[:, c]).max()
            out[:, c] /= peak if peak > 0 else 1.0
        return out

    angles = curves(3)
    angles *= np.radians(max_angle) / max(float(np.linalg.norm(angles, axis=1).max()), 1e-300)
    shifts = max_shift * curves(3)
    rots = np.stack([rodrigues(a) for a in angles])
    # Turning about the pivot: x -> R (x - p) + p + s.
    t = pivot[None] - np.einsum("fij,j->fi", rots, pivot) + shifts
    return HeadMotion(rotations=rots, translations=t)


@dataclass(frozen=True)
class HelmetTake:
    """2D tracks of a helmet take and the truth behind them."""

    uv: F64
    """(F, B, C, 2) tracked pixels; NaN where camera c lost marker b."""
    cameras: list[FisheyeCamera]
    """The rig, C cameras."""
    motion: HeadMotion
    """The true head transforms."""
    points: F64
    """(F, B, 3) the true marker positions in camera (rig) space."""
    occluded: NDArray[np.bool_]
    """(F, B, C) samples lost to occlusion or the image border."""
    mistracked: NDArray[np.bool_]
    """(F, B, C) samples the tracker put on the wrong spot."""


def make_helmet_take(
    bundles: ArrayLike,
    cameras: list[FisheyeCamera],
    motion: HeadMotion,
    *,
    seed: int,
    pixel_noise: float = 0.5,
    occlusion: float = 0.02,
    mistrack: float = 0.002,
    mistrack_pixels: tuple[float, float] = (8.0, 40.0),
) -> HelmetTake:
    """Films rest-space bundles (F, B, 3) moved by `motion` with `cameras`: Gaussian pixel
    noise of `pixel_noise` px per coordinate, an `occlusion` fraction of samples per camera
    lost in runs of 2 to 8 frames, markers outside an image lost, and a `mistrack` fraction of
    samples moved `mistrack_pixels` (min, max) px in a random direction."""
    b = np.asarray(bundles, dtype=np.float64)
    if b.ndim != 3 or b.shape[2] != 3:
        raise InputError(f"bundles: expected shape (F, B, 3), got {b.shape}")
    if motion.rotations.shape[0] != b.shape[0]:
        raise InputError(f"motion has {motion.rotations.shape[0]} frames, bundles {b.shape[0]}")
    if not (pixel_noise >= 0 and 0 <= occlusion < 1 and 0 <= mistrack < 1):
        raise InputError("pixel_noise must be >= 0, occlusion and mistrack in [0, 1)")
    rng = np.random.default_rng(seed)
    world = motion.apply(b)
    nf, nb = b.shape[:2]
    nc = len(cameras)
    uv = np.stack([c.project(world) for c in cameras], axis=2)
    uv += rng.normal(0.0, pixel_noise, size=uv.shape)
    occluded = np.zeros((nf, nb, nc), dtype=bool)
    for i, c in enumerate(cameras):
        occluded[:, :, i] = dropout_mask(nf, nb, occlusion, rng) | ~c.in_image(uv[:, :, i])
    occluded |= np.isnan(uv).any(axis=3)
    mistracked = (rng.random((nf, nb, nc)) < mistrack) & ~occluded
    n = int(mistracked.sum())
    angle = rng.uniform(0, 2 * np.pi, n)
    size = rng.uniform(*mistrack_pixels, n)
    uv[mistracked] += size[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    uv[occluded] = np.nan
    return HelmetTake(
        uv=uv,
        cameras=list(cameras),
        motion=motion,
        points=world,
        occluded=occluded,
        mistracked=mistracked,
    )
