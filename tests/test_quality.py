"""Mesh-quality measures (`lgi.lab.quality`) against closed forms: scaled meshes, the ellipsoid's
volume from any apex, and triangles placed to cross or not."""

from __future__ import annotations

import numpy as np
import pytest

from closed_mesh import ellipsoid
from lgi.lab import quality


def test_scaling_by_s_scales_areas_by_s_squared_and_edges_by_s() -> None:
    x, tris = ellipsoid(8)
    assert np.allclose(quality.area_ratios(x, 1.5 * x, tris), 2.25)
    assert np.allclose(quality.edge_ratios(x, 1.5 * x, tris), 1.5)
    assert len(quality.edges(tris)) == 3 * len(tris) // 2  # closed: each edge in two triangles
    assert not quality.flipped(x, 1.5 * x, tris).any()
    assert quality.flipped(x, x * [1, 1, -1], tris).sum() > 0


def test_cone_volume_of_a_closed_mesh_is_its_volume_from_any_apex() -> None:
    x, tris = ellipsoid(48)
    v = 4 / 3 * np.pi * 3 * 2 * 1
    for apex in ([4.0, 1.0, 0.0], [0.0, 0.0, 0.0], [10.0, -3.0, 2.0]):
        assert quality.cone_volume(x, tris, apex) == pytest.approx(v, rel=5e-3)


def test_crossing_triangles_are_found_and_touching_or_apart_ones_are_not() -> None:
    flat = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]]
    upright = [[0.5, 0.5, -1.0], [0.5, 0.5, 1.0], [0.6, 0.4, 1.0]]  # through flat's interior
    above = [[0.5, 0.5, 0.5], [0.5, 0.5, 1.0], [0.6, 0.4, 1.0]]
    x = np.array(flat + upright + above)
    tris = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8]])
    assert quality.self_intersections(x, tris).tolist() == [[0, 1]]
    # Triangles sharing a vertex are neighbours, never counted.
    fan = np.array([[0, 1, 2], [0, 4, 5]])
    assert len(quality.self_intersections(x, fan)) == 0


def test_a_closed_mesh_has_no_self_intersections_until_pushed_through_itself() -> None:
    x, tris = ellipsoid(12)
    assert len(quality.self_intersections(x, tris)) == 0
    pushed = x.copy()
    top = x[:, 2] > 0.5
    pushed[top, 2] -= 1.8  # the cap goes through the bottom
    assert len(quality.self_intersections(pushed, tris)) > 0
