"""Actor rigs from a template (`lgi.solve.rig.actor_rig`, paper §7.7): with the actor's own shapes
as the template the rig reproduces them on observed skin (the verification notion of
test_model_ict.py), correctives vanish for combinations the dataset holds, deformation transfer
from a moved copy of the template gives the same rig, and bad templates are clear errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

import lgi
from closed_mesh import ellipsoid, rot_z
from lgi.data.dataset import with_shapes
from lgi.lab import ict
from lgi.solve import rig


def observed(model: lgi.Model, meshes: np.ndarray) -> np.ndarray:
    """(F, V): vertices all of whose natural-neighbour bundles move (> 1e-3) on each mesh:
    where a reconstruction from markers alone is determined."""
    w = model.core.sew_weights()
    nbrs = sparse.csr_matrix(
        (np.ones(len(w["indices"])), w["indices"], w["indptr"]),
        shape=(model.num_vertices, model.num_bundles),
    )
    rest = model.bundle_positions(model.dataset.neutral)
    moved = np.linalg.norm(model.bundle_positions(meshes) - rest[None], axis=2) > 1e-3
    return np.asarray((nbrs @ (~moved).T.astype(float)) == 0).T


def test_rig_from_the_actors_own_shapes_reproduces_them_on_observed_ict_skin(
    ict_dataset, ict_model
) -> None:  # type: ignore[no-untyped-def]
    out = rig.actor_rig(ict_model, ict_dataset, quiet=True)
    assert out.names == ict_dataset.names
    truth = np.asarray(ict_dataset.shapes, dtype=np.float64)
    obs = observed(ict_model, ict_dataset.neutral[None] + truth)[:, : ict.SKIN_VERTICES]
    err = np.linalg.norm(np.asarray(out.shapes, np.float64) - truth, axis=2)[:, : ict.SKIN_VERTICES]
    assert obs.sum() > 0.3 * obs.size
    assert err[obs].max() <= 1e-4


def test_corrective_of_a_combination_the_ict_dataset_holds_is_zero(
    ict_dataset, ict_markers
) -> None:  # type: ignore[no-untyped-def]
    names = ict_dataset.names
    a, b = names.index("mouthSmile_L"), names.index("cheekSquint_L")
    shapes = np.asarray(ict_dataset.shapes)
    held = with_shapes(
        ict_dataset,
        np.concatenate([shapes, (shapes[a] + shapes[b])[None]]),
        [*names, "smile_squint"],
    )
    model = lgi.Model.build(held, ict_markers, jaw=None)
    combos = [["mouthSmile_L", "cheekSquint_L"], ["mouthSmile_L", "jawOpen"]]
    out = rig.actor_rig(model, ict_dataset, combos, quiet=True)
    assert out.names[-2:] == [
        "corrective_mouthSmile_L_cheekSquint_L",
        "corrective_mouthSmile_L_jawOpen",
    ]
    meshes = ict_dataset.neutral[None] + np.stack([shapes[a], shapes[b], shapes[a] + shapes[b]])
    obs = observed(model, meshes.astype(np.float64)).all(axis=0)[: ict.SKIN_VERTICES]
    held_c = np.linalg.norm(np.asarray(out.shapes[-2], np.float64), axis=1)[: ict.SKIN_VERTICES]
    assert held_c[obs].max() <= 1e-4
    # A combination the dataset does not hold gets a corrective that is not zero.
    assert np.linalg.norm(out.shapes[-1], axis=1).max() > 0.1


def test_transfer_from_a_translated_template_is_exact(sample_dataset) -> None:  # type: ignore[no-untyped-def]
    moved = lgi.Dataset.from_arrays(
        sample_dataset.neutral + np.array([3.0, -2.0, 5.0]),
        sample_dataset.triangles,
        sample_dataset.shapes,
        names=sample_dataset.names,
    )
    meshes = np.concatenate(
        [
            moved.neutral[None] + np.asarray(moved.shapes, np.float64),
            rig.combination_meshes(moved, [[0, 4], [1, 2, 3]]),
        ]
    )
    on = rig.on_actor(sample_dataset, moved, meshes)
    truth = np.concatenate(
        [
            sample_dataset.neutral[None] + np.asarray(sample_dataset.shapes, np.float64),
            rig.combination_meshes(sample_dataset, [[0, 4], [1, 2, 3]]),
        ]
    )
    assert np.abs(on - truth).max() < 1e-8  # gradients do not see a translation


def test_transfer_of_a_rotation_onto_another_neutral_is_that_rotation() -> None:
    """Deformation transfer of a rigid turn of the whole template (gradient R on every
    triangle) onto a different neutral of the same topology is the turn of that neutral."""
    x, tris = ellipsoid(10)
    rng = np.random.default_rng(2)
    template_neutral = x * [1.3, 0.8, 1.1] + rng.normal(scale=0.02, size=x.shape)
    turn = template_neutral @ rot_z(0.5).T - template_neutral
    actor = lgi.Dataset.from_arrays(x, tris)
    template = lgi.Dataset.from_arrays(template_neutral, tris, turn[None], names=["turn"])
    y = rig.on_actor(actor, template, template_neutral[None] + turn[None])[0]
    expected = x @ rot_z(0.5).T
    assert np.abs((y - y.mean(0)) - (expected - expected.mean(0))).max() < 1e-8


def test_correctives_are_reconstruction_minus_the_sum_of_the_shapes(
    sample_dataset, sample_model
) -> None:  # type: ignore[no-untyped-def]
    names = sample_dataset.names
    combo = [names[0], names[5], names[9]]
    out = rig.actor_rig(sample_model, sample_dataset, [combo], quiet=True)
    k = [names.index(n) for n in combo]
    mesh = sample_dataset.neutral + np.asarray(sample_dataset.shapes, np.float64)[k].sum(axis=0)
    rec = sample_model.solve(sample_model.bundle_positions(mesh), temporal=False, quiet=True)
    expected = (
        rec.vertices[0] - sample_dataset.neutral - np.asarray(out.shapes, np.float64)[k].sum(0)
    )
    assert out.names[-1] == rig.corrective_name(combo)
    assert np.abs(out.shapes[-1] - expected).max() < 1e-5
    assert np.array_equal(out.neutral, sample_dataset.neutral)


@pytest.mark.parametrize(
    ("combos", "match"),
    [
        ([["jawOpen"]], "combination 0: .* at least 2 distinct"),
        ([["jawOpen", "jawOpen"]], "combination 0: .* at least 2 distinct"),
        ([["jawOpen", "nope"]], "combination 0: the template has no shape 'nope'"),
        ("jawOpen", "got a string"),
        ([["jawOpen", "mouthClose"], "mouthClose"], "combination 1: expected a list"),
    ],
)
def test_bad_combinations_are_input_errors_naming_them(
    sample_dataset, sample_model, combos: object, match: str
) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(lgi.InputError, match=match):
        rig.actor_rig(sample_model, sample_dataset, combos, quiet=True)  # type: ignore[arg-type]


def test_template_of_another_topology_is_a_dataset_error(sample_dataset, sample_model) -> None:  # type: ignore[no-untyped-def]
    tris = np.asarray(sample_dataset.triangles).copy()
    tris[7] = tris[7, [0, 2, 1]]
    other = lgi.Dataset.from_arrays(sample_dataset.neutral, tris, sample_dataset.shapes)
    with pytest.raises(lgi.DatasetError, match="triangle 7 differs"):
        rig.actor_rig(sample_model, other, quiet=True)
    x = np.zeros((4, 3)) + np.eye(4, 3)
    small = lgi.Dataset.from_arrays(x, [[0, 1, 2], [0, 2, 3]], np.zeros((1, 4, 3)))
    with pytest.raises(lgi.DatasetError, match="template: 4 vertices"):
        rig.actor_rig(sample_model, small, quiet=True)
