"""OBJ out: a sequence of OBJs, one per solved frame, with the neutral's source polygons and UVs
(`write_obj_sequence`), and single triangle meshes (`write_obj`)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from lgi.errors import InputError
from lgi.io.atomic import atomic_path
from lgi.io.paths import output_file
from lgi.io.topology import Topology, topology, vertex_frames

if TYPE_CHECKING:
    from lgi.data.dataset import Dataset

__all__ = ["write_obj", "write_obj_sequence"]


def _face_lines(topo: Topology) -> str:
    """The `vt` and `f` lines of `topo` (1-based), the same for every frame."""
    ends = np.cumsum(topo.counts)
    starts = ends - topo.counts
    idx = (topo.indices + 1).astype(str)
    lines: list[str] = []
    if topo.uvs is not None and topo.uv_indices is not None:
        lines += [f"vt {a:.9g} {b:.9g}" for a, b in np.asarray(topo.uvs)]
        uvi = (topo.uv_indices + 1).astype(str)
        corners = np.char.add(np.char.add(idx, "/"), uvi)
    else:
        corners = idx
    lines += ["f " + " ".join(corners[s:e]) for s, e in zip(starts, ends, strict=True)]
    return "\n".join(lines) + "\n"


def write_obj_sequence(
    folder: str | os.PathLike[str],
    topo: Topology | Dataset,
    vertices: Any,
    *,
    name: str = "frame",
    start: int = 0,
    digits: int = 4,
) -> list[Path]:
    """Writes one OBJ per frame into `folder` (created), `{name}.{frame:0{digits}d}.obj` from
    frame `start`, each with the source polygons and UVs; returns the paths."""
    t = topo if isinstance(topo, Topology) else topology(topo)
    v = vertex_frames(vertices, t.num_vertices, "write_obj_sequence")
    out = Path(folder)
    if out.exists() and not out.is_dir():
        raise InputError(f"OBJ sequence output {out}: is a file, expected a folder")
    out.mkdir(parents=True, exist_ok=True)
    faces = _face_lines(t)
    template = "v %.9g %.9g %.9g\n" * t.num_vertices
    paths = []
    for i in range(v.shape[0]):
        p = out / f"{name}.{start + i:0{digits}d}.obj"
        with atomic_path(p) as tmp:
            tmp.write_text("# written by lgi\n" + template % tuple(v[i].ravel().tolist()) + faces)
        paths.append(p)
    return paths


def write_obj(
    path: str | os.PathLike[str],
    vertices: NDArray[np.float64],
    triangles: NDArray[np.int64],
    uvs: NDArray[np.float64] | None = None,
    uv_triangles: NDArray[np.int64] | None = None,
) -> None:
    """Writes one triangle mesh as OBJ (`v`, optional `vt`, `f v/vt`), 1-based indices."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64) + 1
    lines = ["# written by lgi", *(f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in v)]
    if uvs is not None and uv_triangles is not None and len(uv_triangles) == len(t):
        lines += (f"vt {a:.9g} {b:.9g}" for a, b in np.asarray(uvs))
        ut = np.asarray(uv_triangles, dtype=np.int64) + 1
        lines += (f"f {a}/{d} {b}/{e} {c}/{f}" for (a, b, c), (d, e, f) in zip(t, ut, strict=True))
    else:
        lines += (f"f {a} {b} {c}" for a, b, c in t)
    with atomic_path(output_file(path, "OBJ output")) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
