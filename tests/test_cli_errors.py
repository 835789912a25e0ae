"""Every user mistake on the command line ends as `lgi: error: ...` on stderr and exit status 2
(no traceback): missing, garbled or wrong-kind files, bad options, names that do not match,
outputs that cannot be written. Run in-process (`lgi.app.cli.main`); the subprocess path is
`test_pipeline_cli.py`'s."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lgi.app import cli
from pipeline_files import build_actor, write_c3d


def run(capsys: pytest.CaptureFixture[str], *argv: str | Path) -> tuple[int, str]:
    try:
        code = cli.main([str(a) for a in argv])
    except SystemExit as e:  # argparse's own errors
        code = int(e.code or 0)
    err = capsys.readouterr().err
    return code, err


def assert_user_error(capsys: pytest.CaptureFixture[str], match: str, *argv: str | Path) -> None:
    code, err = run(capsys, *argv)
    assert code == 2, err
    assert "lgi: error:" in err and "Traceback" not in err, err
    assert match in err, err


@pytest.fixture(scope="module")
def files(tmp_path_factory, sample):  # type: ignore[no-untyped-def]
    """A small actor on disk (8 shapes), its model built through the CLI, and takes."""
    d = tmp_path_factory.mktemp("cli")
    actor, model = build_actor(d, sample)
    c3d = d / "take.c3d"
    write_c3d(c3d, np.asarray(sample.performance[:5]), actor.names, 30.0, "cm")
    csv = d / "take.csv"
    head = ",".join(f"{n}_{a}" for n in actor.names for a in "xyz")
    csv.write_text(
        "frame,"
        + head
        + "\n"
        + "\n".join(
            f"{k},"
            + ",".join("" if np.isnan(v) else repr(float(v)) for v in sample.performance[k].ravel())
            for k in range(3)
        )
        + "\n"
    )
    return {"dir": d, "actor": actor, "model": model, "c3d": c3d, "csv": csv}


# --- lgi build ----------------------------------------------------------------------------


def test_build_mistakes(files, capsys, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    a = files["actor"]
    out = tmp_path / "m.lgi"
    base = [a.neutral, a.shapes, a.markers, "-o", out]
    assert_user_error(
        capsys,
        "NEUTRAL nope.obj: no such file",
        "build",
        "nope.obj",
        a.shapes,
        a.markers,
        "-o",
        out,
    )
    bad_suffix = tmp_path / "neutral.fbx"
    bad_suffix.write_text("x")
    assert_user_error(
        capsys,
        "expected .obj, .gltf, .glb or .npz",
        "build",
        bad_suffix,
        a.shapes,
        a.markers,
        "-o",
        out,
    )
    empty = tmp_path / "empty"
    empty.mkdir()
    assert_user_error(
        capsys, "holds no .obj files", "build", a.neutral, empty, a.markers, "-o", out
    )
    assert_user_error(
        capsys,
        "SHAPES nowhere: no such folder",
        "build",
        a.neutral,
        "nowhere",
        a.markers,
        "-o",
        out,
    )
    assert_user_error(
        capsys,
        "MARKERS none.csv: no such file",
        "build",
        a.neutral,
        a.shapes,
        "none.csv",
        "-o",
        out,
    )
    garbled = tmp_path / "markers.csv"
    garbled.write_text("name,x,y,z\nm0,1,2\n")
    assert_user_error(
        capsys, f"{garbled}, line 2: 3 columns", "build", a.neutral, a.shapes, garbled, "-o", out
    )
    assert_user_error(capsys, "is a folder", "build", *base[:3], "-o", tmp_path)
    assert_user_error(capsys, "does not exist", "build", *base[:3], "-o", tmp_path / "no" / "m.lgi")
    cfg = tmp_path / "cfg.json"
    cfg.write_text("{not json")
    assert_user_error(capsys, "not a JSON file", "build", *base, "--config", cfg)
    cfg.write_text('{"max_tet": 5}')
    assert_user_error(capsys, "unknown fields ['max_tet']", "build", *base, "--config", cfg)
    cfg.write_text('{"max_tets": -5}')
    assert_user_error(capsys, "max_tets", "build", *base, "--config", cfg)
    assert_user_error(capsys, "unknown length unit 'parsec'", "build", *base, "--units", "parsec")
    assert_user_error(capsys, "invalid choice", "build", *base, "--jaw", "maybe")
    assert_user_error(capsys, "required: -o/--out", "build", *base[:3])
    before = a.markers.read_bytes()
    assert_user_error(capsys, "is an input of the command", "build", *base[:3], "-o", a.markers)
    assert a.markers.read_bytes() == before
    shape = sorted(a.shapes.glob("*.obj"))[0]
    want = "is an input of the command"
    assert_user_error(capsys, want, "build", a.neutral, shape, a.markers, "-o", shape)
    far = tmp_path / "far.csv"
    far.write_text(
        "name,x,y,z\n" + "\n".join(f"{n},{1e3 + i},0,0" for i, n in enumerate(a.names)) + "\n"
    )
    want = f"MARKERS {far}: marker 0 is"
    assert_user_error(capsys, want, "build", a.neutral, a.shapes, far, "-o", out)
    assert_user_error(capsys, f"({a.names[0]!r})", "build", a.neutral, a.shapes, far, "-o", out)
    assert not out.exists()


def test_build_jaw_auto_without_a_jaw_open_shape_builds_without_a_rig_and_says_so(
    files, capsys, tmp_path: Path
) -> None:  # type: ignore[no-untyped-def]
    a = files["actor"]
    shapes = tmp_path / "shapes"
    shapes.mkdir()
    for p in sorted(a.shapes.glob("*.obj")):
        if p.stem != "jawOpen":
            (shapes / p.name).write_bytes(p.read_bytes())
    out = tmp_path / "m.lgi"
    code, err = run(capsys, "build", a.neutral, shapes, a.markers, "-o", out, "--jaw", "auto")
    assert code == 0, err
    assert "without a jaw rig" in err
    import lgi

    assert lgi.Model.load(out).jaw_rig is None


# --- lgi solve ----------------------------------------------------------------------------


def test_solve_mistakes(files, capsys, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    m, c3d = files["model"], files["c3d"]
    out = tmp_path / "o.usd"
    assert_user_error(capsys, "MODEL none.lgi: no such file", "solve", "none.lgi", c3d, "-o", out)
    junk = tmp_path / "junk.lgi"
    junk.write_bytes(b"not a model at all, really not" * 3)
    assert_user_error(capsys, "not an lgi model file", "solve", junk, c3d, "-o", out)
    assert_user_error(capsys, "TAKE none.c3d: no such file", "solve", m, "none.c3d", "-o", out)
    assert_user_error(
        capsys, "unknown output format '.fbx'", "solve", m, c3d, "-o", tmp_path / "o.fbx"
    )
    assert_user_error(capsys, "is a folder", "solve", m, c3d, "-o", tmp_path)
    assert_user_error(capsys, "is an input of the command", "solve", m, c3d, "-o", m)
    for spec, msg in [
        ("9:2", "START must be < END"),
        ("0:99", "the take has frames 0:5"),
        ("a:b", "expected START:END"),
    ]:
        assert_user_error(capsys, msg, "solve", m, c3d, "-o", out, "--frames", spec)
    assert_user_error(
        capsys, "expected a number", "solve", m, c3d, "-o", out, "--marker-noise", "lots"
    )
    assert_user_error(
        capsys, "must be a finite number >= 0", "solve", m, c3d, "-o", out, "--marker-noise", "-1"
    )
    assert_user_error(
        capsys, "--fps -3.0: must be a positive number", "solve", m, c3d, "-o", out, "--fps", "-3"
    )
    assert_user_error(capsys, "has no frame rate; pass --fps", "solve", m, files["csv"], "-o", out)
    assert_user_error(
        capsys, "unknown length unit", "solve", m, c3d, "-o", out, "--take-units", "cubits"
    )
    assert not out.exists()


def test_solve_names_that_do_not_match_are_listed_and_allow_missing_solves(
    files, capsys, tmp_path: Path, sample
) -> None:  # type: ignore[no-untyped-def]
    names = list(files["actor"].names)
    names[3] = "typo"
    c3d = tmp_path / "renamed.c3d"
    write_c3d(c3d, np.asarray(sample.performance[:3]), names, 30.0, "cm")
    out = tmp_path / "o.npz"
    assert_user_error(
        capsys,
        f"not in the take: {files['actor'].names[3]}",
        "solve",
        files["model"],
        c3d,
        "-o",
        out,
    )
    code, err = run(capsys, "solve", files["model"], c3d, "-o", out, "--allow-missing", "-q")
    assert code == 0, err
    from lgi.io.result import read_result_npz

    r = read_result_npz(out)
    assert r.missing[:, 3].all() and np.isfinite(r.vertices).all()


def test_solve_a_take_in_mm_for_a_model_without_units_is_refused(
    files, capsys, tmp_path: Path, sample
) -> None:  # type: ignore[no-untyped-def]
    a = files["actor"]
    model = tmp_path / "nounits.lgi"
    assert run(capsys, "build", a.neutral, a.shapes, a.markers, "-o", model, "-q")[0] == 0
    c3d = tmp_path / "mm.c3d"
    write_c3d(c3d, np.asarray(sample.performance[:2]) * 10, a.names, 30.0, "mm")
    assert_user_error(capsys, "model has no unit", "solve", model, c3d, "-o", tmp_path / "o.usd")


# --- lgi export, lgi info -----------------------------------------------------------------


def test_export_and_info_mistakes(files, capsys, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    npz = tmp_path / "r.npz"
    np.savez(npz, something=np.zeros(3))
    assert_user_error(capsys, "not a solved take", "export", npz, "-o", tmp_path / "o.usd")
    assert_user_error(
        capsys, "RESULT none.npz: no such file", "export", "none.npz", "-o", tmp_path / "o.usd"
    )
    good = tmp_path / "good.npz"
    assert run(capsys, "solve", files["model"], files["c3d"], "-o", good, "-q")[0] == 0
    assert_user_error(capsys, "is an input of the command", "export", good, "-o", good)
    assert_user_error(capsys, "FILE none.lgi: no such file", "info", "none.lgi")
    odd = tmp_path / "x.fbx"
    odd.write_text("x")
    assert_user_error(capsys, "unknown file kind '.fbx'", "info", odd)
    garbage = tmp_path / "garbage.npz"
    garbage.write_text("not a zip")
    assert_user_error(capsys, "not a readable .npz archive", "info", garbage)


# --- lgi demo, lgi evaluate (the cases that ended in tracebacks) --------------------------


def test_demo_and_evaluate_out_and_seed_mistakes(capsys, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    f = tmp_path / "file"
    f.write_text("x")
    assert_user_error(capsys, "is a file; --out is a folder", "demo", "--out", f)
    assert_user_error(capsys, "is a file, not a folder", "demo", "--out", f / "sub")
    assert_user_error(capsys, "a seed is an integer in 0..2^32-1", "demo", "--seed", "-1")
    assert_user_error(capsys, "is a file; --out is a folder", "evaluate", "--out", f)


@pytest.mark.parametrize("command", ["demo", "evaluate", "helmet-demo"])
def test_folder_commands_refuse_a_folder_that_holds_files_unless_forced(
    capsys, tmp_path: Path, command: str
) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "results"
    out.mkdir()
    (out / "report.md").write_text("an earlier run's")
    code, err = run(capsys, command, "--out", out, "-q")
    assert code == 2 and "Traceback" not in err, err
    assert f"lgi: error: --out {out}: the folder already holds 1 entry (report.md)" in err
    assert "use --force" in err
    assert (out / "report.md").read_text() == "an earlier run's"
    assert [p.name for p in out.iterdir()] == ["report.md"]


@pytest.mark.parametrize("markers", [None, "name,x,y,z\nm000,1,2\n"])
def test_evaluate_ict_with_a_missing_or_garbled_marker_layout(
    capsys, tmp_path: Path, markers: str | None
) -> None:  # type: ignore[no-untyped-def]
    ict = tmp_path / "ict-facekit"
    (ict / "shapes").mkdir(parents=True)
    tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n"
    (ict / "generic_neutral_mesh.obj").write_text(tri)
    (ict / "shapes" / "s.obj").write_text(tri)
    if markers is not None:
        (ict / "markers_120.csv").write_text(markers)
    want = "line 2: 3 columns" if markers else "cannot read the marker layout"
    assert_user_error(
        capsys, want, "evaluate", "--data", "ict", "--ict-dir", ict, "--out", tmp_path / "o"
    )


def test_solve_chunk_must_be_a_positive_whole_number(files, capsys, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "o.usd"
    for bad in ["0", "-2", "x"]:
        assert_user_error(
            capsys, "--chunk", "solve", files["model"], files["c3d"], "-o", out, "--chunk", bad
        )


def test_info_take_with_model_lists_what_does_not_match(
    files, capsys, tmp_path: Path, sample
) -> None:  # type: ignore[no-untyped-def]
    code, out = run_out(capsys, "info", files["c3d"], "--model", files["model"])
    assert code == 0 and f"matches the model's {len(files['actor'].names)} markers" in out
    names = list(files["actor"].names)
    lost, names[2] = names[2], "extra"
    c3d = tmp_path / "odd.c3d"
    write_c3d(c3d, np.asarray(sample.performance[:2]), names, 30.0, "cm")
    code, out = run_out(capsys, "info", c3d, "--model", files["model"])
    assert code == 0
    assert f"model markers not in the take (1): {lost}" in out
    assert "take labels not in the model (1): extra" in out
    assert_user_error(capsys, "--model none.lgi: no such file", "info", c3d, "--model", "none.lgi")


def run_out(capsys: pytest.CaptureFixture[str], *argv: str | Path) -> tuple[int, str]:
    code = cli.main([str(a) for a in argv])
    return code, capsys.readouterr().out
