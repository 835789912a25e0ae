"""Nonlinear in-betweens and combinations: the shapes of `Dataset.augmented(n, method="arap")`.
The recipes (which shapes, which weights, which names) are the core's, the same as the linear
`Dataset.augmented(n)`; each augmented shape interpolates its shapes' per-triangle rotations in
the log and their stretches linearly (`lgi.data.deform.blend`), then a Poisson solve on the neutral
turns the gradients into positions. A rotating part (an eyeball, the lower teeth, a lip
rolling) keeps its size where the linear sum shrinks it (a rotation by angle a, halfway,
scales the linear mesh by cos(a/2) across the axis)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

import lgi._lgi as _lgi
from lgi.data.deform import PoissonMesh, Polar, blend
from lgi.errors import DatasetError

STILL = 1e-6
"""A vertex that no shape moves by more than this fraction of the neutral's diagonal is held
in place by the solve (the back of the head, the upper teeth)."""


def still_vertices(dataset: _lgi.Dataset) -> NDArray[np.bool_]:
    """(V,) True where no shape of `dataset` moves the vertex (by more than `STILL`)."""
    neutral = np.asarray(dataset.neutral)
    diag = float(np.linalg.norm(neutral.max(axis=0) - neutral.min(axis=0)))
    shapes = np.asarray(dataset.shapes)
    if shapes.shape[0] == 0:
        return np.ones(neutral.shape[0], dtype=bool)
    motion = np.sqrt((shapes.astype(np.float64) ** 2).sum(axis=2)).max(axis=0)
    return np.asarray(motion <= STILL * diag)


def arap_shapes(
    dataset: _lgi.Dataset, min_shapes: int, quiet: bool = False
) -> tuple[NDArray[np.float32], list[str]]:
    """The shapes (S', V, 3) and names of `dataset.augmented(min_shapes)`, made by
    rotation-aware interpolation instead of sums (see the module). Originals are copied
    unchanged; deterministic. A progress bar over the new shapes unless `quiet`."""
    from tqdm import tqdm

    if dataset.num_shapes == 0:
        raise DatasetError("cannot augment a dataset without shapes")
    recipes = dataset.augment_recipes(min_shapes)
    neutral = np.asarray(dataset.neutral)
    shapes = np.asarray(dataset.shapes)
    mesh = PoissonMesh(neutral, dataset.triangles, pinned=still_vertices(dataset))
    polars: dict[int, Polar] = {}

    def polar_of(k: int) -> Polar:
        if k not in polars:
            polars[k] = Polar(mesh.gradients(neutral + shapes[k]))
        return polars[k]

    out = np.zeros((len(recipes), neutral.shape[0], 3), dtype=np.float32)
    for i, (_, terms) in enumerate(
        tqdm(recipes, desc="lgi augment (arap)", disable=quiet, leave=False)
    ):
        if len(terms) == 1 and terms[0][1] == 1.0:
            out[i] = shapes[terms[0][0]]
            continue
        linear = neutral + sum(float(w) * shapes[k].astype(np.float64) for k, w in terms)
        grads = blend([(polar_of(k), float(w)) for k, w in terms])
        out[i] = mesh.solve(grads, linear) - neutral
    return out, [n for n, _ in recipes]
