"""Actor rigs and correctives from a template (paper §7.7): a generic blendshape rig's shapes
and combinations, put on the actor's neutral (directly when the neutrals agree, else by
deformation transfer, Sumner & Popovic 2004), are reduced to their marker positions and
reconstructed with the actor's LGI model. The reconstructions are the actor's shapes; a
combination's reconstruction minus the sum of its shapes' is its corrective (`corrective_A_B`),
which a rig adds at weight w_A * w_B so that the combination looks like the actor's data
rather than a linear sum."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from lgi.data.dataset import Dataset, with_shapes
from lgi.data.deform import PoissonMesh, deformation_gradients
from lgi.errors import DatasetError, InputError
from lgi.io.rig import CORRECTIVE_PREFIX
from lgi.solve.model import Model

F64 = NDArray[np.float64]

__all__ = [
    "CORRECTIVE_PREFIX",
    "SAME_NEUTRAL",
    "actor_rig",
    "combination_meshes",
    "corrective_name",
    "on_actor",
]

SAME_NEUTRAL = 1e-6
"""The template's neutral is the actor's when no vertex differs by more than this fraction of
the actor neutral's bounding-box diagonal; then template shapes are used as they are."""


def corrective_name(combination: Sequence[str]) -> str:
    """The name of a combination's corrective shape: `corrective_A_B`."""
    return CORRECTIVE_PREFIX + "_".join(combination)


def _check_template(actor: Dataset, template: Dataset) -> None:
    if template.num_vertices != actor.num_vertices:
        raise DatasetError(
            f"template: {template.num_vertices} vertices, the actor's model has "
            f"{actor.num_vertices} (the template must have the actor's topology)"
        )
    ta, tt = np.asarray(actor.triangles), np.asarray(template.triangles)
    if ta.shape != tt.shape or not np.array_equal(ta, tt):
        bad = (
            "a different triangle count"
            if ta.shape != tt.shape
            else f"triangle {int(np.flatnonzero((ta != tt).any(axis=1))[0])} differs"
        )
        raise DatasetError(f"template: not the actor's topology ({bad})")
    if template.num_shapes == 0:
        raise DatasetError("template: no shapes")


def _combinations(template: Dataset, combinations: Sequence[Sequence[str]]) -> list[list[int]]:
    index = {n: k for k, n in enumerate(template.names)}
    if isinstance(combinations, str):
        raise InputError("combinations: expected a list of lists of shape names, got a string")
    out = []
    for c, combo in enumerate(combinations):
        if isinstance(combo, str):
            raise InputError(f"combination {c}: expected a list of shape names, got {combo!r}")
        names = list(combo)
        if len(names) < 2 or len(set(names)) != len(names):
            raise InputError(f"combination {c}: {names} must name at least 2 distinct shapes")
        for n in names:
            if n not in index:
                raise InputError(f"combination {c}: the template has no shape {n!r}")
        out.append([index[n] for n in names])
    return out


def combination_meshes(template: Dataset, combinations: Sequence[Sequence[int]]) -> F64:
    """(C, V, 3): the template rig's linear combinations, its neutral plus the sum of the
    combined shapes (each at weight 1)."""
    neutral = np.asarray(template.neutral)
    shapes = np.asarray(template.shapes, dtype=np.float64)
    return np.stack([neutral + shapes[list(c)].sum(axis=0) for c in combinations])


def on_actor(actor: Dataset, template: Dataset, meshes: F64, quiet: bool = True) -> F64:
    """Template meshes (N, V, 3) put on the actor's neutral: the template's displacements
    added when the neutrals agree (`SAME_NEUTRAL`), else deformation transfer (each
    triangle's deformation gradient from the template neutral applied to the actor's
    triangle, then a Poisson solve; vertices no template shape moves stay at the actor's
    neutral)."""
    from tqdm import tqdm

    a0 = np.asarray(actor.neutral)
    t0 = np.asarray(template.neutral)
    diag = float(np.linalg.norm(a0.max(axis=0) - a0.min(axis=0)))
    disp = meshes - t0[None]
    if np.abs(a0 - t0).max() <= SAME_NEUTRAL * diag:
        return np.asarray(a0[None] + disp)
    shapes = np.asarray(template.shapes, dtype=np.float64)
    still = np.sqrt((shapes**2).sum(axis=2)).max(axis=0) <= SAME_NEUTRAL * diag
    mesh = PoissonMesh(a0, actor.triangles, pinned=still)
    out = np.empty_like(meshes)
    for i in tqdm(range(len(meshes)), desc="lgi rig: transfer", disable=quiet, leave=False):
        grads = deformation_gradients(t0, meshes[i], mesh.triangles)
        out[i] = mesh.solve(grads, a0 + disp[i])
    return out


def actor_rig(
    model: Model,
    template: Dataset,
    combinations: Sequence[Sequence[str]] = (),
    *,
    marker_noise: float | None = None,
    quiet: bool = False,
) -> Dataset:
    """The actor's rig from a generic `template` (a `Dataset` with the actor's topology):
    every template shape and every combination (a list of template shape names, each at
    weight 1) on the actor's neutral (`on_actor`), its markers (`Model.bundle_positions`)
    solved by the actor's `model` as independent frames (`marker_noise` as in
    `Model.solve`). Returns a dataset on the actor's neutral (the model's dataset's
    topology, UVs and polygons) with the reconstructed template shapes, named as in the
    template, then per combination its corrective (`corrective_name`): the combination's
    reconstruction minus the sum of its shapes' reconstructions. A progress bar unless
    `quiet`."""
    if not isinstance(model, Model):
        raise InputError(f"model: expected an lgi.Model, got {type(model).__name__}")
    if not isinstance(template, Dataset):
        raise InputError(f"template: expected an lgi.Dataset, got {type(template).__name__}")
    actor = model.dataset
    _check_template(actor, template)
    combos = _combinations(template, combinations)
    t0 = np.asarray(template.neutral)
    meshes = np.concatenate(
        [
            t0[None] + np.asarray(template.shapes, dtype=np.float64),
            combination_meshes(template, combos) if combos else np.zeros((0, *t0.shape)),
        ]
    )
    targets = on_actor(actor, template, meshes, quiet=quiet)
    frames = model.bundle_positions(targets)
    res = model.solve(frames, temporal=False, quiet=quiet, marker_noise=marker_noise)
    disp = np.asarray(res.vertices) - np.asarray(actor.neutral)[None]
    s = template.num_shapes
    shapes = [disp[k] for k in range(s)]
    correctives = [disp[s + i] - disp[c].sum(axis=0) for i, c in enumerate(combos)]
    names = list(template.names) + [corrective_name([template.names[k] for k in c]) for c in combos]
    return with_shapes(actor, np.stack(shapes + correctives).astype(np.float32), names)
