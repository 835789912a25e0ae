"""Outputs are whole or absent, never mixed, never replaced without `--force`, and Ctrl-C ends a
command at once with one line and exit 130: a writer interrupted mid-way leaves nothing at the
final path and no temporary beside it; an existing output is refused before any work; a
folder lgi cannot write to fails before the solve."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import lgi
from lgi.app import cli
from lgi.app.interrupt import deferred_interrupt
from lgi.io import sink as sink_module
from lgi.io.result import read_result_npz
from pipeline_files import build_actor, write_c3d

FRAMES = 120  # > 2 chunks of pipeline.CHUNK_FRAMES, so a write can be stopped mid-way


@pytest.fixture(scope="module")
def files(tmp_path_factory, sample):  # type: ignore[no-untyped-def]
    d = tmp_path_factory.mktemp("outputs")
    actor, model = build_actor(d, sample)
    take = d / "take.c3d"
    write_c3d(take, np.asarray(sample.performance[:FRAMES]), actor.names, 30.0, "cm")
    return {"model": model, "take": take}


def _leftovers(folder: Path) -> list[str]:
    """Hidden temporaries (files or staging folders) lgi left in `folder`."""
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def _solve(files, out: Path, *extra: str) -> int:  # type: ignore[no-untyped-def]
    argv = ["solve", files["model"], files["take"], "-o", out, "-q", *extra]
    return cli.main([str(a) for a in argv])


@pytest.mark.parametrize("name", ["take.usd", "take.usda", "take.npz", "seq/take.obj"])
def test_a_write_interrupted_mid_way_leaves_nothing_at_the_final_path(
    files, tmp_path: Path, monkeypatch, capsys, name: str
) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / name
    out.parent.mkdir(exist_ok=True)
    calls = []
    add = sink_module.FrameSink.add

    def add_then_interrupt(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        calls.append(1)
        if len(calls) == 2:  # the second chunk: the first is already written somewhere
            raise KeyboardInterrupt
        return add(self, *args, **kwargs)

    monkeypatch.setattr(sink_module.FrameSink, "add", add_then_interrupt)
    assert _solve(files, out) == 130
    assert capsys.readouterr().err == "lgi: interrupted\n"
    assert len(calls) == 2
    assert not out.exists()
    assert list(out.parent.glob("take*")) == []
    assert _leftovers(out.parent) == []


def test_an_npz_whose_bytes_stop_half_way_is_not_left_at_the_final_path(
    files, tmp_path: Path, monkeypatch, capsys
) -> None:  # type: ignore[no-untyped-def]
    def half_then_interrupt(fh, array, **kw):  # type: ignore[no-untyped-def]
        # The vertices are in the zip, the first small array half written: then Ctrl-C.
        fh.write(b"\x93NUMPY" + b"\0" * 100)
        raise KeyboardInterrupt

    monkeypatch.setattr(np.lib.format, "write_array", half_then_interrupt)
    out = tmp_path / "take.npz"
    assert _solve(files, out) == 130
    assert not out.exists() and _leftovers(tmp_path) == []


def test_model_save_over_an_existing_model_is_whole_and_leaves_no_temporary(
    files, tmp_path: Path
) -> None:  # type: ignore[no-untyped-def]
    m = lgi.Model.load(files["model"])
    target = tmp_path / "copy.lgi"
    target.write_bytes(b"an older file")
    m.save(target)
    assert lgi.Model.load(target).num_bundles == m.num_bundles
    assert _leftovers(tmp_path) == []


def test_an_existing_output_is_refused_before_solving_and_replaced_with_force(
    files, tmp_path: Path, monkeypatch, capsys
) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "take.npz"
    out.write_bytes(b"an earlier solve")
    solved = []
    real = lgi.Model.solve
    monkeypatch.setattr(lgi.Model, "solve", lambda *a, **k: solved.append(1) or real(*a, **k))
    assert _solve(files, out) == 2
    err = capsys.readouterr().err
    assert f"lgi: error: --out {out}: exists (use --force to replace it)" in err
    assert solved == [] and out.read_bytes() == b"an earlier solve"
    assert _solve(files, out, "--force") == 0
    assert solved == [1]
    assert read_result_npz(out).vertices.shape[0] == FRAMES


def test_an_obj_sequence_over_a_longer_one_never_mixes(files, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "seq" / "shot.obj"
    out.parent.mkdir()
    assert _solve(files, out) == 0
    assert len(list(out.parent.glob("shot.*.obj"))) == FRAMES
    # A shorter range over it: refused, naming the old sequence; with --force, only the new.
    assert _solve(files, out, "--frames", "0:10") == 2
    err = capsys.readouterr().err
    assert f"the sequence shot.NNNN.obj exists ({FRAMES} frames" in err
    assert len(list(out.parent.glob("shot.*.obj"))) == FRAMES
    assert _solve(files, out, "--frames", "0:10", "--force") == 0
    names = sorted(p.name for p in out.parent.iterdir())
    assert names == [f"shot.{k:04d}.obj" for k in range(1, 11)]  # from the C3D's first frame


def test_a_folder_that_cannot_be_written_fails_before_the_solve(
    files, tmp_path: Path, monkeypatch, capsys
) -> None:  # type: ignore[no-untyped-def]
    monkeypatch.setattr(lgi.Model, "solve", lambda *a, **k: pytest.fail("solved before failing"))
    if os.geteuid() != 0:
        locked = tmp_path / "locked"
        locked.mkdir()
        locked.chmod(0o555)
        try:
            assert _solve(files, locked / "take.usd") == 2
        finally:
            locked.chmod(0o755)
        err = capsys.readouterr().err
        assert "cannot write to the folder" in err and "permission denied" in err
    # Root writes anywhere a permission allows; /proc refuses new files to everyone.
    if Path("/proc").is_dir():
        assert _solve(files, Path("/proc/take.usd")) == 2
        err = capsys.readouterr().err
        assert "lgi: error: --out /proc/take.usd: cannot write to the folder /proc" in err
        assert "Tf" not in err and "Traceback" not in err


def test_ctrl_c_during_a_deferred_block_is_raised_after_it_never_swallowed() -> None:
    reached = []
    with pytest.raises(KeyboardInterrupt), deferred_interrupt():
        os.kill(os.getpid(), signal.SIGINT)
        reached.append("the block went on")  # an import that must not be torn apart
    assert reached == ["the block went on"]


_DRIVER = """
import os, signal, sys
import lgi
from lgi.app.main import entry
real = lgi.Model.solve
def solve_then_ctrl_c(*a, **k):
    os.kill(os.getpid(), signal.SIGINT)
    return real(*a, **k)
if sys.argv[1] == "solve":
    lgi.Model.solve = solve_then_ctrl_c
else:
    from lgi.io import usd
    add = usd.UsdCache.add
    calls = []
    def add_then_ctrl_c(self, *a, **k):
        calls.append(1)
        if len(calls) == 2:
            os.kill(os.getpid(), signal.SIGINT)
        return add(self, *a, **k)
    usd.UsdCache.add = add_then_ctrl_c
sys.argv = ["lgi", "solve", sys.argv[2], sys.argv[3], "-o", sys.argv[4], "-q"]
entry()
"""


def _sigint_default() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize("when", ["solve", "write"])
def test_a_real_sigint_ends_the_command_with_one_line_and_exit_130(
    files, tmp_path: Path, when: str
) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "take.usd"
    p = subprocess.run(
        [
            sys.executable,
            "-c",
            textwrap.dedent(_DRIVER),
            when,
            *map(str, (files["model"], files["take"], out)),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        # A process started in the background by a shell inherits SIGINT ignored, and Python
        # then keeps ignoring it: the driver starts from the default, as a terminal's command.
        preexec_fn=_sigint_default,
    )
    assert p.returncode == 130, p.stderr
    assert p.stderr == "lgi: interrupted\n"
    assert not out.exists() and _leftovers(tmp_path) == []


def _lgi_command() -> list[str]:
    """The installed `lgi` console script (the wheel's entry point) beside this Python."""
    script = Path(sys.executable).with_name("lgi")
    if not script.is_file():
        pytest.skip(f"no lgi console script beside {sys.executable} (install the wheel)")
    return [str(script)]


@pytest.mark.parametrize("after", [0.05, 0.1, 0.2, 0.3, 0.5])
def test_ctrl_c_at_any_moment_of_the_command_start_is_one_line_and_exit_130(
    files, tmp_path: Path, after: float
) -> None:  # type: ignore[no-untyped-def]
    """A real SIGINT `after` seconds into `lgi solve` (while Python imports numpy, the core and
    USD, or later, solving): `lgi: interrupted`, exit 130, no traceback. (The interpreter's own
    start, its first ~20 ms before the console script's first line has run, is Python's:
    docs/reliability.md.)"""
    out = tmp_path / "take.usd"
    proc = subprocess.Popen(
        [*_lgi_command(), "solve", str(files["model"]), str(files["take"]), "-o", str(out), "-q"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_sigint_default,
    )
    time.sleep(after)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=300)
    assert "Traceback" not in err, err
    # Before the interpreter has installed its handler (its first ~10 ms) SIGINT's default
    # action ends the process, silently, as any program's: a shell reports 128 + 2 = 130 too.
    assert (proc.returncode, err) in ((130, "lgi: interrupted\n"), (-signal.SIGINT, "")), err
    assert not out.exists() and _leftovers(tmp_path) == []


def test_a_solved_npz_is_stored_not_deflated_and_streams_back_frame_by_frame(
    tmp_path: Path,
) -> None:
    import zipfile

    from lgi.io.result import read_result_npz, stream_result_npz, write_result_npz
    from lgi.io.topology import Topology

    rng = np.random.default_rng(0)
    v = rng.normal(size=(40, 5, 3))
    topo = Topology(5, np.array([3, 3]), np.array([0, 1, 2, 2, 3, 4]), None, None)
    out = write_result_npz(
        tmp_path / "s.npz", topo, v, np.zeros((40, 2)), np.zeros((40, 2), bool), ["a", "b"],
        fps=60.0,
    )  # fmt: skip
    with zipfile.ZipFile(out) as z:
        assert {i.compress_type for i in z.infolist()} == {zipfile.ZIP_STORED}
    np.testing.assert_array_equal(read_result_npz(out).vertices, v.astype(np.float32))
    streamed, wait = stream_result_npz(out)
    wait(40)
    np.testing.assert_array_equal(streamed.vertices, v.astype(np.float32))


def test_a_solved_npz_written_from_chunks_is_the_one_written_whole_and_numpy_reads_it(
    tmp_path: Path,
) -> None:
    """`lgi solve` hands the npz writer its float32 chunks (no whole-take copy): the file must
    hold the same arrays as one written from the whole take, and numpy's own `np.load` must
    read it."""
    from lgi.io.result import read_result_npz, write_result_npz
    from lgi.io.topology import Topology

    rng = np.random.default_rng(1)
    v = rng.normal(size=(23, 5, 3)).astype(np.float32)
    topo = Topology(5, np.array([3, 3]), np.array([0, 1, 2, 2, 3, 4]), None, None)
    rest = (np.zeros((23, 2)), np.zeros((23, 2), bool), ["a", "b"])
    whole = write_result_npz(tmp_path / "whole.npz", topo, v, *rest, fps=30.0)
    parts = write_result_npz(tmp_path / "parts.npz", topo, [v[:7], v[7:8], v[8:]], *rest, fps=30.0)
    a, b = np.load(whole), np.load(parts)
    assert a.files == b.files and a.files[0] == "vertices"
    for name in a.files:
        np.testing.assert_array_equal(a[name], b[name])
    assert b["vertices"].dtype == np.float32 and b["vertices"].shape == (23, 5, 3)
    np.testing.assert_array_equal(read_result_npz(parts).vertices, v)
