"""`--units`, `--scale` and `--up`: the mesh written in another unit and up axis, read back by
pxr and by a PC2 reader; the head's motion maps consistently with the points."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lgi.errors import InputError
from lgi.io.frame import output_frame
from lgi.io.result import read_result_npz
from pipeline_files import lgi_cli, spiked_sample_take, write_solve
from test_pointcache import read_pc2


@pytest.fixture(scope="module")
def solved(sample, sample_model, tmp_path_factory):  # type: ignore[no-untyped-def]
    frames = spiked_sample_take(sample, sample_model)[:20]
    return write_solve(tmp_path_factory.mktemp("frame") / "take.npz", sample_model, frames, None)


def test_usd_in_metres_z_up_has_its_metadata_and_the_points_rotated_and_scaled(
    solved: Path, tmp_path: Path
) -> None:
    from pxr import Usd, UsdGeom

    r = read_result_npz(solved)
    out = tmp_path / "m.usda"
    p = lgi_cli("export", solved, "-o", out, "--units", "m", "--up", "z", "-q")
    assert p.returncode == 0, p.stderr
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    got = np.array(UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh")).GetPointsAttr().Get(101))
    v = r.vertices[1].astype(np.float64) / 100.0  # cm -> m
    want = np.stack([v[:, 0], -v[:, 2], v[:, 1]], axis=1)  # Y up -> Z up
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-7)


def test_a_pc2_in_mm_is_ten_times_the_cm_solve(solved: Path, tmp_path: Path) -> None:
    r = read_result_npz(solved)
    out = tmp_path / "mm.pc2"
    assert lgi_cli("export", solved, "-o", out, "--units", "mm", "-q").returncode == 0
    _, _, v = read_pc2(out)
    np.testing.assert_allclose(v, r.vertices * 10.0, rtol=1e-6)
    out2 = tmp_path / "s.pc2"
    assert lgi_cli("export", solved, "-o", out2, "--scale", "2.5", "-q").returncode == 0
    np.testing.assert_allclose(read_pc2(out2)[2], r.vertices * 2.5, rtol=1e-6)


def test_mistakes_with_the_output_frame_are_refused(solved: Path, tmp_path: Path) -> None:
    p = lgi_cli("export", solved, "-o", tmp_path / "x.npz", "--up", "z")
    assert p.returncode == 2 and "a solved .npz stays in the model's frame" in p.stderr
    p = lgi_cli("export", solved, "-o", tmp_path / "x.usd", "--units", "m", "--scale", "2")
    assert p.returncode == 2 and "--units and --scale: give one" in p.stderr
    with pytest.raises(InputError, match="the model has no unit to convert from"):
        output_frame(None, units="m")


def test_the_head_motion_maps_with_the_points() -> None:
    rng = np.random.default_rng(1)
    f = output_frame("cm", units="m", up="z")
    for _ in range(5):
        r = Rotation.random(random_state=rng).as_matrix()
        t, p = rng.normal(size=3), rng.normal(size=(7, 3))
        moved = p @ r.T + t
        # Mapping the moved points equals moving the mapped points by the mapped motion.
        np.testing.assert_allclose(
            f.points(moved), f.points(p) @ f.rotations(r).T + f.points(t), atol=1e-12
        )
