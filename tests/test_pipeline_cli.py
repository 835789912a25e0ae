"""The file pipeline end to end, as a TD drives it: files on disk (the sample's neutral with
quads, shape OBJs, a named layout, a C3D take written by ezc3d in millimetres with shuffled
labels and dropouts) -> `lgi build` and `lgi solve` as subprocesses -> the USD read back with
pxr, against `Model.solve` on the same frames; then `lgi export` and `lgi info`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import lgi
from pipeline_files import lgi_cli, write_actor, write_c3d

FPS = 48.0


@pytest.fixture(scope="module")
def actor(tmp_path_factory, sample):  # type: ignore[no-untyped-def]
    return write_actor(tmp_path_factory.mktemp("actor"), sample)


@pytest.fixture(scope="module")
def take_frames(sample) -> np.ndarray:  # type: ignore[no-untyped-def]
    """The performance's first 40 frames in centimetres (the model's unit), NaN dropouts."""
    return np.asarray(sample.performance[:40], dtype=np.float64)


@pytest.fixture(scope="module")
def built(tmp_path_factory, actor, sample, take_frames):  # type: ignore[no-untyped-def]
    """`lgi build` run as a subprocess, and a C3D take in mm with labels in reverse order."""
    out = tmp_path_factory.mktemp("built")
    model_path = out / "actor.lgi"
    r = lgi_cli(
        "build", actor.neutral, actor.shapes, actor.markers, "-o", model_path, "--units", "cm", "-q"
    )
    assert r.returncode == 0, r.stderr
    order = np.arange(len(actor.names))[::-1]
    c3d = out / "take.c3d"
    write_c3d(c3d, take_frames[:, order] * 10.0, [actor.names[i] for i in order], FPS, "mm")
    return model_path, c3d


def reference_frames(take_frames: np.ndarray) -> np.ndarray:
    """What the C3D holds, in the model's centimetres: float32 millimetres (the file's
    precision) divided by 10; NaN where dropped."""
    return (take_frames * 10.0).astype(np.float32).astype(np.float64) / 10.0


def test_lgi_build_keeps_the_marker_names_units_and_the_neutral_quads(built, actor):  # type: ignore[no-untyped-def]
    model = lgi.Model.load(built[0])
    assert model.marker_names == actor.names
    assert model.units == "cm"
    counts, _, _ = model.dataset.polygons
    assert counts.size == actor.num_polygons
    np.testing.assert_array_equal(counts, actor.counts)
    assert (counts == 4).sum() > 1000  # the file really had quads


def test_lgi_solve_writes_a_usd_cache_whose_samples_equal_model_solve(
    built, actor, take_frames, tmp_path
):  # type: ignore[no-untyped-def]
    from pxr import Usd, UsdGeom

    model_path, c3d = built
    usd = tmp_path / "take.usd"
    r = lgi_cli("solve", model_path, c3d, "-o", usd, "-q")
    assert r.returncode == 0, r.stderr
    model = lgi.Model.load(model_path)
    ref = model.solve(reference_frames(take_frames), quiet=True)

    stage = Usd.Stage.Open(str(usd))
    assert stage.GetTimeCodesPerSecond() == FPS
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01)
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh"))
    counts = np.array(mesh.GetFaceVertexCountsAttr().Get())
    assert counts.size == actor.num_polygons
    np.testing.assert_array_equal(counts, actor.counts)
    points = mesh.GetPointsAttr()
    times = points.GetTimeSamples()
    # Time codes start at the C3D header's first frame (1, as a TRC's Frame# would count).
    assert times == [float(t) for t in range(1, take_frames.shape[0] + 1)]
    for f, t in enumerate(times):
        got = np.array(points.Get(t), dtype=np.float64)
        np.testing.assert_allclose(got, ref.vertices[f], rtol=0, atol=1e-6 * model.diagonal)
    st = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st")
    assert st.GetInterpolation() == UsdGeom.Tokens.faceVarying
    assert len(st.GetIndices()) == counts.sum()


def test_lgi_export_turns_the_solved_npz_into_usd_and_an_obj_sequence_with_the_same_faces(
    built, actor, tmp_path
):  # type: ignore[no-untyped-def]
    from pxr import Usd, UsdGeom

    model_path, c3d = built
    npz = tmp_path / "take.npz"
    r = lgi_cli("solve", model_path, c3d, "-o", npz, "--frames", "5:9", "-q")
    assert r.returncode == 0, r.stderr
    res = lgi.io.result.read_result_npz(npz)
    assert res.vertices.shape[0] == 4 and res.start == 6 and res.fps == FPS  # take frame 1 + 5
    usd = tmp_path / "again.usda"
    assert lgi_cli("export", npz, "-o", usd, "-q").returncode == 0
    stage = Usd.Stage.Open(str(usd))
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh")).GetPointsAttr()
    assert points.GetTimeSamples() == [6.0, 7.0, 8.0, 9.0]
    np.testing.assert_array_equal(np.array(points.Get(8.0)), res.vertices[2])
    objs = tmp_path / "objs" / "shot.obj"
    objs.parent.mkdir()
    r = lgi_cli("export", npz, "-o", objs, "-q")
    assert r.returncode == 0, r.stderr
    written = sorted(objs.parent.glob("shot.*.obj"))
    assert [p.name for p in written] == [f"shot.{f:04d}.obj" for f in range(6, 10)]
    back = lgi.Dataset.from_obj(written[1])
    np.testing.assert_array_equal(back.polygons[0], actor.counts)
    np.testing.assert_allclose(back.neutral, res.vertices[1], rtol=0, atol=1e-6)


def test_lgi_info_summarises_model_take_and_usd(built, actor, tmp_path):  # type: ignore[no-untyped-def]
    model_path, c3d = built
    r = lgi_cli("info", model_path)
    assert r.returncode == 0, r.stderr
    assert f"markers: {len(actor.names)} ({actor.names[0]}," in r.stdout
    assert f"{actor.num_polygons} polygons" in r.stdout and "units: cm" in r.stdout
    r = lgi_cli("info", c3d)
    assert r.returncode == 0, r.stderr
    assert "frames: 40" in r.stdout and "units: mm" in r.stdout and "fps 48" in r.stdout


def test_ict_through_the_cli_keeps_its_quads_in_the_usd_and_matches_model_solve(ict_path, tmp_path):  # type: ignore[no-untyped-def]
    """The real data: ICT's neutral OBJ has 25,836 quads and 548 triangles (counted here from
    its `f` lines); the USD must have exactly those faces and model.solve's points."""
    from pxr import Usd, UsdGeom

    neutral = ict_path / "generic_neutral_mesh.obj"
    corners = [
        len(line.split()) - 1 for line in neutral.read_text().splitlines() if line.startswith("f ")
    ]
    model_path = tmp_path / "ict.lgi"
    r = lgi_cli(
        "build", neutral, ict_path / "shapes", ict_path / "markers_120.csv", "-o", model_path,
        "--units", "cm", "-q",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    model = lgi.Model.load(model_path)
    data = model.dataset
    frames = model.bundle_positions(data.neutral + 0.7 * data.shapes[[3, 10, 20, 30, 40, 50]])
    frames[2, 5] = np.nan
    c3d = tmp_path / "ict.c3d"
    write_c3d(c3d, frames * 10.0, model.marker_names, 24.0, "mm")
    usd = tmp_path / "ict.usd"
    r = lgi_cli("solve", model_path, c3d, "-o", usd, "-q")
    assert r.returncode == 0, r.stderr
    ref = model.solve(reference_frames(frames), quiet=True)
    stage = Usd.Stage.Open(str(usd))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh"))
    counts = np.array(mesh.GetFaceVertexCountsAttr().Get())
    np.testing.assert_array_equal(counts, corners)
    assert (counts == 4).sum() == 25836 and (counts == 3).sum() == 548
    points = mesh.GetPointsAttr()
    assert points.GetTimeSamples() == [float(t) for t in range(1, 7)]
    for f in range(6):
        got = np.array(points.Get(f + 1), dtype=np.float64)
        np.testing.assert_allclose(got, ref.vertices[f], rtol=0, atol=1e-6 * model.diagonal)


def test_lgi_info_describes_a_dataset_npz(sample_dataset, tmp_path):  # type: ignore[no-untyped-def]
    p = tmp_path / "d.npz"
    sample_dataset.to_npz(p)
    r = lgi_cli("info", p)
    assert r.returncode == 0, r.stderr
    assert f"neutral: {sample_dataset.num_vertices} vertices" in r.stdout
    assert f"shapes: {sample_dataset.num_shapes}" in r.stdout


def usd_points(path: Path) -> np.ndarray:
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(path))
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh")).GetPointsAttr()
    return np.array([np.array(points.Get(t), dtype=np.float64) for t in points.GetTimeSamples()])


def test_csv_and_trc_takes_solve_like_model_solve_with_noise_auto(
    built, actor, take_frames, tmp_path
):  # type: ignore[no-untyped-def]
    """A CSV (no unit: the model's cm, exact float64 text) and a TRC in mm (written by the
    format description in test_takes) through `lgi solve --marker-noise auto`."""
    from test_takes import write_trc

    model_path, _ = built
    model = lgi.Model.load(model_path)
    x = take_frames[:12]
    csv = tmp_path / "take.csv"
    head = ",".join(f"{n}_{a}" for n in actor.names for a in "xyz")
    rows = [f"time,{head}"] + [
        f"{k / FPS!r}," + ",".join("" if np.isnan(v) else repr(float(v)) for v in x[k].ravel())
        for k in range(len(x))
    ]
    csv.write_text("\n".join(rows) + "\n")
    sigma = lgi.estimate_marker_noise(x, model)  # what --marker-noise auto reads
    ref = model.solve(x, marker_noise=sigma, quiet=True)
    out = tmp_path / "csv.usd"
    r = lgi_cli("solve", model_path, csv, "-o", out, "--marker-noise", "auto", "-q")
    assert r.returncode == 0, r.stderr
    np.testing.assert_allclose(usd_points(out), ref.vertices, rtol=0, atol=1e-6 * model.diagonal)

    trc = tmp_path / "take.trc"
    write_trc(trc, x * 10.0, actor.names, FPS, "mm")
    out = tmp_path / "trc.usd"
    r = lgi_cli("solve", model_path, trc, "-o", out, "--marker-noise", str(sigma), "-q")
    assert r.returncode == 0, r.stderr
    ref = model.solve(x * 10.0 * 0.1, marker_noise=sigma, quiet=True)
    np.testing.assert_allclose(usd_points(out), ref.vertices, rtol=0, atol=1e-6 * model.diagonal)


def test_build_jaw_auto_gives_a_jaw_model_and_solve_jaw_track_tracks_it(
    actor, built, take_frames, tmp_path
):  # type: ignore[no-untyped-def]
    model_path = tmp_path / "jaw.lgi"
    r = lgi_cli(
        "build", actor.neutral, actor.shapes, actor.markers, "-o", model_path, "--units", "cm",
        "--jaw", "auto", "-q",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    model = lgi.Model.load(model_path)
    assert model.jaw_rig is not None
    out = tmp_path / "jaw.npz"
    r = lgi_cli("solve", model_path, built[1], "-o", out, "--frames", "0:8", "--jaw", "track", "-q")
    assert r.returncode == 0, r.stderr
    res = lgi.io.result.read_result_npz(out)
    ref = model.solve(reference_frames(take_frames)[:8], jaw="track", quiet=True)
    np.testing.assert_allclose(res.vertices, ref.vertices, rtol=0, atol=1e-6 * model.diagonal)
    np.testing.assert_allclose(res.jaw_theta, ref.jaw_theta, rtol=0, atol=1e-9)  # radians


@pytest.mark.parametrize("suffix", [".usd", ".npz"])
def test_solve_in_chunks_equals_one_model_solve_of_the_range(built, take_frames, tmp_path, suffix):  # type: ignore[no-untyped-def]
    model_path, c3d = built
    out = tmp_path / f"chunked{suffix}"
    r = lgi_cli("solve", model_path, c3d, "-o", out, "--frames", "3:20", "--chunk", "6", "-q")
    assert r.returncode == 0, r.stderr
    model = lgi.Model.load(model_path)
    x = reference_frames(take_frames)[3:20]
    ref = model.solve(x, quiet=True).vertices
    got = usd_points(out) if suffix == ".usd" else lgi.io.result.read_result_npz(out).vertices
    assert got.shape == ref.shape
    if suffix == ".npz":  # float32 vertices: those of one solve, bit for bit
        assert np.array_equal(got, ref.astype(np.float32))
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-6 * model.diagonal)
