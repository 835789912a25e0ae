"""ARAP in-betweens (`Dataset.augmented(n, method="arap")`) and the Poisson solve under them
(`lgi.data.deform`), against closed forms: a rotated closed mesh keeps its volume, a linear
in-between loses the fraction the closed form says; affine maps are reproduced exactly."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import lgi
from closed_mesh import ellipsoid, rot_z, volume
from lgi.data.deform import PoissonMesh, polar


@pytest.fixture(scope="module")
def turning() -> lgi.Dataset:
    """A dataset whose one shape turns the whole ellipsoid by 90 degrees about z."""
    x, tris = ellipsoid()
    return lgi.Dataset.from_arrays(x, tris, (x @ rot_z(np.pi / 2).T - x)[None], names=["turn"])


def test_arap_inbetweens_of_a_rotation_keep_the_volume_where_linear_loses_the_closed_form(
    turning: lgi.Dataset,
) -> None:
    x0, tris = turning.neutral, turning.triangles
    v0 = volume(x0, tris)
    assert v0 == pytest.approx(4 / 3 * np.pi * 6, rel=0.02)  # the mesh is the ellipsoid
    lin = turning.augmented(4)
    arap = turning.augmented(4, method="arap", quiet=True)
    assert arap.names == lin.names == ["turn", "turn@0.25", "turn@0.5", "turn@0.75"]
    for k, w in [(1, 0.25), (2, 0.5), (3, 0.75)]:
        # Linear: (1-w) x + w R x scales areas across z by |(1-w) + w e^{i 90deg}|^2.
        expected = (1 - w) ** 2 + w**2
        assert volume(x0 + lin.shapes[k], tris) / v0 == pytest.approx(expected, rel=1e-6)
        assert abs(volume(x0 + arap.shapes[k], tris) / v0 - 1) < 0.01
        # And the ARAP in-between is the rotation by w * 90 degrees, up to a translation.
        y = x0 + arap.shapes[k].astype(np.float64)
        rotated = x0 @ rot_z(w * np.pi / 2).T
        assert np.abs((y - y.mean(0)) - (rotated - rotated.mean(0))).max() < 1e-4


def test_arap_keeps_originals_and_is_deterministic(turning: lgi.Dataset) -> None:
    a = turning.augmented(4, method="arap", quiet=True)
    b = turning.augmented(4, method="arap", quiet=True)
    assert np.array_equal(a.shapes, b.shapes)
    assert np.array_equal(a.shapes[0], turning.shapes[0])


def test_arap_inbetween_of_a_translation_is_the_linear_one() -> None:
    x, tris = ellipsoid(8)
    d = lgi.Dataset.from_arrays(x, tris, np.full((1, len(x), 3), [0.5, -1.0, 2.0]), names=["slide"])
    lin, arap = d.augmented(4), d.augmented(4, method="arap", quiet=True)
    assert np.abs(arap.shapes - lin.shapes).max() < 1e-5


def test_arap_holds_vertices_no_shape_moves() -> None:
    x, tris = ellipsoid(12)
    up = np.clip(x[:, 2], 0.0, None)[:, None]  # the top half bends, the bottom is still
    bend = np.stack([up[:, 0] ** 2, np.zeros(len(x)), np.zeros(len(x))], axis=1)
    twist = x @ rot_z(0.8).T - x
    d = lgi.Dataset.from_arrays(x, tris, np.stack([bend, twist * up]), names=["bend", "twist"])
    still = x[:, 2] <= 0
    a = d.augmented(9, method="arap", quiet=True)
    assert a.names == d.augmented(9).names
    assert np.abs(np.asarray(a.shapes)[:, still]).max() == 0.0
    assert np.abs(np.asarray(a.shapes)[2:, ~still]).max() > 0.1


@pytest.mark.parametrize("method", ["ARAP", "", 3, None])
def test_unknown_augment_method_is_an_input_error(turning: lgi.Dataset, method: object) -> None:
    if method is None:  # None is the default, linear
        assert np.array_equal(turning.augmented(2, method=None).shapes, turning.augmented(2).shapes)
        return
    with pytest.raises(lgi.InputError, match="method must be 'linear' or 'arap'"):
        turning.augmented(2, method=method)  # type: ignore[arg-type]


@given(
    st.lists(st.floats(-0.6, 0.6), min_size=9, max_size=9),
    st.lists(st.floats(-5, 5), min_size=3, max_size=3),
)
def test_poisson_solve_reproduces_any_affine_map_of_a_closed_mesh(
    m: list[float], t: list[float]
) -> None:
    x, tris = ellipsoid(6)
    a = np.eye(3) + np.reshape(m, (3, 3))
    if np.linalg.det(a) < 0.05:
        a = np.eye(3) + 0.1 * np.reshape(m, (3, 3))
    target = x @ a.T + t
    mesh = PoissonMesh(x, tris)
    y = mesh.solve(mesh.gradients(target), target)
    assert np.abs(y - target).max() < 1e-8 * (1 + np.abs(target).max())


def test_polar_gives_rotations_and_symmetric_stretches() -> None:
    rng = np.random.default_rng(5)
    f = rng.normal(size=(50, 3, 3))
    r, s = polar(f)
    assert np.allclose(np.einsum("nij,nkj->nik", r, r), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(r), 1.0)
    assert np.allclose(s, np.transpose(s, (0, 2, 1)))
    assert np.allclose(r @ s, f, atol=1e-12)


def test_arap_augmenting_a_dataset_without_shapes_is_a_dataset_error() -> None:
    x, tris = ellipsoid(4)
    with pytest.raises(lgi.DatasetError, match="without shapes"):
        lgi.Dataset.from_arrays(x, tris).augmented(3, method="arap")


def test_augment_recipes_are_the_linear_augmented_shapes(sample_dataset) -> None:  # type: ignore[no-untyped-def]
    n = sample_dataset.num_shapes + 40
    recipes = sample_dataset.augment_recipes(n)
    lin = sample_dataset.augmented(n)
    assert [name for name, _ in recipes] == lin.names
    shapes = np.asarray(sample_dataset.shapes, np.float64)
    for k, (_, terms) in enumerate(recipes):
        expected = sum(w * shapes[i] for i, w in terms)
        assert np.abs(lin.shapes[k] - expected).max() < 1e-5
