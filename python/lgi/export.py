"""Writing results: meshes as OBJ (with the neutral's UVs) and sequences as `.npz`."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray


def write_obj(
    path: str | os.PathLike[str],
    vertices: NDArray[np.float64],
    triangles: NDArray[np.int64],
    uvs: NDArray[np.float64] | None = None,
    uv_triangles: NDArray[np.int64] | None = None,
) -> None:
    """Writes one mesh as OBJ (`v`, optional `vt`, `f v/vt`), 1-based indices."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64) + 1
    lines = ["# written by lgi", *(f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in v)]
    if uvs is not None and uv_triangles is not None and len(uv_triangles) == len(t):
        lines += (f"vt {a:.9g} {b:.9g}" for a, b in np.asarray(uvs))
        ut = np.asarray(uv_triangles, dtype=np.int64) + 1
        lines += (f"f {a}/{d} {b}/{e} {c}/{f}" for (a, b, c), (d, e, f) in zip(t, ut, strict=True))
    else:
        lines += (f"f {a} {b} {c}" for a, b, c in t)
    Path(path).write_text("\n".join(lines) + "\n")


def write_sequence_npz(path: str | os.PathLike[str], **arrays: NDArray[np.generic]) -> None:
    """Writes named arrays (e.g. `vertices` (F, V, 3), `bundle_residuals` (F, B)) to `.npz`."""
    named: dict[str, Any] = dict(arrays)
    np.savez_compressed(Path(path), **named)
