"""lgi.Dataset: loading (OBJ, glob, arrays, npz), round trips, and the errors bad input raises."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest

import lgi
import lgi.lab.ict

ICT = lgi.lab.ict.find(os.environ.get(lgi.lab.ict.ENV), start=Path(__file__).parent)
needs_ict = pytest.mark.skipif(
    ICT is None, reason=f"ICT FaceKit data not found (set {lgi.lab.ict.ENV} or ../shared/data)"
)

NEUTRAL = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64)
TRIS = np.array([[0, 1, 2], [0, 2, 3]])
SHAPES = np.stack([np.tile([0.0, 0.0, 0.5], (4, 1)), np.eye(4, 3)]).astype(np.float32)
UVS = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]], dtype=np.float64)
UV_TRIS = np.array([[0, 1, 2], [4, 2, 3]])


def _square(**kw):
    args = dict(shapes=SHAPES, names=["up", "eye"], uvs=UVS, uv_triangles=UV_TRIS)
    args.update(kw)
    return lgi.Dataset.from_arrays(NEUTRAL, TRIS, **args)


def _write_obj(path: Path, verts, faces: str = "f 1 2 3\n") -> Path:
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in verts) + faces)
    return path


@needs_ict
def test_ict_neutral_and_shapes_load_by_glob():
    ict = ICT
    assert ict is not None
    t = time.perf_counter()
    d = lgi.Dataset.from_obj(ict / "generic_neutral_mesh.obj", str(ict / "shapes" / "*.obj"))
    elapsed = time.perf_counter() - t
    print(f"ICT from_obj (neutral + {d.num_shapes} shapes): {elapsed:.3f} s")
    assert d.num_vertices == 26719
    assert d.num_shapes == 57
    assert d.triangles.shape == (548 + 2 * 25836, 3)
    assert d.names == sorted(d.names)
    assert d.shapes.shape == (57, 26719, 3)
    assert elapsed < 10.0


@needs_ict
def test_ict_shape_list_equals_glob_and_displacements_match_the_files():
    ict = ICT
    assert ict is not None
    files = sorted((ict / "shapes").glob("jaw*.obj"))
    d = lgi.Dataset.from_obj(ict / "generic_neutral_mesh.obj", files)
    g = lgi.Dataset.from_obj(ict / "generic_neutral_mesh.obj", ict / "shapes" / "jaw*.obj")
    assert d.names == g.names == [f.stem for f in files]
    # Independent reference: the shape file's v lines read with numpy.
    lines = [ln for ln in files[0].read_text().splitlines() if ln.startswith("v ")]
    ref = np.array([[float(x) for x in ln.split()[1:4]] for ln in lines])
    np.testing.assert_allclose(d.neutral + d.shapes[0], ref, atol=1e-5)


def test_from_arrays_round_trips_every_array():
    d = _square()
    assert (d.num_vertices, d.num_shapes) == (4, 2)
    assert d.names == ["up", "eye"]
    np.testing.assert_array_equal(d.neutral, NEUTRAL)
    np.testing.assert_array_equal(d.triangles, TRIS)
    np.testing.assert_array_equal(d.shapes, SHAPES)
    np.testing.assert_array_equal(d.uvs, UVS)
    np.testing.assert_array_equal(d.uv_triangles, UV_TRIS)
    assert d.neutral.dtype == np.float64 and d.shapes.dtype == np.float32
    assert d.triangles.dtype == np.int64


def test_from_arrays_defaults_no_shapes_no_uvs_and_numbered_names():
    d = lgi.Dataset.from_arrays(NEUTRAL.astype(np.float32), TRIS.astype(np.uint32))
    assert d.num_shapes == 0 and d.shapes.shape == (0, 4, 3)
    assert d.uvs.shape == (0, 2) and d.uv_triangles.shape == (0, 3)
    assert lgi.Dataset.from_arrays(NEUTRAL, TRIS, SHAPES).names == ["shape0", "shape1"]


def test_a_dataset_is_a_python_class_holding_the_core_dataset():
    d = _square()
    assert type(d) is lgi.Dataset and type(d.core) is lgi._lgi.Dataset
    assert repr(d) == repr(d.core) == "Dataset(num_vertices=4, num_shapes=2, num_triangles=2)"
    again = lgi.Dataset(d.core)
    assert again.core is d.core and again.to_bytes() == d.to_bytes()
    assert type(d.augmented(4)) is lgi.Dataset
    assert type(d.with_polygons([3, 3], TRIS.ravel(), UV_TRIS.ravel())) is lgi.Dataset
    with pytest.raises(lgi.InputError, match="from_arrays"):
        lgi.Dataset(NEUTRAL)  # type: ignore[arg-type]


def test_a_models_dataset_is_an_lgi_dataset(sample_model, sample_dataset):
    data = sample_model.dataset
    assert type(data) is lgi.Dataset
    assert data.to_bytes() == sample_dataset.to_bytes()


def test_npz_round_trip_is_exact(tmp_path):
    d = _square()
    d.to_npz(tmp_path / "face.npz")
    with np.load(tmp_path / "face.npz", allow_pickle=False) as z:
        assert sorted(z.files) == sorted(
            ["neutral", "triangles", "shapes", "names", "uvs", "uv_triangles"]
        )
    back = lgi.Dataset.from_npz(tmp_path / "face.npz")
    assert back.names == d.names
    for attr in ("neutral", "triangles", "shapes", "uvs", "uv_triangles"):
        np.testing.assert_array_equal(getattr(back, attr), getattr(d, attr))


def test_npz_without_uvs_or_shapes_round_trips(tmp_path):
    d = lgi.Dataset.from_arrays(NEUTRAL, TRIS)
    d.to_npz(str(tmp_path / "bare.npz"))
    back = lgi.Dataset.from_npz(str(tmp_path / "bare.npz"))
    assert back.num_shapes == 0 and back.uv_triangles.shape == (0, 3)


def test_npz_missing_key_and_bad_content_name_the_file(tmp_path):
    np.savez(tmp_path / "nokey.npz", neutral=NEUTRAL)
    with pytest.raises(lgi.DatasetError, match=r"nokey\.npz.*'triangles'"):
        lgi.Dataset.from_npz(tmp_path / "nokey.npz")
    np.savez(tmp_path / "int.npz", neutral=NEUTRAL.astype(np.int64), triangles=TRIS)
    with pytest.raises(lgi.DatasetError, match=r"int\.npz.*neutral") as e:
        lgi.Dataset.from_npz(tmp_path / "int.npz")
    assert not isinstance(e.value, lgi.InputError)
    (tmp_path / "junk.npz").write_bytes(b"not a zip file at all")
    with pytest.raises(lgi.DatasetError, match=r"junk\.npz"):
        lgi.Dataset.from_npz(tmp_path / "junk.npz")


def test_int_positions_raise_input_error_naming_neutral():
    with pytest.raises(lgi.InputError, match=r"neutral.*dtype int64"):
        lgi.Dataset.from_arrays(NEUTRAL.astype(np.int64), TRIS)


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"neutral": NEUTRAL[:, :2]}, r"neutral: expected shape \(N, 3\)"),
        ({"triangles": TRIS[:, :2]}, r"triangles: expected shape \(N, 3\)"),
        ({"triangles": TRIS.astype(np.float64)}, "triangles: expected an integer array"),
        ({"triangles": [[0, 1, 4]]}, "triangles: row 0 refers to vertex 4"),
        ({"triangles": [[0, 1, -1]]}, "triangles: row 0 has index -1"),
        ({"shapes": SHAPES[:, :3]}, r"shapes: expected shape \(N, 4, 3\)"),
        ({"names": ["only-one"]}, "names: 1 names for 2 shapes"),
        ({"names": "up"}, "names: expected a sequence"),
        ({"names": ["a", "a"]}, "duplicate shape name 'a'"),
        ({"uv_triangles": None}, "uvs given without uv_triangles"),
        ({"uv_triangles": UV_TRIS[:1]}, "uv_triangles: 1 rows for 2 triangles"),
        ({"uv_triangles": [[0, 1, 2], [0, 1, 9]]}, "uv_triangles: row 1 refers to UV 9"),
        ({"uvs": UVS[:, :1]}, r"uvs: expected shape \(N, 2\)"),
    ],
)
def test_bad_arrays_raise_input_error_naming_the_argument(kwargs, pattern):
    args = dict(
        neutral=NEUTRAL,
        triangles=TRIS,
        shapes=SHAPES,
        names=["up", "eye"],
        uvs=UVS,
        uv_triangles=UV_TRIS,
    )
    args.update(kwargs)
    with pytest.raises(lgi.InputError, match=pattern):
        lgi.Dataset.from_arrays(**args)


def test_nan_values_raise_input_error_naming_row_or_shape():
    bad = NEUTRAL.copy()
    bad[2, 1] = np.nan
    with pytest.raises(lgi.InputError, match="neutral: row 2"):
        lgi.Dataset.from_arrays(bad, TRIS)
    shapes = SHAPES.copy()
    shapes[1, 3, 0] = np.inf
    with pytest.raises(lgi.InputError, match="shapes: shape 1, vertex 3"):
        lgi.Dataset.from_arrays(NEUTRAL, TRIS, shapes)
    uvs = UVS.copy()
    uvs[4, 0] = np.nan
    with pytest.raises(lgi.InputError, match="uvs: row 4"):
        lgi.Dataset.from_arrays(NEUTRAL, TRIS, uvs=uvs, uv_triangles=UV_TRIS)


def test_shape_files_with_other_vertex_count_name_the_file(tmp_path):
    tri = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    neutral = _write_obj(tmp_path / "neutral.obj", tri)
    good = _write_obj(tmp_path / "smile.obj", [(x, y, 1) for x, y, _ in tri])
    bad = _write_obj(tmp_path / "frown.obj", [*tri, (5, 5, 5)])
    with pytest.raises(lgi.DatasetError, match=r"frown\.obj has 4 vertices.*3"):
        lgi.Dataset.from_obj(neutral, [good, bad])
    d = lgi.Dataset.from_obj(str(neutral), [str(good)])
    np.testing.assert_array_equal(d.shapes[0], np.tile([0, 0, 1], (3, 1)))
    assert lgi.Dataset.from_obj(neutral).num_shapes == 0


def test_missing_file_raises_dataset_file_error_which_is_file_not_found(tmp_path):
    with pytest.raises(lgi.DatasetFileError, match=r"nowhere\.obj") as e:
        lgi.Dataset.from_obj(tmp_path / "nowhere.obj")
    assert isinstance(e.value, FileNotFoundError)
    assert isinstance(e.value, lgi.DatasetError)
    with pytest.raises(FileNotFoundError, match=r"gone\.npz"):
        lgi.Dataset.from_npz(tmp_path / "gone.npz")
    with pytest.raises(lgi.DatasetFileError, match=r"gone\.gltf"):
        lgi.Dataset.from_gltf(tmp_path / "gone.gltf")


def test_garbled_obj_raises_dataset_error_with_file_and_line(tmp_path):
    p = tmp_path / "garbled.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 one 0\nf 1 2 3\n")
    with pytest.raises(lgi.DatasetError, match=r"garbled\.obj:3: bad number 'one'"):
        lgi.Dataset.from_obj(p)


def test_glob_without_match_raises_naming_the_pattern(tmp_path):
    neutral = _write_obj(tmp_path / "neutral.obj", [(0, 0, 0), (1, 0, 0), (0, 1, 0)])
    pattern = str(tmp_path / "shapes" / "*.obj")
    with pytest.raises(lgi.DatasetFileError, match="no shape file matches the pattern") as e:
        lgi.Dataset.from_obj(neutral, pattern)
    assert pattern in str(e.value)


def test_shapes_argument_of_wrong_type_raises_input_error(tmp_path):
    neutral = _write_obj(tmp_path / "neutral.obj", [(0, 0, 0), (1, 0, 0), (0, 1, 0)])
    with pytest.raises(lgi.InputError, match=r"shapes\[1\]"):
        lgi.Dataset.from_obj(neutral, [neutral, 3])
    with pytest.raises(lgi.InputError, match="shapes: expected a glob pattern"):
        lgi.Dataset.from_obj(neutral, 3)


def test_augmented_keeps_originals_and_adds_inbetweens_and_pair_sums():
    d = _square()
    a = d.augmented(10)
    # originals first, unchanged; the neutral and topology are shared
    assert a.names[:2] == ["up", "eye"]
    np.testing.assert_array_equal(a.shapes[:2], d.shapes)
    np.testing.assert_array_equal(a.neutral, d.neutral)
    np.testing.assert_array_equal(a.triangles, d.triangles)
    # independent reference: each added shape is the recipe its name spells
    by_name = dict(zip(d.names, d.shapes, strict=True))
    for name, shape in zip(a.names, a.shapes, strict=True):
        if "@" in name:
            base, w = name.split("@")
            np.testing.assert_allclose(shape, float(w) * by_name[base], atol=1e-6)
        elif "+" in name:
            x, y = name.split("+")
            np.testing.assert_allclose(shape, by_name[x] + by_name[y], atol=1e-6)
    assert "up@0.5" in a.names and "up+eye" in a.names
    assert a.num_shapes == 2 + 6 + 1


def test_augmented_without_shapes_raises_dataset_error():
    d = lgi.Dataset.from_arrays(NEUTRAL, TRIS)
    with pytest.raises(lgi.errors.DatasetError):
        d.augmented(10)
