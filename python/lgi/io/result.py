"""Solved takes as `.npz`: `write_result_npz` / `read_result_npz` (the file `lgi solve -o
x.npz` writes and `lgi export` converts: vertices, residuals, missing markers, the faces, the
rate and units), and `write_sequence_npz` for plain named arrays."""

from __future__ import annotations

import os
import threading
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lgi.errors import InputError
from lgi.io.atomic import atomic_path
from lgi.io.paths import output_file
from lgi.io.settings import SolveSettings
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
    with atomic_path(output_file(path, "npz output")) as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, **named)


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
    "markers",
    "solve_settings",
)
"""Arrays of a solved take `.npz` (`write_result_npz`): `vertices` (F, V, 3) float32,
`bundle_residuals` (F, B) float, `missing` (F, B) bool, `marker_names` (B,) str, `fps` (NaN
when unknown), `start` (time code of the first frame), `units` ('' when unknown), the faces
(`face_counts`, `face_indices`, and `uvs`/`uv_indices`, empty without UVs), and `jaw_theta`
(F, 3; absent without a jaw), and `markers` (F, B, 3) float32, the take's marker positions
in the model's units, NaN where missing (absent in files written before it was kept; `lgi
view` draws them), and `solve_settings`, how the take was solved (`SolveSettings` as JSON
text; absent in files written before it was kept)."""

_OPTIONAL_KEYS = ("jaw_theta", "markers", "solve_settings")


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
    markers: NDArray[np.float32] | None = None
    settings: SolveSettings | None = None


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
    markers: Any | None = None,
    settings: SolveSettings | None = None,
) -> Path:
    """Writes a solved take (`RESULT_NPZ_KEYS`) that `read_result_npz` and `lgi export` read.
    `vertices`: (F, V, 3), or a list of such chunks in order (`lgi solve`'s, written one after
    another into the file: no whole-take copy is made)."""
    p = output_file(path, "npz output")
    chunks = list(vertices) if isinstance(vertices, list) else [vertices]
    frames = [vertex_frames(c, topo.num_vertices, "write_result_npz") for c in chunks]
    count = sum(int(c.shape[0]) for c in frames)
    arrays: dict[str, Any] = {
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
    if markers is not None:
        mk = np.asarray(markers, dtype=np.float32)
        if mk.shape != (count, len(marker_names), 3):
            raise InputError(
                f"write_result_npz: markers must be (F, B, 3) = ({count}, "
                f"{len(marker_names)}, 3), got {mk.shape}"
            )
        arrays["markers"] = mk
    if settings is not None:
        arrays["solve_settings"] = np.str_(settings.to_json())
    # The layout np.savez writes (a zip of .npy members, vertices first), stored, not deflated:
    # deflate saves about a tenth of a solve's size at several times the write's time
    # (docs/performance.md), and stored members still read in order (`stream_result_npz`).
    # The vertices go in chunk by chunk as float32, each chunk converted on its own.
    header = {
        "descr": np.lib.format.dtype_to_descr(np.dtype("<f4")),
        "fortran_order": False,
        "shape": (count, topo.num_vertices, 3),
    }
    with atomic_path(p) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_STORED) as zf:
        with zf.open("vertices.npy", "w", force_zip64=True) as fh:
            np.lib.format.write_array_header_1_0(fh, header)
            for c in frames:
                fh.write(np.ascontiguousarray(c, dtype="<f4").data)
        for name, value in arrays.items():
            with zf.open(f"{name}.npy", "w", force_zip64=True) as fh:
                np.lib.format.write_array(fh, np.asanyarray(value), allow_pickle=False)
    return p


def read_result_npz(path: str | os.PathLike[str]) -> Result:
    """Reads a solved take written by `write_result_npz`; `InputError` naming the file and
    the array for anything else."""
    p = _existing(path)
    a = _arrays(p, with_vertices=True)
    return _assemble(p, a, a["vertices"])


def stream_result_npz(path: str | os.PathLike[str]) -> tuple[Result, Callable[[int], None]]:
    """A solved take whose `vertices` are still being read: the small arrays are read at once,
    the frames are read in order by a background thread into the returned array, and
    `wait(stop)` returns once frames `0..stop-1` are in (raising `InputError` if the file
    turns out damaged). `lgi view` shows the first frame of a 1,500-frame take this way
    without waiting for all of it."""
    p = _existing(path)
    a = _arrays(p, with_vertices=False)
    try:
        zf = zipfile.ZipFile(p)
        fh: Any = zf.open("vertices.npy")
        version = np.lib.format.read_magic(fh)
        header = (
            np.lib.format.read_array_header_1_0
            if version == (1, 0)
            else np.lib.format.read_array_header_2_0
        )
        shape, fortran, dtype = header(fh)
    except Exception as e:
        raise InputError(f"{p}: not a readable .npz archive: {e}") from None
    if fortran or dtype != np.dtype("<f4") or len(shape) != 3:
        zf.close()
        raise InputError(f"{p}: 'vertices' must be C-ordered float32 (F, V, 3)")
    v = np.zeros(shape, dtype=np.float32)
    frame_bytes = int(np.prod(shape[1:])) * 4
    state = threading.Condition()
    done = [0]
    failure: list[str] = []

    def fill() -> None:
        raw = v.reshape(-1).view(np.uint8)
        try:
            with zf, fh:
                step = max(frame_bytes * 8, 1 << 20)
                for at in range(0, len(raw), step):
                    block = raw[at : at + step]
                    got = 0
                    while got < len(block):
                        n = fh.readinto(block[got:])
                        if not n:
                            raise EOFError("the vertices end early")
                        got += n
                    with state:
                        done[0] = (at + len(block)) // frame_bytes
                        state.notify_all()
        except Exception as e:
            with state:
                failure.append(str(e))
                state.notify_all()

    threading.Thread(target=fill, daemon=True).start()

    def wait(stop: int) -> None:
        with state:
            state.wait_for(lambda: done[0] >= min(stop, shape[0]) or bool(failure))
            if failure:
                raise InputError(f"{p}: cannot read 'vertices': {failure[0]}")

    return _assemble(p, a, v), wait


def _existing(path: str | os.PathLike[str]) -> str:
    p = os.fspath(path)
    if not os.path.isfile(p):
        raise InputError(f"{p}: no such result file")
    return p


def _arrays(p: str, *, with_vertices: bool) -> dict[str, Any]:
    try:
        with np.load(p, allow_pickle=False) as z:
            if not isinstance(z, np.lib.npyio.NpzFile):  # pragma: no cover - .npy given
                raise InputError(f"{p}: not an .npz archive")
            absent = [k for k in RESULT_NPZ_KEYS if k not in _OPTIONAL_KEYS and k not in z.files]
            if absent:
                raise InputError(
                    f"{p}: not a solved take (written by lgi solve -o *.npz): missing {absent}"
                )
            return {k: z[k] for k in z.files if with_vertices or k != "vertices"}
    except InputError:
        raise
    except Exception as e:
        raise InputError(f"{p}: not a readable .npz archive: {e}") from None


def _assemble(p: str, a: dict[str, Any], v: Any) -> Result:
    """The `Result` of the arrays `a` with vertices `v`, checked."""
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
        markers=_markers(p, a.get("markers"), v.shape[0], len(a["marker_names"])),
        settings=(
            None
            if "solve_settings" not in a
            else SolveSettings.from_json(str(a["solve_settings"]), f"{p}: 'solve_settings'")
        ),
    )


def _markers(p: str, m: Any, frames: int, count: int) -> NDArray[np.float32] | None:
    if m is None:
        return None
    if m.shape != (frames, count, 3):
        raise InputError(f"{p}: 'markers' must be ({frames}, {count}, 3), got {m.shape}")
    return np.asarray(m, dtype=np.float32)
