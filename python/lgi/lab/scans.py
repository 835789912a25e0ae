"""The paper's own setting: a dataset of whole-face scans of a range-of-motion session.

The scans are not a FACS basis but K expressions, each a whole face: frames of real ARKit
curves (the shared Live Link Face recordings) picked farthest-first in curve space
(`pick_scans`), each evaluated by the capture truth rig (`lgi.lab.capture.capture_truth`: the
dataset's shapes blended linearly, the jaw turned about its hinge), so a scan holds the
combination and the jaw rotation a real scan would. They come with the dataset's jaw rig and
each scan's jaw pose (`scan_theta`: what a scan session records with each scan, here the
curve-weighted poses of the dataset's jaw shapes). The performance is a different recording.

A caution that shapes any reading of the results: a truth made from a linear rig lies in the
span of scans made from the same rig (but for the jaw's rotation), so a global fit of the
scans is nearly an oracle; local geometry has to win where the truth is not a blend.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi.data.dataset import Dataset, with_shapes
from lgi.errors import InputError
from lgi.lab.capture import HingeJaw, NonlinearTruth, capture_truth

F64 = NDArray[np.float64]

__all__ = ["ScanSession", "pick_scans", "scan_session", "scan_theta"]

_CHUNK = 100
"""Scans made at once (their float64 meshes are 64 MB per 100 on ICT)."""


def pick_scans(weights: ArrayLike, count: int) -> list[int]:
    """`count` rows of `weights` (F, S) farthest-first in curve space: first the frame farthest
    from the neutral (all weights 0), then each frame farthest from every one picked (the
    expressions a range-of-motion session would scan: as different as possible)."""
    w = np.asarray(weights, dtype=np.float64)
    if w.ndim != 2 or w.shape[0] == 0:
        raise InputError(f"weights: expected (F, S) with F >= 1, got {w.shape}")
    if not 1 <= count <= w.shape[0]:
        raise InputError(f"scans: need 1..{w.shape[0]} (the frames there are), got {count}")
    dist = np.linalg.norm(w, axis=1)
    picked: list[int] = []
    for _ in range(count):
        j = int(np.argmax(dist))
        picked.append(j)
        dist = np.minimum(dist, np.linalg.norm(w - w[j], axis=1))
    return picked


def scan_theta(weights: ArrayLike, shape_theta: ArrayLike) -> F64:
    """Each scan's jaw pose (K, 3): its curve weights (K, S) times the dataset's shapes' poses
    (S, 3) (`lgi.solve.jaw.estimate_rig`'s theta), the jaw shapes' share of the expression."""
    return np.asarray(weights, dtype=np.float64) @ np.asarray(shape_theta, dtype=np.float64)


class ScanSession:
    """K whole-face scans: `dataset` (the neutral and the scans as shapes `scan000`...), the
    curve weights that made them and their jaw poses for the dataset's rig."""

    def __init__(self, dataset: Dataset, weights: F64, theta: F64 | None, frames: list[int]):
        self.dataset = dataset
        self.weights = weights
        self.theta = theta
        self.frames = frames


def scan_session(
    source: Dataset,
    weights: ArrayLike,
    count: int,
    jaw: HingeJaw | None,
    shape_theta: ArrayLike | None,
    names: Sequence[str] | None = None,
    nonlinear: NonlinearTruth | None = None,
) -> ScanSession:
    """Scans of `source` (a blendshape dataset) at `count` of the curve frames `weights` (F, S)
    picked by `pick_scans`, each made by the capture truth rig with `jaw`; with `shape_theta`
    (S, 3, the source's shapes' jaw poses) each scan's pose (`scan_theta`). With `nonlinear`
    the scans are its meshes (`lgi.lab.capture.NonlinearTruth`), not the linear rig's."""
    w = np.asarray(weights, dtype=np.float64)
    picked = pick_scans(w, count)
    neutral = np.asarray(source.neutral)
    shapes = np.empty((count, *neutral.shape), dtype=np.float32)
    for at in range(0, count, _CHUNK):  # float64 meshes a chunk at a time: K = 2,000 fits
        chunk = w[picked[at : at + _CHUNK]]
        part = nonlinear.meshes(chunk) if nonlinear else capture_truth(source, chunk, jaw)
        shapes[at : at + part.shape[0]] = part - neutral[None]
    labels = list(names) if names is not None else [f"scan{i:03d}" for i in range(count)]
    ds = with_shapes(source, shapes, labels)
    theta = None if shape_theta is None else scan_theta(w[picked], shape_theta)
    return ScanSession(ds, w[picked], theta, picked)
