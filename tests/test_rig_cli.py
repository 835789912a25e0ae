"""`lgi rig MODEL NEUTRAL SHAPES -o OUT`: the actor rig written as USD, glTF or `.npz` equals
`lgi.solve.rig.actor_rig` on the same inputs; every mistake is `lgi: error: ...` and exit 2."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import lgi
from lgi.app import cli
from lgi.solve import rig
from pipeline_files import write_actor


def run(capsys: pytest.CaptureFixture[str], *argv: str | Path) -> tuple[int, str]:
    try:
        code = cli.main([str(a) for a in argv])
    except SystemExit as e:  # argparse's own errors
        code = int(e.code or 0)
    return code, capsys.readouterr().err


@pytest.fixture(scope="module")
def actor(tmp_path_factory, sample):  # type: ignore[no-untyped-def]
    d = tmp_path_factory.mktemp("rig")
    files = write_actor(d, sample, num_shapes=6)
    model = d / "actor.lgi"
    argv = ["build", files.neutral, files.shapes, files.markers, "-o", model, "-q", "--jaw", "none"]
    assert cli.main([str(x) for x in argv]) == 0
    return files, model


def test_rig_command_writes_the_actor_rig_in_each_format(actor, capsys, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    files, model = actor
    template = lgi.Dataset.from_obj(files.neutral, str(files.shapes / "*.obj"))
    a, b = template.names[:2]
    expected = rig.actor_rig(lgi.Model.load(model), template, [[a, b]], quiet=True)
    for name in ["rig.npz", "rig.glb", "rig.usda"]:
        out = tmp_path / name
        code, err = run(
            capsys,
            "rig",
            model,
            files.neutral,
            files.shapes,
            "-o",
            out,
            "--combine",
            f"{a}+{b}",
            "-q",
        )
        assert code == 0, err
        assert out.is_file()
    back = lgi.Dataset.from_npz(tmp_path / "rig.npz")
    assert back.names == expected.names and back.names[-1] == f"corrective_{a}_{b}"
    assert np.array_equal(back.shapes, expected.shapes)
    assert lgi.Dataset.from_gltf(tmp_path / "rig.glb").names == expected.names


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (["--combine", "jawOpen"], "--combine 'jawOpen': expected template shape names joined"),
        (["--combine", "jawOpen+nope"], "the template has no shape 'nope'"),
        (["--marker-noise", "auto"], "no take to estimate it from"),
        (["--marker-noise", "-1"], "--marker-noise -1: must be a finite number >= 0"),
    ],
)
def test_rig_mistakes_are_user_errors(
    actor, capsys, tmp_path: Path, extra: list[str], match: str
) -> None:  # type: ignore[no-untyped-def]
    files, model = actor
    code, err = run(
        capsys, "rig", model, files.neutral, files.shapes, "-o", tmp_path / "r.usd", *extra
    )
    assert code == 2 and "lgi: error:" in err and "Traceback" not in err, err
    assert match in err, err


def test_rig_file_mistakes_are_user_errors(actor, capsys, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    files, model = actor
    npz = tmp_path / "template.npz"
    lgi.Dataset.from_obj(files.neutral, str(files.shapes / "*.obj")).to_npz(npz)
    cases = [
        (
            ["rig", model, files.neutral, files.shapes, "-o", tmp_path / "r.fbx"],
            "unknown rig format",
        ),
        (
            ["rig", tmp_path / "none.lgi", files.neutral, files.shapes, "-o", tmp_path / "r.usd"],
            "no such file",
        ),
        (["rig", model, npz, "-", "-o", npz], "is an input of the command"),
        (
            ["rig", model, files.neutral, files.shapes, "-o", tmp_path / "no" / "r.usd"],
            "does not exist",
        ),
    ]
    for argv, match in cases:
        code, err = run(capsys, *argv)
        assert code == 2 and "lgi: error:" in err and match in err, err
    other = tmp_path / "other.npz"
    x = np.eye(4, 3)
    lgi.Dataset.from_arrays(x, [[0, 1, 2], [0, 2, 3]], np.zeros((1, 4, 3))).to_npz(other)
    code, err = run(capsys, "rig", model, other, "-", "-o", tmp_path / "r.usd")
    assert code == 2 and "template: 4 vertices" in err, err


def test_rig_in_metres_z_up_holds_the_neutral_and_offsets_turned_and_scaled(
    tmp_path_factory, sample, capsys, tmp_path: Path
) -> None:  # type: ignore[no-untyped-def]
    from pxr import Usd, UsdGeom, UsdSkel

    d = tmp_path_factory.mktemp("rig-cm")
    files = write_actor(d, sample, num_shapes=4)
    model = d / "actor.lgi"
    argv = ["build", files.neutral, files.shapes, files.markers, "-o", model, "--units", "cm"]
    assert cli.main([str(x) for x in [*argv, "-q", "--jaw", "none"]]) == 0
    out = tmp_path / "rig.usda"
    code, err = run(
        capsys, "rig", model, files.neutral, files.shapes, "-o", out, "--units", "m", "--up", "z"
    )
    assert code == 0, err
    template = lgi.Dataset.from_obj(files.neutral, str(files.shapes / "*.obj"))
    expected = rig.actor_rig(lgi.Model.load(model), template, [], quiet=True)
    turn = lambda p: np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1) / 100.0  # noqa: E731
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    face = UsdGeom.Mesh(stage.GetPrimAtPath("/Rig/Face"))
    np.testing.assert_allclose(
        np.array(face.GetPointsAttr().Get()), turn(np.asarray(expected.neutral)), atol=1e-7
    )
    first = UsdSkel.BlendShape(stage.GetPrimAtPath(f"/Rig/Face/{expected.names[0]}"))
    idx = np.array(first.GetPointIndicesAttr().Get())
    np.testing.assert_allclose(
        np.array(first.GetOffsetsAttr().Get()),
        turn(np.asarray(expected.shapes[0])[idx]),
        atol=1e-7,
    )
    code, err = run(
        capsys, "rig", model, files.neutral, files.shapes, "-o", tmp_path / "r.glb", "--up", "z"
    )
    assert code == 2 and "glTF is Y up by its specification" in err
