"""Regressions of the reliability review (issue 14): every case it found, each named for what it
proves. The fuzz campaign that keeps them fixed is test_fuzz.py (docs/reliability.md)."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

import lgi
from interrupts import python_sigint_handler, sigint_at
from lgi import _lgi
from lgi.lab.baselines import BlendshapeFit, DisplacementInterpolation, LgiRbf
from lgi.lab.sample import make_sample
from lgi.lab.sample import sample_dataset as dataset_of
from lgi.solve.jaw import JawRig


@pytest.fixture(scope="module")
def small():  # type: ignore[no-untyped-def]
    """A small sample (1,379 vertices, 43 shapes, 106 markers), its dataset and model."""
    s = make_sample(0, resolution=40, num_frames=12)
    d = dataset_of(s)
    return s, d, lgi.Model.build(d, s.markers_rest)


def _methods(small):  # type: ignore[no-untyped-def]
    s, d, model = small
    return {
        "lgi": model,
        "displacement": DisplacementInterpolation(d, s.markers_rest),
        "blendshape": BlendshapeFit(d, s.markers_rest),
        "lgi-rbf": LgiRbf(d, s.markers_rest),
    }


# -- glTF: malformed files are errors naming the file, never a PanicException ------------------


def _triangle_gltf(tmp_path: Path, name: str, **change: object) -> Path:
    """A one-triangle glTF (positions, u16 indices); `change` edits the JSON's parts."""
    buf = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<3H", 0, 1, 2) + b"\0\0"
    import base64

    doc: dict = {
        "asset": {"version": "2.0"},
        "buffers": [
            {
                "byteLength": len(buf),
                "uri": "data:application/octet-stream;base64," + base64.b64encode(buf).decode(),
            }
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 6},
        ],
        "accessors": [
            {
                "bufferView": 0,
                "componentType": 5126,
                "count": 3,
                "type": "VEC3",
                "min": [0, 0, 0],
                "max": [1, 1, 0],
            },
            {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"},
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
    }
    for key, value in change.items():
        if key == "position_accessor":
            doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = value
        elif key == "index_component":
            doc["accessors"][1]["componentType"] = value
        elif key == "stride":
            doc["bufferViews"][0]["byteStride"] = value
    p = tmp_path / name
    p.write_text(json.dumps(doc))
    return p


def test_the_gltf_template_reads(tmp_path: Path) -> None:
    d = lgi.Dataset.from_gltf(_triangle_gltf(tmp_path, "ok.gltf"))
    assert d.num_vertices == 3


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"position_accessor": 7}, "accessor 7"),
        ({"index_component": 5126}, "indices"),
        ({"stride": 4}, "byteStride 4"),
    ],
)
def test_malformed_gltf_is_a_dataset_error_naming_the_file_not_a_panic(
    tmp_path: Path, change: dict, match: str
) -> None:
    p = _triangle_gltf(tmp_path, "bad.gltf", **change)
    with pytest.raises(lgi.DatasetError, match=match) as e:
        lgi.Dataset.from_gltf(p)
    assert "bad.gltf" in str(e.value)


# -- model files: a crafted file with a valid checksum is a ModelFormatError -------------------


def _resum(data: bytearray) -> None:
    """Recompute the version 3 checksum (docs/file-formats.md) after editing the payload."""
    mask = (1 << 64) - 1
    prime = 0x0000_0100_0000_01B3
    payload = bytes(data[28:])
    lanes = [0xCBF29CE484222325, 0x84222325CBF29CE4, 0x9CE484222325CBF2, 0x2325CBF29CE48422]
    n = len(payload) // 32 * 32
    words = np.frombuffer(payload[:n], dtype="<u8").reshape(-1, 4) if n else np.zeros((0, 4), "<u8")
    for row in words:
        for k in range(4):
            lanes[k] = ((lanes[k] ^ int(row[k])) * prime) & mask
    h = (len(payload) * prime) & mask
    for lane in lanes:
        h = ((h ^ lane) * prime) & mask
        h ^= h >> 29
    for b in payload[n:]:
        h = ((h ^ b) * prime) & mask
    data[20:28] = struct.pack("<Q", h)


def test_resum_reproduces_the_writers_checksum(small, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    p = tmp_path / "m.lgi"
    small[2].save(p)
    data = bytearray(p.read_bytes())
    original = bytes(data)
    _resum(data)
    assert bytes(data) == original


def test_model_file_with_words_zeroed_and_a_valid_checksum_is_refused_or_loads_valid(
    small, tmp_path: Path
) -> None:  # type: ignore[no-untyped-def]
    p = tmp_path / "m.lgi"
    small[2].save(p)
    data = bytearray(p.read_bytes())
    # Zero words across the payload (counts, coordinates, indices): whatever it hits, the file
    # must be refused as a model file, or load as a valid model; never a panic or another error.
    seen = 0
    for at in range(28, len(data) - 8, max(8, len(data) // 24 // 8 * 8)):
        crafted = bytearray(data)
        crafted[at : at + 8] = b"\0" * 8
        _resum(crafted)
        q = tmp_path / "crafted.lgi"
        q.write_bytes(bytes(crafted))
        try:
            m = lgi.Model.load(q)
        except lgi.ModelFormatError:
            seen += 1
            continue
        res = m.solve(small[0].markers_rest[None], quiet=True)
        assert np.isfinite(res.vertices).all()
    assert seen > 0


# -- magnitudes: one policy across every method -------------------------------------------------


@pytest.mark.parametrize("value", [1e200, 1e30, -1e154, 1e308])
@pytest.mark.parametrize("method", ["lgi", "displacement", "blendshape", "lgi-rbf"])
def test_marker_beyond_the_magnitude_limit_is_an_input_error_naming_frame_and_marker(
    small, method: str, value: float
) -> None:  # type: ignore[no-untyped-def]
    s = small[0]
    frames = np.repeat(s.markers_rest[None], 3, axis=0)
    frames[2, 5, 1] = value
    # The model names its marker by label and index; the baselines, which have no labels, by index.
    with pytest.raises(lgi.InputError, match=r"frame 2: marker (m005 \()?5\b") as e:
        _methods(small)[method].solve(frames, quiet=True)
    assert "DVec3" not in str(e.value) and "inf from" not in str(e.value)


@pytest.mark.parametrize("method", ["lgi", "displacement", "blendshape", "lgi-rbf"])
def test_every_method_accepts_markers_just_inside_the_limit_with_finite_output(
    small, method: str
) -> None:  # type: ignore[no-untyped-def]
    s, _, model = small
    frames = s.markers_rest[None].copy()
    centre = (s.markers_rest.min(axis=0) + s.markers_rest.max(axis=0)) / 2
    frames[0, 0] = centre + np.array([0.99 * _lgi.MAGNITUDE_LIMIT * model.diagonal, 0, 0])
    res = _methods(small)[method].solve(frames, quiet=True)
    assert np.isfinite(res.vertices).all()


@pytest.mark.parametrize("method", ["lgi", "displacement", "blendshape", "lgi-rbf"])
def test_every_marker_missing_raises_the_same_input_error_for_every_method(
    small, method: str
) -> None:  # type: ignore[no-untyped-def]
    frames = np.full((1, small[0].markers_rest.shape[0], 3), np.nan)
    with pytest.raises(lgi.InputError, match="only 0 markers present"):
        _methods(small)[method].solve(frames, quiet=True)


def test_jaw_forward_translation_beyond_the_limit_is_an_input_error(small) -> None:  # type: ignore[no-untyped-def]
    s, d, _ = small
    model = lgi.Model.build(
        d,
        s.markers_rest,
        jaw=JawRig(pivot=s.jaw_pivot, weights=s.jaw_weights),
        shape_theta=s.shape_jaw_theta,
    )
    theta = np.zeros((1, 3))
    theta[0, 2] = 1e200
    with pytest.raises(lgi.InputError, match="jaw forward translation"):
        model.solve(s.markers_rest[None], jaw=theta, quiet=True)


def test_shape_displacement_beyond_the_limit_is_a_dataset_error_naming_shape_and_vertex(
    small,
) -> None:  # type: ignore[no-untyped-def]
    s = small[0]
    shapes = s.shapes.astype(np.float64)
    shapes[3, 17, 2] = 1e30
    with pytest.raises(lgi.LgiError, match=r"shape 3 .*vertex 17"):
        lgi.Dataset.from_arrays(s.neutral, s.triangles, shapes, s.names, s.uvs, s.uv_triangles)


# -- Ctrl-C and callback errors stop a solve ---------------------------------------------------


def test_an_exception_in_the_progress_callback_stops_the_solve_and_reaches_the_caller(
    small,
) -> None:  # type: ignore[no-untyped-def]
    s, _, model = small
    frames = np.repeat(s.markers_rest[None], 200, axis=0)
    calls: list[int] = []

    def progress(f: int) -> None:
        calls.append(f)
        if f == 4:
            raise ValueError("stop here")

    with pytest.raises(ValueError, match="stop here"):
        model.core.solve(frames, progress=progress, temporal=True)
    assert calls == [0, 1, 2, 3, 4]


def test_ctrl_c_during_a_long_solve_raises_keyboard_interrupt_before_the_end(small) -> None:  # type: ignore[no-untyped-def]
    s, _, model = small
    frames = np.repeat(s.markers_rest[None], 4000, axis=0)
    calls: list[int] = []
    with python_sigint_handler(), pytest.raises(KeyboardInterrupt):
        model.core.solve(frames, progress=sigint_at(10, calls), temporal=True)
    assert 10 < len(calls) < 4000


# -- unclear exceptions --------------------------------------------------------------------


def test_misaligned_out_array_is_an_input_error(small) -> None:  # type: ignore[no-untyped-def]
    s, _, model = small
    nv = model.num_vertices
    raw = np.zeros(nv * 3 * 8 + 1, dtype=np.uint8)
    out = np.frombuffer(raw.data, dtype=np.float64, count=nv * 3, offset=1).reshape(1, nv, 3)
    assert not out.flags.aligned
    with pytest.raises(lgi.InputError, match="out"):
        model.solve(s.markers_rest[None], out=out, quiet=True)


@pytest.mark.parametrize("window", [2**64, -1, "3", 2.5, True])
def test_bad_smooth_window_is_an_input_error_naming_it(small, window: object) -> None:  # type: ignore[no-untyped-def]
    s, _, model = small
    with pytest.raises(lgi.InputError, match="smooth_window"):
        model.solve(s.markers_rest[None], smooth_window=window, quiet=True)  # type: ignore[arg-type]


@pytest.mark.parametrize("count", [-1, 2**64, "4"])
def test_bad_augmented_count_is_an_input_error_naming_it(small, count: object) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(lgi.InputError, match="min_shapes"):
        small[1].augmented(count)  # type: ignore[arg-type]


def test_huge_sample_resolution_is_refused_before_allocating() -> None:
    with pytest.raises(lgi.InputError, match="resolution"):
        make_sample(resolution=100000)


def test_saving_to_a_full_device_says_cannot_write(small) -> None:  # type: ignore[no-untyped-def]
    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full on this system")
    with pytest.raises(lgi.FileWriteError, match="cannot write /dev/full"):
        small[2].save("/dev/full")


def test_obj_vertex_beyond_the_coordinate_bound_is_a_dataset_error_naming_the_file(
    tmp_path: Path,
) -> None:
    # Found by the fuzz campaign: the dataset's magnitude check did not name the OBJ file.
    p = tmp_path / "far.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1e31\nf 1 2 3\nf 1 2 4\n")
    with pytest.raises(lgi.DatasetError, match=r"far\.obj.*vertex 3"):
        lgi.Dataset.from_obj(p)


# -- silent degradation ----------------------------------------------------------------------


def test_a_build_config_that_leaves_most_markers_without_tets_warns_with_the_reason(small) -> None:  # type: ignore[no-untyped-def]
    s, d, _ = small
    with pytest.warns(lgi.LgiWarning, match=r"will only be projected.*min_quality 2"):
        model = lgi.Model.build(d, s.markers_rest, config=lgi.BuildConfig(min_quality=2.0))
    assert np.isfinite(model.solve(s.markers_rest[None], quiet=True).vertices).all()


def test_the_default_build_of_the_sample_does_not_warn(small) -> None:  # type: ignore[no-untyped-def]
    import warnings

    s, d, _ = small
    with warnings.catch_warnings():
        warnings.simplefilter("error", lgi.LgiWarning)
        lgi.Model.build(d, s.markers_rest)
