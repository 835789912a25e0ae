"""Animation curves out of a solve: each frame's global blendshape fit (`SolveResult.
fit_weights`) and jaw pose, for pipelines that drive a rig rather than play a point cache.
The curves are the global fit's, not the solved mesh (which follows local geometry): USD
`UsdSkel` animation over the blend-shape rig `lgi rig` writes (`write_usd_curves`), or a Live
Link Face CSV of ARKit curves where the dataset's shape names map (`write_livelink_csv`)."""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from lgi.errors import InputError, LgiWarning
from lgi.io.atomic import atomic_path
from lgi.io.frame import OutputFrame
from lgi.io.livelink import arkit_to_dataset
from lgi.io.rig import RigAnimation, write_usd_rig

if TYPE_CHECKING:
    from lgi.data.dataset import Dataset

__all__ = [
    "ARKIT_CURVES",
    "CURVE_SUFFIXES",
    "write_curves",
    "write_livelink_csv",
    "write_usd_curves",
]

ARKIT_CURVES = (
    "EyeBlinkLeft", "EyeLookDownLeft", "EyeLookInLeft", "EyeLookOutLeft", "EyeLookUpLeft",
    "EyeSquintLeft", "EyeWideLeft", "EyeBlinkRight", "EyeLookDownRight", "EyeLookInRight",
    "EyeLookOutRight", "EyeLookUpRight", "EyeSquintRight", "EyeWideRight", "JawForward",
    "JawRight", "JawLeft", "JawOpen", "MouthClose", "MouthFunnel", "MouthPucker", "MouthRight",
    "MouthLeft", "MouthSmileLeft", "MouthSmileRight", "MouthFrownLeft", "MouthFrownRight",
    "MouthDimpleLeft", "MouthDimpleRight", "MouthStretchLeft", "MouthStretchRight",
    "MouthRollLower", "MouthRollUpper", "MouthShrugLower", "MouthShrugUpper", "MouthPressLeft",
    "MouthPressRight", "MouthLowerDownLeft", "MouthLowerDownRight", "MouthUpperUpLeft",
    "MouthUpperUpRight", "BrowDownLeft", "BrowDownRight", "BrowInnerUp", "BrowOuterUpLeft",
    "BrowOuterUpRight", "CheekPuff", "CheekSquintLeft", "CheekSquintRight", "NoseSneerLeft",
    "NoseSneerRight", "TongueOut",
)  # fmt: skip
"""ARKit's 52 blendshape curves in Live Link Face's column order."""

CURVE_SUFFIXES = (".usd", ".usda", ".usdc", ".csv")

LIVELINK_RATES = (24.0, 25.0, 30.0, 48.0, 50.0, 60.0, 120.0)
"""Frame rates a Live Link Face timecode can count (its frame field is read at these)."""


def write_usd_curves(
    path: str | os.PathLike[str],
    dataset: Dataset,
    weights: Any,
    *,
    fps: float,
    start: int = 0,
    units: str | None = None,
    jaw_theta: Any | None = None,
    frame: OutputFrame | None = None,
) -> Path:
    """The blend-shape rig of `dataset` (`write_usd_rig`, in `frame` when given) with (F, S)
    `weights` as its `SkelAnimation`'s time-sampled `blendShapeWeights` and the jaw pose as
    `lgi:jawTheta` (its forward translation scaled with the frame)."""
    jaw = None if jaw_theta is None else np.asarray(jaw_theta, dtype=np.float64).copy()
    if jaw is not None and frame is not None:
        jaw[:, 2] *= frame.scale
    return write_usd_rig(
        path,
        dataset,
        units=units,
        animation=RigAnimation(np.asarray(weights), fps, start, jaw),
        frame=frame,
    )


def _timecode(seconds: float, rate: float) -> str:
    """Live Link Face's `HH:MM:SS:FF.fff`, frames counted at `rate`."""
    whole = int(seconds)
    frames = (seconds - whole) * rate
    h, m, s = whole // 3600, whole // 60 % 60, whole % 60
    return f"{h:02d}:{m:02d}:{s:02d}:{frames:06.3f}"


def write_livelink_csv(
    path: str | os.PathLike[str],
    shape_names: Sequence[str],
    weights: Any,
    *,
    fps: float,
    start: int = 0,
) -> Path:
    """A Live Link Face CSV of the ARKit curves the dataset's shapes map to (`arkit_to_dataset`;
    a curve driving two shapes gets their mean): `Timecode` at `fps` from frame `start`,
    `BlendShapeCount`, then the 52 curves, 0 where no shape maps. Dataset shapes no curve
    drives are named in an `LgiWarning`; a dataset none of whose shapes map is an error."""
    w = np.asarray(weights, dtype=np.float64)
    if w.ndim != 2 or w.shape[1] != len(shape_names):
        raise InputError(f"curves: weights must be (F, {len(shape_names)}), got {w.shape}")
    mapping = arkit_to_dataset(ARKIT_CURVES, shape_names)
    used = {s for shapes in mapping.values() for s in shapes}
    unmapped = [n for i, n in enumerate(shape_names) if i not in used]
    if not mapping:
        raise InputError(
            f"--curves {path}: no shape of the dataset has an ARKit name "
            f"({', '.join(list(shape_names)[:6])}, ...); write USD curves instead"
        )
    if unmapped:
        warnings.warn(
            f"--curves {path}: {len(unmapped)} shapes have no ARKit curve and are left out: "
            + ", ".join(unmapped[:8])
            + (", ..." if len(unmapped) > 8 else ""),
            LgiWarning,
            stacklevel=2,
        )
    out = np.zeros((w.shape[0], len(ARKIT_CURVES)))
    for k, c in enumerate(ARKIT_CURVES):
        if c in mapping:
            out[:, k] = w[:, mapping[c]].mean(axis=1)
    lines = ["Timecode,BlendShapeCount," + ",".join(ARKIT_CURVES)]
    for f in range(w.shape[0]):
        stamp = _timecode((start + f) / fps, fps)
        lines.append(f"{stamp},{len(ARKIT_CURVES)}," + ",".join(f"{x:.6g}" for x in out[f]))
    target = Path(path)
    with atomic_path(target) as tmp:
        tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return target


def write_curves(
    path: str | os.PathLike[str],
    dataset: Dataset,
    weights: Any,
    *,
    fps: float | None,
    start: int,
    units: str | None,
    jaw_theta: Any | None,
    frame: OutputFrame | None = None,
) -> Path:
    """`--curves FILE` by suffix: USD (`write_usd_curves`, its rig in `frame`) or Live Link
    CSV (weights have no unit)."""
    suffix = Path(path).suffix.lower()
    if suffix not in CURVE_SUFFIXES:
        raise InputError(f"--curves {path}: use .usd/.usda/.usdc (UsdSkel) or .csv (Live Link)")
    if fps is None:
        raise InputError("--curves: the take has no frame rate; pass --fps")
    if suffix == ".csv":
        if fps not in LIVELINK_RATES:
            raise InputError(
                f"--curves {path}: Live Link Face timecodes count frames at "
                f"{', '.join(map(str, LIVELINK_RATES))} per second, not {fps:g}"
            )
        return write_livelink_csv(path, list(dataset.names), weights, fps=fps, start=start)
    return write_usd_curves(
        path, dataset, weights, fps=fps, start=start, units=units, jaw_theta=jaw_theta, frame=frame
    )
