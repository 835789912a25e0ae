"""Results out (`lgi.io.usd`, `lgi.io.obj`, `lgi.io.result`): USD point caches read back with
pxr (faces are the source polygons, UVs the indexed face-varying `st`, samples at frame time
codes, stage metadata), chunked writing identical to one call, OBJ sequences read back by the
core's OBJ reader, and solved-take `.npz` round trips."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pxr import Usd, UsdGeom

import lgi
from lgi import InputError
from lgi.io import obj, result, usd
from lgi.io.topology import topology

QUAD_GRID = """v 0 0 0
v 1 0 0
v 2 0 0
v 0 1 0
v 1 1 0
v 2 1 0
v 1 2 0
vt 0 0
vt 0.5 0
vt 1 0
vt 0 0.5
vt 0.5 0.5
vt 1 0.5
vt 0.5 1
f 1/1 2/2 5/5 4/4
f 2/2 3/3 6/6 5/5
f 4/4 5/5 7/7
"""


@pytest.fixture()
def quads(tmp_path: Path) -> lgi.Dataset:
    p = tmp_path / "grid.obj"
    p.write_text(QUAD_GRID)
    return lgi.Dataset.from_obj(p)


def frames(n: int, v: int) -> np.ndarray:
    return np.random.default_rng(3).normal(size=(n, v, 3))


def test_topology_of_an_obj_neutral_is_its_quads_and_triangle_and_uv_corners(quads) -> None:  # type: ignore[no-untyped-def]
    t = topology(quads)
    np.testing.assert_array_equal(t.counts, [4, 4, 3])
    np.testing.assert_array_equal(t.indices, [0, 1, 4, 3, 1, 2, 5, 4, 3, 4, 6])
    np.testing.assert_array_equal(t.uv_indices, t.indices)  # this file's vt follow its v
    assert np.asarray(quads.triangles).shape == (5, 3)


def test_usd_cache_reads_back_with_pxr(quads, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    v = frames(3, 7)
    path = usd.write_usd(tmp_path / "c.usda", quads, v, fps=24.0, units="mm", start=101)
    stage = Usd.Stage.Open(str(path))
    assert stage.GetTimeCodesPerSecond() == 24.0
    assert stage.GetStartTimeCode() == 101 and stage.GetEndTimeCode() == 103
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(1e-3)
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert stage.GetDefaultPrim().GetPath() == "/Face"
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh"))
    assert list(mesh.GetFaceVertexCountsAttr().Get()) == [4, 4, 3]
    assert list(mesh.GetFaceVertexIndicesAttr().Get()) == [0, 1, 4, 3, 1, 2, 5, 4, 3, 4, 6]
    st = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st")
    assert st.GetInterpolation() == UsdGeom.Tokens.faceVarying
    flat = np.array(st.ComputeFlattened())
    np.testing.assert_allclose(flat[2], [0.5, 0.5])  # corner 2 of face 0 is vt 5
    pts = mesh.GetPointsAttr()
    assert pts.GetTimeSamples() == [101.0, 102.0, 103.0]
    for f in range(3):
        np.testing.assert_array_equal(np.array(pts.Get(101 + f)), v[f].astype(np.float32))
        ext = np.array(mesh.GetExtentAttr().Get(101 + f))
        np.testing.assert_allclose(ext, [v[f].min(0), v[f].max(0)], rtol=1e-6)


def test_chunked_usd_writing_equals_one_call_and_keeps_jaw_and_residual_attributes(
    quads, tmp_path: Path
) -> None:  # type: ignore[no-untyped-def]
    v = frames(5, 7)
    jaw = np.random.default_rng(1).normal(size=(5, 3))
    res = np.abs(np.random.default_rng(2).normal(size=(5, 4)))
    one = usd.write_usd(tmp_path / "one.usda", quads, v, fps=30.0)
    cache = usd.UsdCache(tmp_path / "chunks.usda", topology(quads), fps=30.0)
    for a, b in [(0, 2), (2, 3), (3, 5)]:
        cache.add(v[a:b], jaw_theta=jaw[a:b], marker_residuals=res[a:b])
    cache.close()
    s1, s2 = Usd.Stage.Open(str(one)), Usd.Stage.Open(str(tmp_path / "chunks.usda"))
    p1 = UsdGeom.Mesh(s1.GetPrimAtPath("/Face/Mesh")).GetPointsAttr()
    prim = s2.GetPrimAtPath("/Face/Mesh")
    p2 = UsdGeom.Mesh(prim).GetPointsAttr()
    assert p1.GetTimeSamples() == p2.GetTimeSamples() == [0.0, 1.0, 2.0, 3.0, 4.0]
    for t in range(5):
        np.testing.assert_array_equal(np.array(p1.Get(t)), np.array(p2.Get(t)))
        np.testing.assert_allclose(
            np.array(prim.GetAttribute("lgi:jawTheta").Get(t)), jaw[t], rtol=1e-6
        )
        np.testing.assert_allclose(
            np.array(prim.GetAttribute("lgi:markerResidual").Get(t)), res[t], rtol=1e-6
        )
    # Units not given: no metersPerUnit authored.
    assert not s1.HasAuthoredMetadata("metersPerUnit")


def test_usd_cache_keeps_the_head_transform_per_frame_and_refuses_half_of_one(
    quads, tmp_path: Path
) -> None:  # type: ignore[no-untyped-def]
    from scipy.spatial.transform import Rotation

    v = frames(4, 7)
    rot = Rotation.from_rotvec(np.random.default_rng(3).normal(0, 0.1, (4, 3))).as_matrix()
    shift = np.random.default_rng(4).normal(size=(4, 3))
    cache = usd.UsdCache(tmp_path / "head.usda", topology(quads), fps=24.0)
    cache.add(v, head_rotations=rot, head_translations=shift)
    cache.close()
    stage = Usd.Stage.Open(str(tmp_path / "head.usda"))
    prim = stage.GetPrimAtPath("/Face/Mesh")
    for t in range(4):
        got = np.array(prim.GetAttribute("lgi:headRotation").Get(t))
        np.testing.assert_allclose(got, rot[t], rtol=0, atol=1e-15)
        np.testing.assert_allclose(
            np.array(prim.GetAttribute("lgi:headTranslation").Get(t)), shift[t], atol=1e-15
        )
    other = usd.UsdCache(tmp_path / "half.usda", topology(quads), fps=24.0)
    with pytest.raises(lgi.InputError, match=r"rotations .* and translations .* together"):
        other.add(v, head_rotations=rot)


def test_a_dataset_without_polygons_exports_its_triangles(tmp_path: Path) -> None:
    tri = lgi.Dataset.from_arrays(np.eye(3), np.array([[0, 1, 2]]))
    assert tri.polygons is None
    p = usd.write_usd(tmp_path / "t.usd", tri, np.eye(3)[None], fps=25.0)
    stage = Usd.Stage.Open(str(p))  # held: a prim dies with its stage
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh"))
    assert list(mesh.GetFaceVertexCountsAttr().Get()) == [3]
    assert not UsdGeom.PrimvarsAPI(mesh).HasPrimvar("st")


def test_obj_sequence_reads_back_through_the_core_reader_with_the_same_polygons(
    quads, tmp_path: Path
) -> None:  # type: ignore[no-untyped-def]
    v = frames(2, 7)
    paths = obj.write_obj_sequence(tmp_path / "seq", quads, v, name="shot", start=7)
    assert [p.name for p in paths] == ["shot.0007.obj", "shot.0008.obj"]
    for p, want in zip(paths, v, strict=True):
        back = lgi.Dataset.from_obj(p)
        np.testing.assert_allclose(back.neutral, want, rtol=1e-8)
        for a, b in zip(back.polygons, quads.polygons, strict=True):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(back.uvs, quads.uvs)


def test_result_npz_round_trips(quads, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    v = frames(3, 7)
    t = topology(quads)
    res = np.arange(6.0).reshape(3, 2)
    miss = np.array([[True, False]] * 3)
    p = result.write_result_npz(
        tmp_path / "r.npz", t, v, res, miss, ["a", "b"], fps=None, start=4, units="cm"
    )
    r = result.read_result_npz(p)
    np.testing.assert_array_equal(r.vertices, v.astype(np.float32))
    np.testing.assert_array_equal(r.bundle_residuals, res)
    np.testing.assert_array_equal(r.missing, miss)
    assert r.marker_names == ["a", "b"] and r.fps is None and r.start == 4 and r.units == "cm"
    np.testing.assert_array_equal(r.topology.counts, t.counts)
    np.testing.assert_array_equal(r.topology.uv_indices, t.uv_indices)


def test_export_inputs_are_checked(quads, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(InputError, match=r"expected float vertices \(F, 7, 3\)"):
        usd.write_usd(tmp_path / "a.usd", quads, np.zeros((2, 6, 3)), fps=24.0)
    with pytest.raises(InputError, match="not all finite"):
        usd.write_usd(tmp_path / "a.usd", quads, np.full((1, 7, 3), np.nan), fps=24.0)
    with pytest.raises(InputError, match="fps must be a positive number"):
        usd.write_usd(tmp_path / "a.usd", quads, frames(1, 7), fps=0.0)
    with pytest.raises(InputError, match=r"suffix must be \.usd"):
        usd.write_usd(tmp_path / "a.abc", quads, frames(1, 7), fps=24.0)
    with pytest.raises(InputError, match="is a folder"):
        usd.write_usd(tmp_path, quads, frames(1, 7), fps=24.0)
    with pytest.raises(InputError, match="no frames were added"):
        usd.UsdCache(tmp_path / "e.usd", topology(quads), fps=24.0).close()
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(InputError, match="is a file, expected a folder"):
        obj.write_obj_sequence(f, quads, frames(1, 7))


def test_source_polygons_survive_a_dataset_npz_and_leaving_shapes_out(
    quads, tmp_path: Path
) -> None:  # type: ignore[no-untyped-def]
    from lgi.data.dataset import without_shapes

    with_shape = lgi.Dataset.from_arrays(
        quads.neutral,
        quads.triangles,
        np.ones((2, 7, 3)),
        uvs=quads.uvs,
        uv_triangles=quads.uv_triangles,
    ).with_polygons(*quads.polygons)
    p = tmp_path / "d.npz"
    with_shape.to_npz(p)
    back = lgi.Dataset.from_npz(p)
    for a, b in zip(back.polygons, quads.polygons, strict=True):
        np.testing.assert_array_equal(a, b)
    kept = without_shapes(back, [0])
    assert kept.num_shapes == 1
    np.testing.assert_array_equal(kept.polygons[0], [4, 4, 3])


def test_polygons_that_do_not_fan_split_into_the_triangles_are_refused(quads) -> None:  # type: ignore[no-untyped-def]
    counts, vertices, uvs = quads.polygons
    with pytest.raises(InputError, match="do not fan-split"):
        quads.with_polygons(counts, np.roll(vertices, 1), uvs)
    with pytest.raises(InputError, match="UV indices"):
        quads.with_polygons(counts, vertices)
    with pytest.raises(InputError, match="1-D integer array"):
        quads.with_polygons(counts.reshape(1, -1), vertices, uvs)


def test_write_usd_takes_a_model_and_a_solve_result_as_the_design_says(
    tmp_path: Path, sample, sample_dataset
) -> None:  # type: ignore[no-untyped-def]
    model = lgi.Model.build(sample_dataset, sample.markers_rest, units="cm")
    res = model.solve(sample.performance[:3], quiet=True)
    p = usd.write_usd(tmp_path / "m.usda", model, res, fps=30.0)
    stage = Usd.Stage.Open(str(p))
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01)
    prim = stage.GetPrimAtPath("/Face/Mesh")
    pts = UsdGeom.Mesh(prim).GetPointsAttr()
    np.testing.assert_array_equal(np.array(pts.Get(2)), res.vertices[2].astype(np.float32))
    got = np.array(prim.GetAttribute("lgi:markerResidual").Get(1))
    np.testing.assert_allclose(got, res.bundle_residuals[1].astype(np.float32))
