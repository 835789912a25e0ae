"""Rig exports read back by other readers: glTF morph targets by the core's glTF reader
(`Dataset.from_gltf`) and by a plain JSON / GLB-chunk parse, USD blendshapes by pxr's own
`UsdSkel.BlendShapeQuery` applying weights (against neutral + sum of weighted shapes)."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

import lgi
from lgi.io.rig import gltf_vertices, write_gltf_rig, write_usd_rig
from lgi.solve import rig


@pytest.fixture(scope="module")
def small_rig(sample_dataset, sample_model):  # type: ignore[no-untyped-def]
    return rig.actor_rig(sample_model, sample_dataset, [["jawOpen", "mouthClose"]], quiet=True)


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_gltf_rig_reads_back_through_the_core_reader(
    small_rig, tmp_path: Path, suffix: str
) -> None:  # type: ignore[no-untyped-def]
    path = write_gltf_rig(tmp_path / f"rig{suffix}", small_rig)
    back = lgi.Dataset.from_gltf(path)
    source, tris = gltf_vertices(small_rig)
    assert back.names == small_rig.names
    assert np.array_equal(back.triangles, tris)
    assert np.abs(back.neutral - small_rig.neutral[source]).max() < 1e-5  # f32 storage
    assert np.array_equal(back.shapes, small_rig.shapes[:, source])


def test_glb_chunks_and_json_follow_the_gltf_layout(small_rig, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    raw = write_gltf_rig(tmp_path / "rig.glb", small_rig).read_bytes()
    magic, version, length = struct.unpack_from("<III", raw, 0)
    assert (magic, version, length) == (0x46546C67, 2, len(raw))
    json_len, json_type = struct.unpack_from("<II", raw, 12)
    assert json_type == 0x4E4F534A and json_len % 4 == 0
    doc = json.loads(raw[20 : 20 + json_len])
    bin_len, bin_type = struct.unpack_from("<II", raw, 20 + json_len)
    assert bin_type == 0x004E4942 and bin_len == doc["buffers"][0]["byteLength"]
    mesh = doc["meshes"][0]
    assert mesh["extras"]["targetNames"][-1] == "corrective_jawOpen_mouthClose"
    assert mesh["weights"] == [0.0] * small_rig.num_shapes
    prim = mesh["primitives"][0]
    assert len(prim["targets"]) == small_rig.num_shapes
    # The last target's floats, read straight from the BIN chunk, are the corrective.
    acc = doc["accessors"][prim["targets"][-1]["POSITION"]]
    view = doc["bufferViews"][acc["bufferView"]]
    start = 28 + json_len + view["byteOffset"]
    data = np.frombuffer(raw[start : start + view["byteLength"]], dtype="<f4").reshape(-1, 3)
    source, _ = gltf_vertices(small_rig)
    assert np.array_equal(data, small_rig.shapes[-1][source])
    assert acc["min"] == pytest.approx(data.min(axis=0).tolist())


def test_usd_rig_deforms_like_the_weighted_sum_under_pxr(small_rig, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from pxr import Usd, UsdSkel, Vt

    path = write_usd_rig(tmp_path / "rig.usda", small_rig, units="cm")
    stage = Usd.Stage.Open(str(path))
    assert stage.GetDefaultPrim().GetPath() == "/Rig"
    mesh = stage.GetPrimAtPath("/Rig/Face")
    binding = UsdSkel.BindingAPI(mesh)
    assert list(binding.GetBlendShapesAttr().Get()) == small_rig.names
    query = UsdSkel.BlendShapeQuery(binding)
    assert query.GetNumBlendShapes() == small_rig.num_shapes
    w = np.zeros(small_rig.num_shapes, np.float32)
    w[[0, 4, -1]] = [0.5, 1.0, 1.0]
    sub, bs_index, sub_index = query.ComputeSubShapeWeights(Vt.FloatArray.FromNumpy(w))
    points = mesh.GetAttribute("points").Get()
    assert query.ComputeDeformedPoints(
        sub,
        bs_index,
        sub_index,
        query.ComputeBlendShapePointIndices(),
        query.ComputeSubShapePointOffsets(),
        points,
    )
    expected = small_rig.neutral + np.tensordot(w, small_rig.shapes.astype(np.float64), 1)
    assert np.abs(np.array(points) - expected).max() < 1e-4
    corrective = stage.GetPrimAtPath("/Rig/Face/corrective_jawOpen_mouthClose")
    assert list(corrective.GetAttribute("lgi:combination").Get()) == ["jawOpen", "mouthClose"]
    cache = UsdSkel.Cache()
    root = UsdSkel.Root(stage.GetPrimAtPath("/Rig"))
    cache.Populate(root, Usd.TraverseInstanceProxies())
    (found,) = cache.ComputeSkelBindings(root, Usd.TraverseInstanceProxies())
    assert found.GetSkeleton().GetPath() == "/Rig/Skel"


def test_gltf_splits_ict_vertices_at_uv_seams_and_keeps_each_corners_uv(
    ict_dataset, tmp_path: Path
) -> None:  # type: ignore[no-untyped-def]
    small = lgi.data.dataset.with_shapes(ict_dataset, ict_dataset.shapes[:2], ict_dataset.names[:2])
    back = lgi.Dataset.from_gltf(write_gltf_rig(tmp_path / "ict.glb", small))
    source, tris = gltf_vertices(small)
    assert back.num_vertices == len(source) > small.num_vertices  # ICT has seams
    assert np.array_equal(source[tris], small.triangles)
    uv = np.asarray(back.uvs)[np.asarray(back.uv_triangles)]
    expected = np.asarray(small.uvs)[np.asarray(small.uv_triangles)]
    # The writer stores glTF's v (down the image), the reader gives the dataset's (up).
    assert np.abs(uv - expected).max() < 1e-6


@pytest.mark.parametrize(
    ("name", "match"), [("rig.obj", "suffix must be"), ("nope/rig.glb", "does not exist")]
)
def test_bad_rig_output_paths_are_input_errors(
    small_rig, tmp_path: Path, name: str, match: str
) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(lgi.InputError, match=match):
        write_gltf_rig(tmp_path / name, small_rig)
    with pytest.raises(lgi.InputError, match=match):
        write_usd_rig(tmp_path / name.replace(".glb", ".usd"), small_rig)
