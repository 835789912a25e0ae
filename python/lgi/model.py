"""`lgi.Model`: build a Local Geometric Indexing model from a dataset and a marker layout, and
solve frames of markers into dense meshes. The heavy lifting is in the Rust core (GIL
released); this layer adds configuration, progress bars and a typed result."""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi import _lgi
from lgi._lgi import Dataset


@dataclass(frozen=True)
class BuildConfig:
    """Build parameters. Distances are relative to the neutral's bounding-box diagonal."""

    surface_tolerance: float = 0.02
    """Markers farther than this from the neutral surface raise `MarkerError`."""
    prune_motion: float = 1e-5
    """Shapes moving a bundle less than this count as the neutral for that bundle."""
    duplicate_distance: float = 1e-7
    """Cloud points closer than this are merged (their shapes become aliases)."""
    tet_neighbours: int = 10
    """Nearest neighbours of each cloud point used to form tets."""
    max_tets: int = 20_000
    """Tets kept per bundle, best quality first."""
    min_quality: float = 0.02
    """Tets below this quality (1 = regular tet) are dropped."""
    max_edge: float = float("inf")
    """Tets with a longer edge are dropped (relative)."""
    containment_eps: float = 1e-9
    """Barycentric tolerance of 'inside a tet'."""
    projection_candidates: int = 8
    """Nearest tets scored when a marker is outside every tet."""
    temporal_weight: float = 1e-6
    """Penalty per shape not shared with the previous frame's choice (relative to diagonal²)."""
    detour_ratio: float = 1.4
    """No weight between a bundle and a vertex whose surface path is this many times longer
    than the straight line (it goes around a hole: the mouth, an eye). inf disables."""


@dataclass(frozen=True)
class Choices:
    """Per frame and bundle: the local geometry each bundle chose."""

    shapes: NDArray[np.int64]
    """(F, B, 4) dataset shape indices; -1 is the neutral (or an unused slot)."""
    weights: NDArray[np.float64]
    """(F, B, 4) convex weights of `shapes` (all 0 for a missing bundle)."""
    tets: NDArray[np.int64]
    """(F, B) tet index in the bundle's index, -1 when none was used."""
    projected: NDArray[np.bool_]
    """(F, B) True when the marker was outside every tet and was projected."""

    @property
    def inside(self) -> NDArray[np.bool_]:
        """(F, B) True when the marker was inside a tet (interpolated exactly)."""
        return ~self.projected


@dataclass(frozen=True)
class SolveResult:
    """Output of `Model.solve`."""

    vertices: NDArray[np.float64]
    """(F, V, 3) reconstructed meshes."""
    bundle_residuals: NDArray[np.float64]
    """(F, B) distance from each marker to the reconstructed surface (0 where missing)."""
    bundle_positions: NDArray[np.float64]
    """(F, B, 3) the markers' surface positions on the result (estimates where missing)."""
    missing: NDArray[np.bool_]
    """(F, B) markers that were NaN in the input."""
    choices: Choices


def _progress_bar(total: int, desc: str, quiet: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="frame", disable=quiet or total < 2, leave=False)


class Model:
    """A built LGI model: immutable; `solve` may be called from several threads."""

    def __init__(self, core: _lgi.Model) -> None:
        self._core = core

    @classmethod
    def build(
        cls,
        dataset: Dataset,
        markers_rest: ArrayLike,
        config: BuildConfig | None = None,
    ) -> Model:
        """Builds the model for `dataset` and marker rest positions `markers_rest` (B, 3)."""
        cfg = dataclasses.asdict(config or BuildConfig())
        return cls(_lgi.Model.build(dataset, markers_rest, cfg))

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Model:
        """Loads a model written by `save`."""
        return cls(_lgi.Model.load(os.fspath(path)))

    def save(self, path: str | os.PathLike[str]) -> None:
        """Writes the model (versioned binary `.lgi` file)."""
        self._core.save(os.fspath(path))

    @property
    def num_bundles(self) -> int:
        return self._core.num_bundles

    @property
    def num_vertices(self) -> int:
        return self._core.num_vertices

    @property
    def diagonal(self) -> float:
        """Bounding-box diagonal of the neutral: the unit of relative tolerances."""
        return self._core.diagonal

    @property
    def dataset(self) -> Dataset:
        return self._core.dataset

    @property
    def markers_rest(self) -> NDArray[np.float64]:
        return self._core.markers_rest

    @property
    def core(self) -> _lgi.Model:
        """The compiled model, for low-level inspection (weights, neighbours, statistics)."""
        return self._core

    def solve(
        self, frames: ArrayLike, *, temporal: bool = True, quiet: bool = False
    ) -> SolveResult:
        """Solves frames (F, B, 3) of marker positions (a single (B, 3) frame gives F = 1).
        NaN rows are missing markers. With `temporal` (a performance), frames are solved in
        order and each prefers the previous frame's choices; `temporal=False` treats frames as
        independent (e.g. one frame per dataset shape) and solves them in parallel."""
        arr = np.asarray(frames)
        if arr.ndim == 2:
            arr = arr[None]
        total = int(arr.shape[0]) if arr.ndim == 3 else 0
        with _progress_bar(total, "lgi solve", quiet) as bar:
            out = self._core.solve(arr, progress=lambda _f: bar.update(1), temporal=temporal)
        return SolveResult(
            vertices=out["vertices"],
            bundle_residuals=out["bundle_residuals"],
            bundle_positions=out["bundle_positions"],
            missing=out["missing"],
            choices=Choices(
                shapes=out["choice_shapes"],
                weights=out["choice_weights"],
                tets=out["choice_tets"],
                projected=out["choice_projected"],
            ),
        )

    def bundle_positions(self, meshes: ArrayLike) -> NDArray[np.float64]:
        """Marker surface positions (F, B, 3) on meshes (F, V, 3) or (V, 3) -> (B, 3)."""
        arr = np.asarray(meshes)
        if arr.ndim == 2:
            return self._core.bundle_positions(arr[None])[0]
        return self._core.bundle_positions(arr)

    def __repr__(self) -> str:
        return f"Model(num_bundles={self.num_bundles}, num_vertices={self.num_vertices})"
