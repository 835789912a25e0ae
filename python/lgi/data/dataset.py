"""`lgi.Dataset`: a neutral mesh and its shapes. A Python class holding the core's dataset
(`lgi._lgi.Dataset`, `Dataset.core`), the way `lgi.Model` holds the core's model: files the
core reads (OBJ, glTF, bytes) and arrays go through the core, the `.npz` layout is
`lgi.io.npz_dataset`'s and the ARAP in-betweens are `lgi.data.augment`'s. Also the built-in
sample as a dataset and datasets with shapes left out (leave-one-out protocols)."""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

import lgi._lgi as _lgi
from lgi.errors import InputError

_Path = str | os.PathLike[str]


class Dataset:
    """Neutral mesh plus S shapes (per-vertex displacements from the neutral), with triangles,
    optional per-corner UVs and the neutral's source faces. Immutable; cheap to share. Made by
    `from_obj`, `from_gltf`, `from_arrays`, `from_npz` or `from_bytes`; pickles as its
    `to_bytes`."""

    def __init__(self, core: _lgi.Dataset) -> None:
        if not isinstance(core, _lgi.Dataset):
            raise InputError(
                f"Dataset(core) takes an lgi._lgi.Dataset, got {type(core).__name__}; use "
                "Dataset.from_obj, from_gltf, from_arrays, from_npz or from_bytes"
            )
        self._core = core

    @classmethod
    def from_obj(cls, neutral: _Path, shapes: _Path | Sequence[_Path] | None = None) -> Dataset:
        """Loads a neutral OBJ and shape OBJs (same vertex order as the neutral; only their
        `v` lines are read). `shapes` is a glob pattern (str or path; matches are sorted), a
        sequence of paths, or None for no shapes. Shapes are named after their file stems."""
        return cls(_lgi.Dataset.from_obj(neutral, shapes))

    @classmethod
    def from_gltf(cls, path: _Path) -> Dataset:
        """Loads the first mesh of a glTF/GLB file; its morph targets are the shapes."""
        return cls(_lgi.Dataset.from_gltf(path))

    @classmethod
    def from_arrays(
        cls,
        neutral: ArrayLike,
        triangles: ArrayLike,
        shapes: ArrayLike | None = None,
        names: Sequence[str] | None = None,
        uvs: ArrayLike | None = None,
        uv_triangles: ArrayLike | None = None,
    ) -> Dataset:
        """A dataset from arrays: `neutral` (V, 3) float, `triangles` (T, 3) int, `shapes`
        (S, V, 3) float displacements or None, `names` (S strings; default `shape{k}`), `uvs`
        (U, 2) float with `uv_triangles` (T, 3) int indexing it (both or neither). A bad
        argument is an `lgi.InputError` naming it."""
        return cls(_lgi.Dataset.from_arrays(neutral, triangles, shapes, names, uvs, uv_triangles))

    @classmethod
    def from_npz(cls, path: _Path) -> Dataset:
        """Loads an `.npz` archive of the layout `to_npz` writes
        (`lgi.io.npz_dataset.NPZ_KEYS`, read with `allow_pickle=False`)."""
        from lgi.io.npz_dataset import read_npz

        return cls(read_npz(path))

    def to_npz(self, path: _Path) -> None:
        """Writes the dataset as a compressed `.npz` archive with the keys `from_npz` reads
        (numpy appends `.npz` to `path` when it has no such suffix)."""
        from lgi.io.npz_dataset import write_npz

        write_npz(self._core, path)

    def to_bytes(self) -> bytes:
        """The dataset as bytes: the model file's dataset part (neutral, shape names,
        displacements, source polygons) in the model format's framing, magic `LGIDATAS`."""
        return self._core.to_bytes()

    @classmethod
    def from_bytes(cls, data: bytes | bytearray) -> Dataset:
        """A dataset from `to_bytes`'s bytes, with every check of a dataset built from
        arrays; corrupt bytes raise `lgi.ModelFormatError`."""
        return cls(_lgi.Dataset.from_bytes(data))

    def __reduce__(self) -> tuple[Any, tuple[bytes]]:
        # Pickled as its bytes (checked again on load), like `lgi.Model`.
        return (Dataset.from_bytes, (self.to_bytes(),))

    def augmented(
        self, min_shapes: int, method: str | None = None, *, quiet: bool = False
    ) -> Dataset:
        """A new dataset with in-between shapes (`name@0.5`, ...) and pairwise combinations
        added to the shapes (`augment_recipes`), at least `min_shapes` when there are enough
        pairs (the neutral is shared). `method="linear"` (default) sums displacements (the
        core's); `"arap"` interpolates rotations instead (`lgi.data.augment.arap_shapes`, a
        progress bar unless `quiet`)."""
        n = _lgi.check_count(min_shapes, "min_shapes")
        if method is None or method == "linear":
            return Dataset(self._core.augmented(n))
        if method == "arap":
            from lgi.data.augment import arap_shapes

            return with_shapes(self, *arap_shapes(self._core, n, quiet))
        raise InputError(f"method must be 'linear' or 'arap', got {method!r}")

    def augment_recipes(self, min_shapes: int) -> list[tuple[str, list[tuple[int, float]]]]:
        """The recipes of `augmented(min_shapes)`, in its order: `(name, [(shape, weight),
        ...])` per shape of the augmented dataset (originals first, weight 1)."""
        return self._core.augment_recipes(min_shapes)

    def with_polygons(
        self, counts: ArrayLike, vertices: ArrayLike, uvs: ArrayLike | None = None
    ) -> Dataset:
        """A new dataset with the neutral's source faces: `counts` (P,) corners per face (each
        >= 3), `vertices` (sum of counts,) vertex index per corner, `uvs` the UV index per
        corner (required exactly when the dataset has UVs). They must fan-split (corner 0
        with each later edge) into exactly `triangles` and `uv_triangles`; exports then write
        these faces. An `lgi.InputError` names what does not match."""
        return Dataset(self._core.with_polygons(counts, vertices, uvs))

    @property
    def polygons(self) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]] | None:
        """The neutral's source faces when its file had them (OBJ): `(counts, vertices,
        uvs)`, int64 arrays of corners per face (P,), vertex index per corner (sum of counts,)
        and UV index per corner (same length, or empty without UVs); fan-split they give
        `triangles` and `uv_triangles`. None for datasets from arrays, glTF or `.npz`
        without them."""
        return self._core.polygons

    @property
    def num_vertices(self) -> int:
        """Number of vertices V."""
        return self._core.num_vertices

    @property
    def num_shapes(self) -> int:
        """Number of shapes S (the neutral is not counted)."""
        return self._core.num_shapes

    @property
    def names(self) -> list[str]:
        """Shape names (S)."""
        return self._core.names

    @property
    def neutral(self) -> NDArray[np.float64]:
        """Neutral positions, (V, 3) float64."""
        return self._core.neutral

    @property
    def shapes(self) -> NDArray[np.float32]:
        """Shape displacements, (S, V, 3) float32."""
        return self._core.shapes

    @property
    def triangles(self) -> NDArray[np.int64]:
        """Triangles, (T, 3) int64."""
        return self._core.triangles

    @property
    def uvs(self) -> NDArray[np.float64]:
        """UV coordinates, (U, 2) float64."""
        return self._core.uvs

    @property
    def uv_triangles(self) -> NDArray[np.int64]:
        """Per-triangle UV indices, (T, 3) int64 (empty when the mesh has no UVs)."""
        return self._core.uv_triangles

    @property
    def core(self) -> _lgi.Dataset:
        """The core's dataset, what the binding takes (`lgi._lgi.Model.build`, ...)."""
        return self._core

    def __repr__(self) -> str:
        return repr(self._core)


def with_shapes(dataset: Dataset, shapes: Any, names: Sequence[str]) -> Dataset:
    """A dataset with `dataset`'s neutral, topology, UVs and source polygons and new `shapes`
    (S, V, 3) displacements named `names`."""
    has_uv = np.asarray(dataset.uv_triangles).size > 0
    out = Dataset.from_arrays(
        dataset.neutral,
        dataset.triangles,
        shapes,
        names=list(names),
        uvs=dataset.uvs if has_uv else None,
        uv_triangles=dataset.uv_triangles if has_uv else None,
    )
    if dataset.polygons is not None:
        counts, vertices, uvs = dataset.polygons
        out = out.with_polygons(counts, vertices, uvs if has_uv else None)
    return out


def without_shapes(dataset: Dataset, drop: Iterable[int]) -> Dataset:
    """A copy of `dataset` without the shapes at indices `drop` (same neutral, topology, UVs,
    source polygons)."""
    gone = set(drop)
    keep = [i for i in range(dataset.num_shapes) if i not in gone]
    return with_shapes(dataset, np.asarray(dataset.shapes)[keep], [dataset.names[i] for i in keep])
