"""Dataset tooling on top of `lgi.Dataset`: the built-in sample as a dataset, and datasets with
shapes left out (leave-one-out protocols)."""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np

from lgi._lgi import Dataset

if TYPE_CHECKING:
    from lgi.sample import Sample


def sample_dataset(sample: Sample) -> Dataset:
    """The dataset of a generated sample (`lgi.sample.make_sample`): neutral, UVs and shapes."""
    return Dataset.from_arrays(
        sample.neutral,
        sample.triangles,
        sample.shapes,
        names=sample.names,
        uvs=sample.uvs,
        uv_triangles=sample.uv_triangles,
    )


def without_shapes(dataset: Dataset, drop: Iterable[int]) -> Dataset:
    """A copy of `dataset` without the shapes at indices `drop` (same neutral, topology, UVs)."""
    gone = set(drop)
    keep = [i for i in range(dataset.num_shapes) if i not in gone]
    has_uv = np.asarray(dataset.uv_triangles).size > 0
    return Dataset.from_arrays(
        dataset.neutral,
        dataset.triangles,
        np.asarray(dataset.shapes)[keep],
        names=[dataset.names[i] for i in keep],
        uvs=dataset.uvs if has_uv else None,
        uv_triangles=dataset.uv_triangles if has_uv else None,
    )
