"""Marker faults repaired by default: `lgi solve` undoes a named label swap and solves a spike
as missing over its frames, says so, records it in the solve's settings, and the face on those
frames is the clean take's again; `--no-repair` keeps the markers as given. The take file is
never touched."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

import lgi
from lgi.app import cli
from lgi.io.result import read_result_npz
from lgi.solve.diagnose import Finding
from lgi.solve.repair import repaired
from pipeline_files import build_actor, write_c3d


def test_repaired_undoes_a_swap_and_blanks_a_spike_and_leaves_gaps_alone() -> None:
    x = np.arange(10 * 4 * 3, dtype=np.float64).reshape(10, 4, 3)
    found = [
        Finding("swap", ("b", "c"), 2, 4, 1.0),
        Finding("spike", ("a",), 7, 7, 1.0),
        Finding("gap", ("d",), 0, 9, 1.0),
    ]
    got, mask, done = repaired(x, found, ["a", "b", "c", "d"])
    assert np.array_equal(got[2:5, 1], x[2:5, 2]) and np.array_equal(got[2:5, 2], x[2:5, 1])
    assert np.isnan(got[7, 0]).all() and np.isfinite(np.delete(got, 7, axis=0)[:, 0]).all()
    assert np.array_equal(got[:, 3], x[:, 3])  # a gap is the dataset's: never repaired
    assert mask.sum() == 3 * 2 + 1 and mask[2:5, 1:3].all() and mask[7, 0]
    assert done == (("swap", ("b", "c"), 2, 4), ("spike", ("a",), 7, 7))
    assert np.array_equal(x, np.arange(120, dtype=np.float64).reshape(10, 4, 3))  # untouched


@pytest.fixture(scope="module")
def takes(sample, tmp_path_factory):  # type: ignore[no-untyped-def]
    """The sample's model, its clean performance as a C3D take (time codes from 1), and the
    same take with two markers 1-2 cm apart swapped for 30 frames and one 1.5 cm spike of 3
    frames."""
    folder = tmp_path_factory.mktemp("repair")
    actor, model = build_actor(folder, sample)
    clean = np.asarray(sample.performance, dtype=np.float64)
    pose = np.nanmedian(clean, axis=0)
    d = np.linalg.norm(pose[:, None] - pose[None], axis=2)
    a = 3
    b = int(np.flatnonzero((d[a] > 1.0) & (d[a] < 2.0))[0])
    faulty = clean.copy()
    faulty[60:90, [a, b]] = faulty[60:90, [b, a]]
    faulty[40:43, 10, 2] += 1.5
    paths = {}
    for name, frames in (("clean", clean), ("faulty", faulty)):
        paths[name] = folder / f"{name}.c3d"
        write_c3d(paths[name], frames, actor.names, 30.0, "cm")
    return model, paths, actor.names, (a, b)


def _solve(model: Path, take: Path, out: Path, *extra: str) -> None:
    argv = ["solve", str(model), str(take), "-o", str(out), "--marker-noise", "auto", *extra]
    assert cli.main([*argv, "-q"]) == 0


def test_lgi_solve_repairs_a_swap_and_a_spike_and_the_face_is_the_clean_takes_again(
    takes, tmp_path: Path, capsys
) -> None:  # type: ignore[no-untyped-def]
    model, paths, names, (a, b) = takes
    before = hashlib.sha256(paths["faulty"].read_bytes()).hexdigest()
    _solve(model, paths["clean"], tmp_path / "clean.npz")
    capsys.readouterr()
    argv = ["solve", str(model), str(paths["faulty"]), "-o", str(tmp_path / "fixed.npz")]
    assert cli.main([*argv, "--marker-noise", "auto"]) == 0
    said = capsys.readouterr().err
    pair = sorted((names[a], names[b]))
    assert f"repaired: {pair[0]} <-> {pair[1]} swapped, time codes 61-90" in said, said
    assert f"repaired: {names[10]} solved as missing (a spike), time codes 41-43" in said, said
    _solve(model, paths["faulty"], tmp_path / "kept.npz", "--no-repair")
    assert hashlib.sha256(paths["faulty"].read_bytes()).hexdigest() == before

    clean = read_result_npz(tmp_path / "clean.npz")
    fixed = read_result_npz(tmp_path / "fixed.npz")
    kept = read_result_npz(tmp_path / "kept.npz")
    assert fixed.settings is not None and kept.settings is not None
    assert set(fixed.settings.repairs) == {
        ("swap", tuple(pair), 60, 89),
        ("spike", (names[10],), 40, 42),
    }
    assert kept.settings.repairs == ()
    assert "repaired: " in fixed.settings.describe("cm")
    # `lgi info` names them at the take's time codes (from 1), as the solve said them.
    capsys.readouterr()
    assert cli.main(["info", str(tmp_path / "fixed.npz")]) == 0
    info = capsys.readouterr().out
    assert f"repaired: {names[10]} solved as missing (a spike), time codes 41-43" in info, info

    def off(r, rows: slice) -> float:  # type: ignore[no-untyped-def]
        return float(np.linalg.norm(r.vertices[rows] - clean.vertices[rows], axis=2).mean())

    for rows in (slice(60, 90), slice(40, 43)):
        # Repaired, the face on the fault's frames is near the clean take's solve; kept as
        # given, it carries the fault.
        assert off(fixed, rows) < 0.2 * off(kept, rows), (rows, off(fixed, rows), off(kept, rows))


def test_the_report_lists_what_was_repaired(takes, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    model, paths, names, _ = takes
    _solve(model, paths["faulty"], tmp_path / "fixed.npz")
    assert cli.main(["report", str(tmp_path / "fixed.npz"), "-o", str(tmp_path / "r.html")]) == 0
    page = (tmp_path / "r.html").read_text()
    repaired_list = page.split("<ul class=repaired>")[1].split("</ul>")[0]
    assert f"{names[10]} solved as missing (a spike), time codes 41-43" in repaired_list
    assert "swapped, time codes 61-90" in repaired_list


def test_repairs_round_trip_through_the_settings_and_a_malformed_record_is_refused() -> None:
    from lgi.errors import InputError
    from lgi.io.settings import SolveSettings

    s = SolveSettings.of(has_jaw_rig=False, jaw=None, marker_noise=0.02, detail_weight=None)
    s = SolveSettings(**{**s.__dict__, "repairs": (("swap", ("m1", "m2"), 3, 9),)})
    back = SolveSettings.from_json(s.to_json(), "x.npz")
    assert back == s and back.repair_lines(100) == ["m1 <-> m2 swapped, time codes 103-109"]
    old = '{"detail_weight": null, "jaw": null, "marker_noise": 0.02, "version": "0.1.0"}'
    assert SolveSettings.from_json(old, "x.npz").repairs == ()  # files before repairs
    bad = old[:-1] + ', "repairs": [{"kind": "gap", "markers": ["m1"], "first": 0, "last": 1}]}'
    with pytest.raises(InputError, match=r"x\.npz: repairs must be a list"):
        SolveSettings.from_json(bad, "x.npz")


def test_model_solve_repairs_a_swap_and_a_spike_and_says_what_it_repaired(
    sample, sample_model
) -> None:  # type: ignore[no-untyped-def]
    x = np.array(sample.performance)
    x[50:70, [3, 40]] = x[50:70, [40, 3]]  # a label swap, 20 frames
    x[100:102, 7] += [0.0, 0.0, 1.0]  # a 1 cm spike, 2 frames
    clean = sample_model.solve(sample.performance, marker_noise=0.02, quiet=True)
    kept = sample_model.solve(x, marker_noise=0.02, repair=False, quiet=True)
    fixed = sample_model.solve(x, marker_noise=0.02, quiet=True)
    assert clean.repairs == () and kept.repairs is None and kept.repaired is None
    names = sample_model.marker_names
    got = {(f.kind, frozenset(f.markers), f.first, f.last) for f in fixed.repairs}
    assert got == {
        ("swap", frozenset({names[3], names[40]}), 50, 69),
        ("spike", frozenset({names[7]}), 100, 101),
    }
    want = np.zeros(x.shape[:2], dtype=bool)
    want[50:70, [3, 40]] = want[100:102, 7] = True
    np.testing.assert_array_equal(fixed.repaired, want)

    def err(r, rows):  # type: ignore[no-untyped-def]
        return float(np.linalg.norm(r.vertices[rows] - sample.truth[rows], axis=2).mean())

    for rows in (slice(50, 70), slice(100, 102)):
        assert err(kept, rows) > 1.3 * err(clean, rows)  # the faults dent the face as given
        assert err(fixed, rows) <= 1.05 * err(clean, rows)  # and repaired, it is the clean one's
    # Frames solved each alone, or in chunks, are not read for faults (None: not looked for).
    assert sample_model.solve(x, marker_noise=0.02, steady=False, quiet=True).repairs is None
    assert next(sample_model.solve_iter(x, chunk=50, marker_noise=0.02, quiet=True)).repairs is None
    with pytest.raises(lgi.InputError, match="repair must be True or False"):
        sample_model.solve(x, repair="yes", quiet=True)  # type: ignore[arg-type]


def test_a_repair_reads_faults_at_the_given_markers_noise_and_a_denoised_plan_keeps_it(
    sample, sample_model
) -> None:  # type: ignore[no-untyped-def]
    x = np.array(sample.performance)
    x[100:102, 7] += [0.0, 0.0, 1.0]  # a 1 cm spike, 2 frames
    name = sample_model.marker_names[7]
    # Read at 0.2 mm (5 sigma: 1 mm) the spike is a fault; at 5 mm (5 sigma: 2.5 cm) nothing is.
    at_given = sample_model.solve(x, marker_noise=0.02, fault_noise=0.02, quiet=True)
    assert [(f.kind, f.markers, f.first, f.last) for f in at_given.repairs] == [
        ("spike", (name,), 100, 101)
    ]
    assert sample_model.solve(x, marker_noise=0.02, fault_noise=0.5, quiet=True).repairs == ()
    # A plan of a denoised take reads faults at the noise before denoising, as `lgi solve`.
    plan = lgi.plan_solve(x, sample_model, marker_noise=0.02, denoise=True)
    assert plan.denoised is not None and plan.options.marker_noise < 0.02
    assert plan.options.fault_noise == plan.given_noise == 0.02
    assert lgi.plan_solve(x, sample_model, marker_noise=0.02).options.fault_noise is None
    with pytest.raises(lgi.InputError, match="fault_noise"):
        sample_model.solve(x, marker_noise=0.02, fault_noise=-1.0, quiet=True)
