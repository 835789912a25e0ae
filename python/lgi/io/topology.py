"""The faces an exported mesh carries, shared by every writer of solved frames: the neutral's own
source polygons (quads and n-gons as its OBJ had them, `Dataset.polygons`) with their UVs, or
its triangles when the dataset has none (arrays, glTF, `.npz`); and the one check of the
vertex frames a writer is given."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from lgi.errors import InputError

if TYPE_CHECKING:
    from lgi.data.dataset import Dataset

I64 = NDArray[np.int64]
F64 = NDArray[np.float64]

__all__ = ["Topology", "topology", "vertex_frames"]


@dataclass(frozen=True)
class Topology:
    """Faces of the exported mesh: `counts` (P,) corners per face, `indices` (sum counts,)
    vertex per corner, and optionally `uvs` (U, 2) with `uv_indices` (one per corner)."""

    num_vertices: int
    counts: I64
    indices: I64
    uvs: F64 | None = None
    uv_indices: I64 | None = None

    @property
    def num_faces(self) -> int:
        return int(self.counts.shape[0])

    def triangles(self) -> I64:
        """(T, 3) the faces fan-split into triangles (corner 0 with each pair of neighbours),
        grouped by fan position: every face's first triangle, then every second, ..."""
        starts = np.concatenate([[0], np.cumsum(self.counts)[:-1]]).astype(np.int64)
        out = []
        for k in range(1, int(self.counts.max(initial=3)) - 1):
            s = starts[self.counts > k + 1]
            out.append(np.stack([self.indices[s], self.indices[s + k], self.indices[s + k + 1]], 1))
        return np.concatenate(out).astype(np.int64) if out else np.zeros((0, 3), np.int64)


def topology(dataset: Dataset) -> Topology:
    """The dataset neutral's source polygons (or its triangles when it has none) and UVs."""
    polys = dataset.polygons
    has_uv = np.asarray(dataset.uv_triangles).size > 0
    if polys is not None:
        counts, indices, uv_idx = polys
        return Topology(
            dataset.num_vertices,
            counts,
            indices,
            dataset.uvs if has_uv else None,
            uv_idx if has_uv else None,
        )
    tris = np.asarray(dataset.triangles, dtype=np.int64)
    return Topology(
        dataset.num_vertices,
        np.full(tris.shape[0], 3, dtype=np.int64),
        tris.ravel(),
        dataset.uvs if has_uv else None,
        np.asarray(dataset.uv_triangles, dtype=np.int64).ravel() if has_uv else None,
    )


def vertex_frames(vertices: Any, num_vertices: int, what: str) -> NDArray[np.floating[Any]]:
    """`vertices` as (F, V, 3) floats (a (V, 3) mesh gives F = 1), checked finite."""
    v = np.asarray(vertices)
    if v.ndim == 2:
        v = v[None]
    if v.ndim != 3 or v.shape[1:] != (num_vertices, 3) or v.dtype.kind != "f":
        raise InputError(
            f"{what}: expected float vertices (F, {num_vertices}, 3), got {v.dtype} {v.shape}"
        )
    if not np.isfinite(v).all():
        raise InputError(f"{what}: vertices are not all finite")
    return v
