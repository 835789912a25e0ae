"""Solved takes as `.npz`: `write_result_npz` / `read_result_npz` (the file `lgi solve -o
x.npz` writes and `lgi export` converts: vertices, residuals, missing markers, the faces, the
rate and units), and `write_sequence_npz` for plain named arrays."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lgi.errors import InputError
from lgi.io.paths import output_file
from lgi.io.topology import Topology, vertex_frames

F64 = NDArray[np.float64]

__all__ = [
    "RESULT_NPZ_KEYS",
    "Result",
    "read_result_npz",
    "write_result_npz",
    "write_sequence_npz",
]


def write_sequence_npz(path: str | os.PathLike[str], **arrays: NDArray[np.generic]) -> None:
    """Writes named arrays (e.g. `vertices` (F, V, 3), `bundle_residuals` (F, B)) to `.npz`."""
    named: dict[str, Any] = dict(arrays)
    np.savez_compressed(output_file(path, "npz output"), **named)


RESULT_NPZ_KEYS = (
    "vertices",
    "bundle_residuals",
    "missing",
    "marker_names",
    "fps",
    "start",
    "units",
    "face_counts",
    "face_indices",
    "uvs",
    "uv_indices",
    "jaw_theta",
)
"""Arrays of a solved take `.npz` (`write_result_npz`): `vertices` (F, V, 3) float32,
`bundle_residuals` (F, B) float, `missing` (F, B) bool, `marker_names` (B,) str, `fps` (NaN
when unknown), `start` (time code of the first frame), `units` ('' when unknown), the faces
(`face_counts`, `face_indices`, and `uvs`/`uv_indices`, empty without UVs), and `jaw_theta`
(F, 3; absent without a jaw)."""


@dataclass(frozen=True)
class Result:
    """A solved take read back (`read_result_npz`)."""

    vertices: NDArray[np.float32]
    bundle_residuals: F64
    missing: NDArray[np.bool_]
    marker_names: list[str]
    fps: float | None
    start: int
    units: str | None
    topology: Topology
    jaw_theta: F64 | None = None


def write_result_npz(
    path: str | os.PathLike[str],
    topo: Topology,
    vertices: Any,
    bundle_residuals: Any,
    missing: Any,
    marker_names: list[str],
    *,
    fps: float | None,
    start: int = 0,
    units: str | None = None,
    jaw_theta: Any | None = None,
) -> Path:
    """Writes a solved take (`RESULT_NPZ_KEYS`) that `read_result_npz` and `lgi export` read."""
    p = output_file(path, "npz output")
    v = vertex_frames(vertices, topo.num_vertices, "write_result_npz")
    arrays: dict[str, Any] = {
        "vertices": v.astype(np.float32),
        "bundle_residuals": np.asarray(bundle_residuals, dtype=np.float64),
        "missing": np.asarray(missing, dtype=bool),
        "marker_names": np.array(marker_names, dtype=str),
        "fps": np.float64(np.nan if fps is None else fps),
        "start": np.int64(start),
        "units": np.str_(units or ""),
        "face_counts": topo.counts,
        "face_indices": topo.indices,
        "uvs": np.zeros((0, 2)) if topo.uvs is None else np.asarray(topo.uvs),
        "uv_indices": np.zeros(0, np.int64) if topo.uv_indices is None else topo.uv_indices,
    }
    if jaw_theta is not None:
        arrays["jaw_theta"] = np.asarray(jaw_theta, dtype=np.float64)
    with open(p, "wb") as fh:  # a file object: numpy would append '.npz' to another suffix
        np.savez_compressed(fh, **arrays)
    return p


def read_result_npz(path: str | os.PathLike[str]) -> Result:
    """Reads a solved take written by `write_result_npz`; `InputError` naming the file and
    the array for anything else."""
    p = os.fspath(path)
    if not os.path.isfile(p):
        raise InputError(f"{p}: no such result file")
    try:
        with np.load(p, allow_pickle=False) as z:
            if not isinstance(z, np.lib.npyio.NpzFile):  # pragma: no cover - .npy given
                raise InputError(f"{p}: not an .npz archive")
            absent = [k for k in RESULT_NPZ_KEYS[:-1] if k not in z.files]
            if absent:
                raise InputError(
                    f"{p}: not a solved take (written by lgi solve -o *.npz): missing {absent}"
                )
            a = {k: z[k] for k in z.files}
    except InputError:
        raise
    except Exception as e:
        raise InputError(f"{p}: not a readable .npz archive: {e}") from None
    v = a["vertices"]
    counts, indices = a["face_counts"].astype(np.int64), a["face_indices"].astype(np.int64)
    if v.ndim != 3 or v.shape[2] != 3:
        raise InputError(f"{p}: 'vertices' must be (F, V, 3), got {v.shape}")
    nv = v.shape[1]
    if counts.sum() != indices.size or (
        indices.size and (indices.min() < 0 or indices.max() >= nv)
    ):
        raise InputError(
            f"{p}: 'face_counts'/'face_indices' do not describe faces of {nv} vertices"
        )
    has_uv = a["uv_indices"].size > 0
    topo = Topology(
        nv,
        counts,
        indices,
        a["uvs"].astype(np.float64) if has_uv else None,
        a["uv_indices"].astype(np.int64) if has_uv else None,
    )
    fps = float(a["fps"])
    units = str(a["units"]) or None
    return Result(
        vertices=v,
        bundle_residuals=a["bundle_residuals"],
        missing=a["missing"],
        marker_names=[str(x) for x in a["marker_names"]],
        fps=fps if np.isfinite(fps) else None,
        start=int(a["start"]),
        units=units,
        topology=topo,
        jaw_theta=a.get("jaw_theta"),
    )
