"""The dataset `.npz` layout (numpy's format, so read and written here), on the core's dataset:
`lgi.Dataset.from_npz` / `to_npz` wrap `read_npz` / `write_npz`."""

from __future__ import annotations

import os
from typing import Any

import numpy as np

import lgi._lgi as _lgi
from lgi.errors import DatasetError, DatasetFileError, FileWriteError, InputError
from lgi.io.atomic import atomic_path

__all__ = ["NPZ_KEYS", "read_npz", "write_npz"]


NPZ_KEYS = (
    "neutral",
    "triangles",
    "shapes",
    "names",
    "uvs",
    "uv_triangles",
    "polygon_counts",
    "polygon_vertices",
    "polygon_uvs",
)
"""Arrays of the `.npz` layout: `neutral` (V, 3) float and `triangles` (T, 3) int, then the
optional `shapes` (S, V, 3) float displacements, `names` (S,) str, `uvs` (U, 2) float and
`uv_triangles` (T, 3) int (empty `uvs` and `uv_triangles` mean no UVs), and the neutral's
source faces `polygon_counts` (P,), `polygon_vertices` and `polygon_uvs` (one per corner;
empty without UVs), which must fan-split into `triangles` (`Dataset.with_polygons`)."""


def read_npz(path: str | os.PathLike[str]) -> _lgi.Dataset:
    """Loads an `.npz` archive of the `NPZ_KEYS` layout (read with `allow_pickle=False`).
    Errors name the file: `DatasetFileError` when it cannot be read, `DatasetError` when it is
    not an archive or its content is invalid."""
    name = os.fspath(path)
    try:
        npz = np.load(name, allow_pickle=False)
    except OSError as e:
        raise DatasetFileError(f"cannot read {name}: {e}") from e
    except Exception as e:  # garbled archive, pickled data: numpy raises various classes
        raise DatasetError(f"{name}: not a readable .npz archive: {e}") from e
    if not isinstance(npz, np.lib.npyio.NpzFile):
        raise DatasetError(f"{name}: not an .npz archive (a single .npy array?)")
    with npz:
        arrays: dict[str, Any] = {}
        for key in NPZ_KEYS:
            if key in npz.files:
                try:
                    arrays[key] = npz[key]
                except Exception as e:
                    raise DatasetError(f"{name}: array '{key}': {e}") from e
    for key in NPZ_KEYS[:2]:
        if key not in arrays:
            raise DatasetError(f"{name}: missing array '{key}' (the archive has {npz.files})")
    uvs, uv_triangles = arrays.get("uvs"), arrays.get("uv_triangles")
    if (uvs is None or uvs.size == 0) and (uv_triangles is None or uv_triangles.size == 0):
        uvs = uv_triangles = None
    try:
        ds = _lgi.Dataset.from_arrays(
            arrays["neutral"],
            arrays["triangles"],
            arrays.get("shapes"),
            arrays.get("names"),
            uvs,
            uv_triangles,
        )
        if "polygon_counts" in arrays:
            pu = arrays.get("polygon_uvs")
            ds = ds.with_polygons(
                arrays["polygon_counts"],
                arrays.get("polygon_vertices", np.zeros(0, np.int64)),
                None if pu is None or pu.size == 0 else pu,
            )
        return ds
    except InputError as e:
        # Bad content is a fault of the file, not of an argument: re-raise naming the file.
        raise DatasetError(f"{name}: {e}") from e


def write_npz(dataset: _lgi.Dataset, path: str | os.PathLike[str]) -> None:
    """Writes `dataset` as a compressed `.npz` archive of the `NPZ_KEYS` layout (numpy appends
    `.npz` to `path` when it has no such suffix)."""
    name = os.fspath(path)
    if not name.endswith(".npz"):  # numpy's own rule for a file name without the suffix
        name += ".npz"
    polygons: dict[str, Any] = {}
    if dataset.polygons is not None:
        counts, vertices, uvs = dataset.polygons
        polygons = {"polygon_counts": counts, "polygon_vertices": vertices, "polygon_uvs": uvs}
    try:
        with atomic_path(name) as tmp, open(tmp, "wb") as fh:
            _savez(fh, dataset, polygons)
    except OSError as e:
        raise FileWriteError(f"cannot write {name}: {e.strerror or e}") from None


def _savez(fh: Any, dataset: _lgi.Dataset, polygons: dict[str, Any]) -> None:
    np.savez_compressed(
        fh,
        neutral=dataset.neutral,
        triangles=dataset.triangles,
        shapes=dataset.shapes,
        names=np.array(dataset.names).astype("str"),
        uvs=dataset.uvs,
        uv_triangles=dataset.uv_triangles,
        **polygons,
    )
