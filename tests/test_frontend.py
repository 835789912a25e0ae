"""The front end in one call and on the command line: `process` equals the stages run by hand,
`lgi triangulate` writes what `process` computes, bad files give `lgi: error:` naming the file
and exit 2, and `lgi helmet-demo` reports every stage."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lgi.app import cli
from lgi.capture import frontend
from lgi.capture.calibration import save_cameras
from lgi.capture.stabilize import align, despike, stable_weights
from lgi.capture.triangulation import triangulate
from lgi.lab.helmet import head_motion, helmet_cameras, make_helmet_take


@pytest.fixture(scope="module")
def take():  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(0)
    rest = rng.uniform([-6, -8, 4], [6, 8, 11], size=(40, 3))
    local = np.repeat(rest[None], 30, axis=0)
    local[:, :8] += rng.normal(0, 0.3, size=(30, 8, 3))  # a few expressive markers
    cams = helmet_cameras(rest)
    motion = head_motion(30, rest, seed=1)
    return rest, cams, make_helmet_take(local, cams, motion, seed=2)


def test_process_equals_the_stages_run_by_hand(take) -> None:  # type: ignore[no-untyped-def]
    rest, cams, t = take
    front = frontend.process(cams, t.uv, rest)
    tri = triangulate(cams, t.uv, max_error=3.0)
    al = align(tri.points, rest, stable_weights(tri.points, rest))
    frames, spikes = despike(al.frames)
    np.testing.assert_array_equal(front.frames, frames)
    np.testing.assert_array_equal(front.spikes, spikes)
    np.testing.assert_array_equal(front.alignment.rotations, al.rotations)
    assert "triangulation:" in front.summary() and "despike:" in front.summary()


def test_cli_triangulate_writes_the_stabilised_bundles(take, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    rest, cams, t = take
    save_cameras(tmp_path / "rig.yaml", cams)
    np.savez(tmp_path / "tracks.npz", uv=t.uv)
    rows = "\n".join(f"m{i},{x},{y},{z}" for i, (x, y, z) in enumerate(rest))
    (tmp_path / "rest.csv").write_text("name,x,y,z\n" + rows + "\n")
    out = tmp_path / "bundles.npz"
    argv = ["triangulate", "--cameras", str(tmp_path / "rig.yaml"), "--tracks"]
    argv += [str(tmp_path / "tracks.npz"), "--rest", str(tmp_path / "rest.csv")]
    assert cli.main([*argv, "--out", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    want = frontend.process(cams, t.uv, rest)
    with np.load(out) as z:
        np.testing.assert_allclose(z["frames"], want.frames, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(z["views"], want.triangulation.views)
        assert z["rotations"].shape == (30, 3, 3)
    # The bundles file is a take: `lgi solve` reads it by label, the head transform with it.
    from lgi.io import takes

    read = takes.read(out, [f"m{i}" for i in range(len(rest))][::-1])
    np.testing.assert_array_equal(read.frames, want.frames[:, ::-1])
    assert read.head is not None
    np.testing.assert_array_equal(read.head.rotations, want.alignment.rotations)
    np.testing.assert_array_equal(read.head.translations, want.alignment.translations)


def test_cli_triangulate_names_the_bad_file_and_exits_2(take, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    rest, cams, t = take
    save_cameras(tmp_path / "rig.yaml", cams)
    np.savez(tmp_path / "tracks.npz", wrong=t.uv)
    np.save(tmp_path / "rest.npy", rest)
    argv = ["triangulate", "--cameras", str(tmp_path / "rig.yaml"), "--rest"]
    argv += [str(tmp_path / "rest.npy"), "--out", str(tmp_path / "b.npz"), "--tracks"]
    assert cli.main([*argv, str(tmp_path / "tracks.npz")]) == 2
    assert "tracks.npz: no array 'uv'" in capsys.readouterr().err
    np.savez(tmp_path / "three.npz", uv=np.zeros((2, 40, 3, 2)))
    assert cli.main([*argv, str(tmp_path / "three.npz")]) == 2
    assert "uv must be (F, B, 2, 2)" in capsys.readouterr().err
    assert not (tmp_path / "b.npz").exists()


def test_cli_helmet_demo_reports_every_stage(tmp_path: Path) -> None:
    assert cli.main(["helmet-demo", "--out", str(tmp_path), "-q"]) == 0
    report = (tmp_path / "helmet_report.md").read_text()
    for stage in ("triangulation:", "stabilisation:", "despike:", "head rotation error"):
        assert stage in report
    assert (tmp_path / "helmet.yaml").is_file() and (tmp_path / "tracks.npz").is_file()
