"""Live Link Face recordings in: the CSV files Apple's Live Link Face app writes (ARKit
blendshape-weight curves per frame, then head and eye rotations), read as `Curves`, with the
mapping of ARKit curve names onto a dataset's shape names (`arkit_to_dataset`)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lgi.errors import InputError
from lgi.io.csv_rows import read_csv_rows

F64 = NDArray[np.float64]

__all__ = ["ARKIT_BOTH_SIDES", "Curves", "arkit_to_dataset", "read_livelinkface"]


ARKIT_BOTH_SIDES = ("BrowInnerUp", "CheekPuff")
"""ARKit curves with no side that drive both a `_L` and an `_R` shape in a two-sided rig."""

_TIMECODE_RATES = (24, 25, 30, 48, 50, 60, 120)


@dataclass(frozen=True)
class Curves:
    """Blendshape-weight curves of one recording."""

    times: F64
    """(F,) seconds from the first frame."""
    names: list[str]
    """N curve names as recorded (ARKit PascalCase: `EyeBlinkLeft`, `JawOpen`, ...)."""
    weights: F64
    """(F, N) weights, 0..1."""
    path: str
    """The file read."""

    @property
    def num_frames(self) -> int:
        return int(self.weights.shape[0])

    @property
    def fps(self) -> float:
        """Median frame rate (frames per second)."""
        if self.times.size < 2:
            return float("nan")
        return float(1.0 / np.median(np.diff(self.times)))

    def for_dataset(self, shape_names: Sequence[str]) -> F64:
        """(F, S) weights of the dataset's shapes `shape_names` ([`arkit_to_dataset`]); shapes no
        curve drives stay 0."""
        mapping = arkit_to_dataset(self.names, shape_names)
        out = np.zeros((self.num_frames, len(shape_names)))
        for curve, shapes in mapping.items():
            c = self.names.index(curve)
            for s in shapes:
                out[:, s] = self.weights[:, c]
        return out


def arkit_to_dataset(curves: Sequence[str], shape_names: Sequence[str]) -> dict[str, list[int]]:
    """Which dataset shapes (indices into `shape_names`) each ARKit curve drives.

    The rule (ICT-FaceKit's and most ARKit-style rigs' naming): the curve's name with a lower-case
    first letter if a shape has it (`JawOpen` -> `jawOpen`, `MouthLeft` -> `mouthLeft`); else a
    `Left`/`Right` suffix becomes `_L`/`_R` (`EyeBlinkLeft` -> `eyeBlink_L`: ARKit's left is the
    performer's left); else `BrowInnerUp` and `CheekPuff` drive both sides. Curves with no shape
    (`TongueOut`, head and eye rotations) are left out."""
    index = {n: i for i, n in enumerate(shape_names)}
    out: dict[str, list[int]] = {}
    for c in curves:
        if not c:
            continue
        stem = c[0].lower() + c[1:]
        if stem in index:
            out[c] = [index[stem]]
            continue
        for suffix, side in (("Left", "_L"), ("Right", "_R")):
            if stem.endswith(suffix) and stem[: -len(suffix)] + side in index:
                out[c] = [index[stem[: -len(suffix)] + side]]
                break
        else:
            if c in ARKIT_BOTH_SIDES:
                both = [index[s] for s in (stem + "_L", stem + "_R") if s in index]
                if both:
                    out[c] = both
    return out


def _seconds(timecode: str, rate: int) -> float:
    h, m, s, f = timecode.split(":")
    return int(h) * 3600 + int(m) * 60 + int(s) + float(f) / rate


def read_livelinkface(path: str | os.PathLike[str]) -> Curves:
    """Reads a Live Link Face CSV: `Timecode` (HH:MM:SS:FF.fff), `BlendShapeCount`, then one
    column per curve (the 52 ARKit weights, then head and eye rotations). Raises `InputError`
    naming the file and line for anything else."""
    p, rows = read_csv_rows(path, "a Live Link Face CSV")
    if not rows or len(rows[0]) < 3 or rows[0][:2] != ["Timecode", "BlendShapeCount"]:
        raise InputError(
            f"{p}: not a Live Link Face CSV: the header must start with "
            f"'Timecode,BlendShapeCount' (got {','.join(rows[0][:3]) if rows else 'nothing'!r})"
        )
    names = rows[0][2:]
    stamps: list[str] = []
    values = np.empty((len(rows) - 1, len(names)))
    for i, row in enumerate(rows[1:]):
        line = i + 2
        if len(row) != len(names) + 2:
            raise InputError(
                f"{p}, line {line}: {len(row)} columns, the header has {len(names) + 2}"
            )
        parts = row[0].split(":")
        if len(parts) != 4:
            raise InputError(f"{p}, line {line}: timecode {row[0]!r} is not HH:MM:SS:FF.fff")
        stamps.append(row[0])
        try:
            values[i] = [float(x) for x in row[2:]]
        except ValueError:
            raise InputError(f"{p}, line {line}: a weight is not a number") from None
        if not np.all(np.isfinite(values[i])):
            raise InputError(f"{p}, line {line}: a weight is not finite")
    if not stamps:
        raise InputError(f"{p}: the recording has no frames")
    try:
        frame_numbers = [float(s.split(":")[3]) for s in stamps]
        # The timecode's frame field counts at the timecode rate: the smallest standard rate
        # above every frame number seen.
        rate = next((r for r in _TIMECODE_RATES if max(frame_numbers) < r), _TIMECODE_RATES[-1])
        t = np.array([_seconds(s, rate) for s in stamps])
    except ValueError:
        raise InputError(f"{p}: a timecode is not HH:MM:SS:FF.fff") from None
    # A take that crosses midnight wraps: unwrap by whole days.
    t = t + 86400.0 * np.concatenate([[0], np.cumsum(np.diff(t) < -43200.0)])
    if np.any(np.diff(t) <= 0):
        line = int(np.argmax(np.diff(t) <= 0)) + 3
        raise InputError(f"{p}, line {line}: timecodes do not increase")
    return Curves(times=t - t[0], names=names, weights=values, path=p)
