"""The LGI model end to end on the built-in sample: exact interpolation of markers, missing
markers, determinism, persistence, and every bad input as a clear exception."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import lgi


@pytest.fixture(scope="module")
def solved(sample, sample_model):  # type: ignore[no-untyped-def]
    return sample_model.solve(sample.performance, quiet=True)


def test_every_present_marker_is_interpolated_to_1e6_of_the_diagonal(sample_model, solved):  # type: ignore[no-untyped-def]
    assert solved.bundle_residuals.max() <= 1e-6 * sample_model.diagonal
    # The residual is measured independently of the core: barycentric evaluation on the output.
    again = sample_model.bundle_positions(solved.vertices)
    np.testing.assert_allclose(again, solved.bundle_positions, atol=1e-12)


def test_missing_markers_give_finite_vertices_and_are_flagged(sample, sample_model, solved):  # type: ignore[no-untyped-def]
    nan_rows = np.isnan(sample.performance).any(axis=2)
    assert nan_rows.any(), "the sample performance must contain dropouts"
    np.testing.assert_array_equal(solved.missing, nan_rows)
    assert np.isfinite(solved.vertices).all()
    assert np.isfinite(solved.bundle_positions).all()
    # Each frame alone, a missing marker chooses nothing; in a take it is filled first.
    alone = sample_model.solve(sample.performance, steady=False, quiet=True)
    np.testing.assert_array_equal(alone.missing, nan_rows)
    assert (alone.choices.weights[nan_rows] == 0).all()


def test_choices_are_convex_combinations(solved):  # type: ignore[no-untyped-def]
    w = solved.choices.weights[~solved.missing]
    assert (w >= 0).all()
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-12)


def test_reconstruction_is_closer_to_truth_than_the_neutral(sample, sample_dataset, solved):  # type: ignore[no-untyped-def]
    err = np.linalg.norm(solved.vertices - sample.truth, axis=2).mean()
    base = np.linalg.norm(sample_dataset.neutral[None] - sample.truth, axis=2).mean()
    assert err < 0.5 * base, (err, base)


def test_solve_is_deterministic(sample, sample_model, solved):  # type: ignore[no-untyped-def]
    again = sample_model.solve(sample.performance, quiet=True)
    np.testing.assert_array_equal(again.vertices, solved.vertices)
    np.testing.assert_array_equal(again.choices.shapes, solved.choices.shapes)


def test_dataset_shapes_are_reproduced_exactly_by_their_own_markers(sample_dataset, sample_model):  # type: ignore[no-untyped-def]
    meshes = sample_dataset.neutral[None] + sample_dataset.shapes.astype(np.float64)
    res = sample_model.solve(sample_model.bundle_positions(meshes), temporal=False, quiet=True)
    err = np.linalg.norm(res.vertices - meshes, axis=2)
    # Vertices whose sewing weights only involve bundles that chose the shape are exact.
    assert np.median(err) < 1e-5, np.median(err)


def test_save_load_round_trip_gives_identical_results(tmp_path: Path, sample, sample_model, solved):  # type: ignore[no-untyped-def]
    path = tmp_path / "sample.lgi"
    sample_model.save(path)
    loaded = lgi.Model.load(path)
    res = loaded.solve(sample.performance, quiet=True)
    np.testing.assert_array_equal(res.vertices, solved.vertices)


def test_corrupt_truncated_and_foreign_model_files_raise_model_format_error(
    tmp_path: Path, sample_model
):  # type: ignore[no-untyped-def]
    path = tmp_path / "m.lgi"
    sample_model.save(path)
    data = path.read_bytes()
    bad = tmp_path / "bad.lgi"
    bad.write_bytes(data[: len(data) // 2])
    with pytest.raises(lgi.ModelFormatError, match="truncated"):
        lgi.Model.load(bad)
    flipped = bytearray(data)
    flipped[len(data) // 2] ^= 0xFF
    bad.write_bytes(bytes(flipped))
    with pytest.raises(lgi.ModelFormatError, match="checksum"):
        lgi.Model.load(bad)
    bad.write_bytes(b"solid cube\nfacet normal 0 0 1\n")
    with pytest.raises(lgi.ModelFormatError, match="not an lgi model"):
        lgi.Model.load(bad)
    with pytest.raises(lgi.DatasetFileError, match=r"nope\.lgi"):
        lgi.Model.load(tmp_path / "nope.lgi")


def test_frames_of_wrong_shape_or_dtype_raise_input_error_naming_frames(sample, sample_model):  # type: ignore[no-untyped-def]
    with pytest.raises(lgi.InputError, match="frames"):
        sample_model.solve(np.zeros((3, 5, 3)))
    with pytest.raises(lgi.InputError, match="dtype"):
        sample_model.solve(np.zeros((3, sample_model.num_bundles, 3), dtype=np.int32))
    inf = sample.performance[:2].copy()
    inf[1, 4, 0] = np.inf
    with pytest.raises(lgi.InputError, match=r"frame 1, bundle 4"):
        sample_model.solve(inf)


def test_too_many_missing_markers_raise_input_error_naming_the_frame(sample, sample_model):  # type: ignore[no-untyped-def]
    frames = sample.performance[:3].copy()
    frames[2, 2:] = np.nan
    with pytest.raises(lgi.InputError, match="frame 2"):
        sample_model.solve(frames)


def test_a_refused_marker_noise_shows_its_error_and_no_progress_bar(sample, sample_model, capsys):  # type: ignore[no-untyped-def]
    # The bar is on (quiet=False, several frames); the call is refused before it is drawn.
    for bad, message in ((-1.0, "finite distance >= 0"), (float("nan"), "finite distance")):
        with pytest.raises(lgi.InputError, match=message):
            sample_model.solve(sample.performance[:3], marker_noise=bad, quiet=False)
    assert capsys.readouterr().err == ""


def test_marker_far_from_surface_raises_marker_error_naming_it(sample, sample_dataset):  # type: ignore[no-untyped-def]
    markers = sample.markers_rest.copy()
    markers[7] += np.array([0.0, 0.0, 5.0])
    with pytest.raises(lgi.MarkerError, match="marker 7"):
        lgi.Model.build(sample_dataset, markers)


def test_bad_build_config_raises_input_error_naming_the_field(sample, sample_dataset):  # type: ignore[no-untyped-def]
    with pytest.raises(lgi.InputError, match="surface_tolerance"):
        lgi.Model.build(
            sample_dataset, sample.markers_rest, lgi.BuildConfig(surface_tolerance=-1.0)
        )


def test_build_config_defaults_are_the_cores_and_every_field_survives_save_and_load(  # type: ignore[no-untyped-def]
    sample, sample_dataset, sample_model, tmp_path
):
    # A model built without a config uses the core's Default; lgi.BuildConfig() must equal it.
    assert sample_model.core.config == lgi.BuildConfig()
    fields = lgi.BuildConfig().to_dict()
    changed = {
        k: (v + 1 if isinstance(v, int) else (v * 1.5 if np.isfinite(v) else 3.0))
        for k, v in fields.items()
    }
    custom = lgi.BuildConfig(**changed)
    assert custom.to_dict() == changed
    model = lgi.Model.build(sample_dataset, sample.markers_rest, custom)
    model.save(tmp_path / "custom.lgi")
    assert lgi.Model.load(tmp_path / "custom.lgi").config == custom


def test_build_config_is_a_frozen_value_with_keyword_fields():
    import copy
    import pickle

    c = lgi.BuildConfig(max_tets=5000, detour_ratio=float("inf"))
    assert c.max_tets == 5000 and c.detour_ratio == float("inf")
    assert c == lgi.BuildConfig().replace(max_tets=5000, detour_ratio=float("inf"))
    assert c != lgi.BuildConfig() and hash(c) == hash(copy.copy(c))
    assert pickle.loads(pickle.dumps(c)) == c
    assert repr(c).startswith("BuildConfig(surface_tolerance=0.02, ") and "max_tets=5000" in repr(c)
    with pytest.raises(AttributeError):
        c.max_tets = 1  # type: ignore[misc]
    with pytest.raises(lgi.InputError, match=r"BuildConfig\.max_tets: expected a non-negative"):
        lgi.BuildConfig(max_tets=-1)
    with pytest.raises(lgi.InputError, match=r"BuildConfig\.min_quality: expected a number"):
        lgi.BuildConfig(min_quality="high")  # type: ignore[arg-type]
    with pytest.raises(lgi.InputError, match="no field 'tets'"):
        c.replace(tets=3)


def test_inputs_are_not_modified(sample, sample_model):  # type: ignore[no-untyped-def]
    frames = sample.performance[:5].copy()
    before = frames.copy()
    sample_model.solve(frames, quiet=True)
    np.testing.assert_array_equal(frames, before)


def test_non_finite_mesh_in_bundle_positions_raises_input_error_naming_mesh_and_vertex(
    sample, sample_model
):  # type: ignore[no-untyped-def]
    meshes = np.repeat(sample.neutral[None], 2, axis=0)
    meshes[1, 5, 1] = np.inf
    with pytest.raises(lgi.InputError, match=r"mesh 1, vertex 5"):
        sample_model.bundle_positions(meshes)


def test_solve_into_out_writes_the_same_vertices_and_returns_that_array(sample, sample_model):
    frames = np.asarray(sample.performance)[:6]
    fresh = sample_model.solve(frames, quiet=True)
    buf = np.full((6, sample_model.num_vertices, 3), np.nan)
    res = sample_model.solve(frames, quiet=True, out=buf)
    assert res.vertices is buf
    np.testing.assert_array_equal(buf, fresh.vertices)
    # Reused for the next chunk: overwritten, not accumulated.
    other = frames[3:] + 0.01
    res2 = sample_model.solve(other, quiet=True, out=buf[:3])
    np.testing.assert_array_equal(res2.vertices, sample_model.solve(other, quiet=True).vertices)
    np.testing.assert_array_equal(buf[3:], fresh.vertices[3:])


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda f, v: np.zeros((f, v, 3), np.float32), "float64"),
        (lambda f, v: np.zeros((f + 1, v, 3)), "shape"),
        (lambda f, v: np.zeros((f, 3, v)).transpose(0, 2, 1), "C-contiguous"),
        (lambda f, v: [[[0.0] * 3] * v] * f, "float64"),
    ],
)
def test_solve_out_rejects_wrong_dtype_shape_and_layout(sample, sample_model, make, message):
    frames = np.asarray(sample.performance)[:2]
    with pytest.raises(lgi.errors.InputError, match=message):
        sample_model.solve(frames, quiet=True, out=make(2, sample_model.num_vertices))


def test_solve_out_rejects_a_read_only_array(sample, sample_model):
    frames = np.asarray(sample.performance)[:2]
    buf = np.zeros((2, sample_model.num_vertices, 3))
    buf.flags.writeable = False
    with pytest.raises(lgi.errors.InputError, match="writeable"):
        sample_model.solve(frames, quiet=True, out=buf)
    assert not buf.any()


@pytest.mark.parametrize("chunk", [1, 7, 64])
def test_solve_iter_chunks_equal_one_solve_bit_for_bit(sample, sample_dataset, chunk) -> None:  # type: ignore[no-untyped-def]
    model = lgi.Model.build(sample_dataset, sample.markers_rest)  # jaw rig, pose from the fit
    frames = sample.performance[:40]
    for kw in ({}, {"marker_noise": 0.02}):
        whole = model.solve(frames, quiet=True, **kw)
        parts = list(model.solve_iter(frames, chunk=chunk, quiet=True, **kw))
        assert parts[0].vertices.shape[0] == min(chunk, 40) and len(parts) == -(-40 // chunk)
        np.testing.assert_array_equal(np.concatenate([p.vertices for p in parts]), whole.vertices)
        np.testing.assert_array_equal(
            np.concatenate([p.choices.shapes for p in parts]), whole.choices.shapes
        )
        assert whole.jaw_theta is not None
        np.testing.assert_array_equal(
            np.concatenate([p.jaw_theta for p in parts if p.jaw_theta is not None]),
            whole.jaw_theta,
        )


def test_solve_iter_writes_every_chunk_into_one_buffer_and_checks_its_arguments(
    sample, sample_model
) -> None:  # type: ignore[no-untyped-def]
    frames = sample.performance[:20]
    want = sample_model.solve(frames, quiet=True).vertices
    buf = np.empty((8, sample_model.num_vertices, 3))
    got = [p.vertices.copy() for p in sample_model.solve_iter(frames, chunk=8, out=buf, quiet=True)]
    np.testing.assert_array_equal(np.concatenate(got), want)
    assert all(
        np.shares_memory(p.vertices, buf)
        for p in sample_model.solve_iter(frames, chunk=8, out=buf, quiet=True)
    )
    with pytest.raises(lgi.InputError, match="chunk"):
        next(sample_model.solve_iter(frames, chunk=0))
    with pytest.raises(lgi.InputError, match="jaw must be"):
        next(sample_model.solve_iter(frames, jaw=np.zeros((20, 3))))
