"""Pickling (what Dask, Ray and multiprocessing ship to a worker) goes through the versioned
model format: a model from bytes solves bit for bit like the original, corrupt bytes raise the
error a corrupt file raises, a dataset round trips with its polygons; and the thread count
`lgi.set_num_threads` sets is the one lgi's parallel work runs on, without changing a result
or the way Ctrl-C stops a solve."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lgi
from interrupts import python_sigint_handler, sigint_at
from lgi import _lgi
from pipeline_files import write_actor


@pytest.fixture(scope="module")
def frames(sample) -> np.ndarray:  # type: ignore[no-untyped-def]
    return np.asarray(sample.performance[:12], dtype=np.float64)


@pytest.fixture(scope="module")
def model_bytes(sample_model) -> bytes:  # type: ignore[no-untyped-def]
    return sample_model.to_bytes()


def assert_same_solve(a: lgi.SolveResult, b: lgi.SolveResult) -> None:
    assert np.array_equal(a.vertices, b.vertices)
    assert np.array_equal(a.bundle_residuals, b.bundle_residuals)
    assert np.array_equal(a.choices.shapes, b.choices.shapes)
    assert np.array_equal(a.choices.weights, b.choices.weights)
    assert np.array_equal(a.choices.tets, b.choices.tets)


def test_a_pickled_model_solves_bit_identically_exact_and_noise_aware(sample_model, frames):  # type: ignore[no-untyped-def]
    back = pickle.loads(pickle.dumps(sample_model))
    assert isinstance(back, lgi.Model)
    assert back.marker_names == sample_model.marker_names
    assert np.array_equal(back.markers_rest, sample_model.markers_rest)
    assert_same_solve(back.solve(frames, quiet=True), sample_model.solve(frames, quiet=True))
    a = back.solve(frames, quiet=True, marker_noise=0.01)
    b = sample_model.solve(frames, quiet=True, marker_noise=0.01)
    assert_same_solve(a, b)
    assert np.array_equal(a.marker_corrections, b.marker_corrections)


def test_a_jaw_model_with_names_and_units_survives_pickling(sample, sample_dataset, frames):  # type: ignore[no-untyped-def]
    model = lgi.Model.build(
        sample_dataset, sample.markers_rest, marker_names=sample.marker_names, units="cm"
    )
    assert model.jaw_rig is not None
    back = pickle.loads(pickle.dumps(model))
    assert back.units == "cm" and back.marker_names == list(sample.marker_names)
    assert np.array_equal(back.jaw_rig.weights, model.jaw_rig.weights)
    a, b = back.solve(frames, quiet=True), model.solve(frames, quiet=True)
    assert_same_solve(a, b)
    assert np.array_equal(a.jaw_theta, b.jaw_theta)


def test_model_bytes_are_the_model_file_and_the_core_model_pickles_alone(  # type: ignore[no-untyped-def]
    sample_model, model_bytes, tmp_path
):
    path = tmp_path / "m.lgi"
    sample_model.save(path)
    assert path.read_bytes() == model_bytes
    assert lgi.Model.from_bytes(bytearray(model_bytes)).to_bytes() == model_bytes
    core = pickle.loads(pickle.dumps(sample_model.core))
    assert core.to_bytes() == model_bytes


def flipped(data: bytes, at: int) -> bytes:
    b = bytearray(data)
    b[at] ^= 0x01
    return bytes(b)


@settings(max_examples=25, deadline=None)
@given(st.floats(min_value=0.0, max_value=1.0, exclude_max=True))
def test_any_flipped_bit_is_a_model_format_error_from_bytes_as_from_a_file(  # type: ignore[no-untyped-def]
    model_bytes, tmp_path_factory, where
):
    bad = flipped(model_bytes, int(where * len(model_bytes)))
    with pytest.raises(lgi.ModelFormatError) as from_bytes:
        lgi.Model.from_bytes(bad)
    path = tmp_path_factory.mktemp("corrupt") / "m.lgi"
    path.write_bytes(bad)
    with pytest.raises(lgi.ModelFormatError) as from_file:
        lgi.Model.load(path)
    # The same check fails, naming its source.
    assert str(from_bytes.value).replace("<in-memory bytes>", str(path)) == str(from_file.value)


def test_a_corrupt_pickle_and_truncated_bytes_raise_model_format_error(model_bytes):  # type: ignore[no-untyped-def]
    pickled = pickle.dumps(lgi.Model.from_bytes(model_bytes))
    at = pickled.index(model_bytes[:64]) + len(model_bytes) // 2
    with pytest.raises(lgi.ModelFormatError, match="checksum mismatch"):
        pickle.loads(flipped(pickled, at))
    with pytest.raises(lgi.ModelFormatError, match="truncated"):
        lgi.Model.from_bytes(model_bytes[:-8])
    with pytest.raises(lgi.ModelFormatError, match="bad magic"):
        lgi.Model.from_bytes(b"")
    with pytest.raises(lgi.InputError, match="expected bytes, got str"):
        lgi.Model.from_bytes("LGIMODEL")  # type: ignore[arg-type]


def test_a_dataset_with_source_polygons_round_trips_through_pickle(sample, tmp_path):  # type: ignore[no-untyped-def]
    files = write_actor(tmp_path, sample, num_shapes=4)
    data = lgi.Dataset.from_obj(files.neutral, sorted(files.shapes.glob("*.obj")))
    assert data.polygons is not None
    pickled = pickle.dumps(data)
    assert data.to_bytes() in pickled  # pickled as its bytes
    back = pickle.loads(pickled)
    assert type(back) is lgi.Dataset
    assert pickle.loads(pickle.dumps(data.core)).to_bytes() == data.to_bytes()
    for name in ("neutral", "triangles", "shapes", "uvs", "uv_triangles"):
        assert np.array_equal(getattr(back, name), getattr(data, name)), name
    assert back.names == data.names
    for a, b in zip(back.polygons, data.polygons, strict=True):
        assert np.array_equal(a, b)
    assert back.to_bytes() == data.to_bytes()


def test_corrupt_dataset_bytes_and_model_bytes_as_a_dataset_raise_model_format_error(  # type: ignore[no-untyped-def]
    sample_dataset, model_bytes
):
    data = sample_dataset.to_bytes()
    with pytest.raises(lgi.ModelFormatError, match="checksum mismatch"):
        lgi.Dataset.from_bytes(flipped(data, len(data) - 5))
    with pytest.raises(lgi.ModelFormatError, match="bad magic"):
        lgi.Dataset.from_bytes(model_bytes)
    with pytest.raises(lgi.ModelFormatError, match="bad magic"):
        lgi.Model.from_bytes(data)


def test_a_solve_result_pickles_with_its_arrays(sample_model, frames):  # type: ignore[no-untyped-def]
    res = sample_model.solve(frames, quiet=True)
    back = pickle.loads(pickle.dumps(res))
    assert_same_solve(back, res)
    assert np.array_equal(back.missing, res.missing)


@pytest.fixture
def default_threads():  # type: ignore[no-untyped-def]
    yield
    lgi.set_num_threads(None)


def test_set_num_threads_sets_the_count_and_leaves_results_bit_identical(  # type: ignore[no-untyped-def]
    sample_model, frames, default_threads
):
    lgi.set_num_threads(None)
    default = lgi.get_num_threads()
    reference = sample_model.solve(frames, quiet=True, marker_noise=0.01)
    for n in (1, 3, 3):
        lgi.set_num_threads(n)
        assert lgi.get_num_threads() == n
        assert_same_solve(sample_model.solve(frames, quiet=True, marker_noise=0.01), reference)
    lgi.set_num_threads(None)
    assert lgi.get_num_threads() == default


def test_noise_aware_ict300_is_bit_identical_at_1_and_2_threads_basis_included(  # type: ignore[no-untyped-def]
    ict_dataset, ict_markers, default_threads
):
    """ICT-300's fit is sewn over a basis of its shapes, found on a model's first noise-aware
    solve from a Gram matrix summed in parallel: each thread count gets a fresh model, so
    the basis is found under that count (a parallel reduce once made them differ)."""
    data = ict_dataset.augmented(300)
    rng = np.random.default_rng(4)
    meshes = np.repeat(data.neutral[None], 12, axis=0)
    for m in meshes:
        ids = rng.integers(0, data.num_shapes, size=3)
        for k, w in zip(ids, rng.dirichlet(np.ones(3)), strict=True):
            m += w * data.shapes[k]
    noise = rng.normal(0.0, 0.05, (len(meshes), len(ict_markers), 3))
    results = []
    for n in (1, 2):
        lgi.set_num_threads(n)
        model = lgi.Model.build(data, ict_markers, jaw=None)
        frames = model.bundle_positions(meshes) + noise
        results.append(model.solve(frames, quiet=True, marker_noise=0.05))
    assert_same_solve(results[1], results[0])


def test_without_set_num_threads_the_count_is_rayons_default_from_rayon_num_threads() -> None:
    code = (
        "import lgi; print(lgi.get_num_threads()); "
        "lgi.set_num_threads(2); print(lgi.get_num_threads())"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        env={**os.environ, "RAYON_NUM_THREADS": "3"},
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    ).stdout.split()
    assert out == ["3", "2"]


def test_on_lgi_own_pool_ctrl_c_and_a_failing_callback_still_stop_a_solve_early(  # type: ignore[no-untyped-def]
    sample, sample_model, default_threads
):
    lgi.set_num_threads(2)
    frames = np.repeat(sample.markers_rest[None], 4000, axis=0)
    calls: list[int] = []
    with python_sigint_handler(), pytest.raises(KeyboardInterrupt):
        sample_model.core.solve(frames, progress=sigint_at(10, calls), temporal=True)
    assert 10 < len(calls) < 4000

    def fail_at_4(f: int) -> None:
        if f == 4:
            raise ValueError("stop here")

    with pytest.raises(ValueError, match="stop here"):
        sample_model.core.solve(frames[:50], progress=fail_at_4, temporal=True)
    # The pool is whole afterwards.
    assert lgi.get_num_threads() == 2
    assert sample_model.solve(frames[:3], quiet=True).vertices.shape[0] == 3


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2", _lgi.MAX_THREADS + 1])
def test_set_num_threads_refuses_what_is_not_a_thread_count(bad, default_threads):  # type: ignore[no-untyped-def]
    lgi.set_num_threads(2)
    with pytest.raises(lgi.InputError, match="set_num_threads"):
        lgi.set_num_threads(bad)
    assert lgi.get_num_threads() == 2
