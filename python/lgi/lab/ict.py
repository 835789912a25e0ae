"""The ICT-FaceKit data, the project's real face: where it lies, how it is read and what its
vertex ranges mean, written once for the CLI, the evaluation scripts, the benches and the tests.

The folder (`ict-facekit/` under the shared data folder) holds `generic_neutral_mesh.obj`, the
expression shapes `shapes/*.obj` (same vertex order) and the marker layout `markers_120.csv`
(header row, then name, x, y, z). Callers say where the shared data folder is (the CLI and the
tests take it from the `LGI_SHARED_DATA` environment variable, `ENV`); `find` otherwise looks for
`shared/data` beside the working directory and its parents.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lgi.data.dataset import Dataset
from lgi.io.takes import Layout, read_layout

__all__ = [
    "ENV",
    "LOWER_TEETH",
    "NARROW_FACE",
    "SKIN_VERTICES",
    "animface",
    "face_triangles",
    "find",
    "is_ict",
    "livelinkface",
    "load_dataset",
    "load_landmarks",
    "load_layout",
    "load_markers",
    "lower_teeth",
    "skin",
]

ENV = "LGI_SHARED_DATA"
"""Environment variable naming the shared data folder (the parent of `ict-facekit/`)."""

SKIN_VERTICES = 9409
"""The face skin is vertices 0..9408; the rest are eyes, teeth, gums and the back of the head."""

LOWER_TEETH = (19247, 21450)
"""Lower teeth (0-based, inclusive): the jaw's only truly rigid part."""

NARROW_FACE = 6706
"""Vertices 0..6705: the narrow face (no ears, neck or scalp), where a marker artist puts dots."""

_FOLDER = "ict-facekit"
_NEUTRAL = "generic_neutral_mesh.obj"


def skin() -> NDArray[np.int64]:
    """Indices of the face-skin vertices (the region errors are measured on)."""
    return np.arange(SKIN_VERTICES)


def lower_teeth() -> NDArray[np.int64]:
    """Indices of the lower teeth (what a jaw hinge is fitted to)."""
    return np.arange(LOWER_TEETH[0], LOWER_TEETH[1] + 1)


def livelinkface(shared_data: str | os.PathLike[str] | None = None) -> list[Path]:
    """The shared Live Link Face recordings (`livelinkface/*.csv` beside `ict-facekit/`),
    sorted; empty when absent."""
    ict = find(shared_data)
    return [] if ict is None else sorted((ict.parent / "livelinkface").glob("*.csv"))


def animface(shared_data: str | os.PathLike[str] | None = None) -> list[Path]:
    """The shared AnimFace marker takes (`animface/*.trc` beside `ict-facekit/`), sorted;
    empty when absent."""
    ict = find(shared_data)
    return [] if ict is None else sorted((ict.parent / "animface").glob("*.trc"))


def face_triangles(dataset: Dataset) -> NDArray[np.int64]:
    """The triangles of the narrow face (`NARROW_FACE`): where a marker can lie."""
    t = np.asarray(dataset.triangles, dtype=np.int64)
    return t[(t < NARROW_FACE).all(axis=1)]


def load_landmarks(folder: str | os.PathLike[str]) -> NDArray[np.int64]:
    """The 68 iBUG landmarks' vertices (`vertex_indices.json`, `idx_to_landmark_verts`);
    `InputError` naming the file when it is missing or does not hold them."""
    from lgi.errors import InputError

    p = Path(folder) / "vertex_indices.json"
    try:
        idx = json.loads(p.read_text())["idx_to_landmark_verts"]
        out = np.asarray(idx, dtype=np.int64)
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise InputError(f"{p}: cannot read the iBUG landmark vertices ({e})") from None
    if out.shape != (68,):
        raise InputError(f"{p}: expected 68 landmark vertices, got {out.shape}")
    return out


def is_ict(folder: str | os.PathLike[str]) -> bool:
    """True when `folder` holds the ICT-FaceKit neutral mesh."""
    return (Path(folder) / _NEUTRAL).is_file()


def find(
    shared_data: str | os.PathLike[str] | None = None, start: str | os.PathLike[str] | None = None
) -> Path | None:
    """The ICT-FaceKit folder under `shared_data`, or (None) under the first `shared/data` in
    `start` (default: the working directory) or one of its parents; None when absent."""
    if shared_data is not None:
        d = Path(shared_data) / _FOLDER
        return d if is_ict(d) else None
    here = Path(start if start is not None else Path.cwd()).resolve()
    for p in [here, *here.parents]:
        d = p / "shared" / "data" / _FOLDER
        if is_ict(d):
            return d
    return None


def load_dataset(folder: str | os.PathLike[str]) -> Dataset:
    """The neutral and its shapes (named after the shape files, in sorted order)."""
    d = Path(folder)
    return Dataset.from_obj(d / _NEUTRAL, str(d / "shapes" / "*.obj"))


def load_markers(folder: str | os.PathLike[str]) -> NDArray[np.float64]:
    """The 120 markers' rest positions (120, 3); `InputError` naming the file and line when
    `markers_120.csv` is missing or garbled (`lgi.io.takes.read_layout`)."""
    return load_layout(folder).positions


def load_layout(folder: str | os.PathLike[str]) -> Layout:
    """The 120-marker layout with its names (`m000`...)."""
    return read_layout(Path(folder) / "markers_120.csv")
