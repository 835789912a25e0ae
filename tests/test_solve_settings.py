"""How a take was solved travels with the result: `lgi solve` records its marker noise, jaw pose
and detail weight (`SolveSettings`) in the solved `.npz` and the USD cache, `lgi export` carries
them on, and `lgi info` / `lgi report` show them."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import lgi
from lgi.errors import InputError
from lgi.io.result import read_result_npz, write_result_npz
from lgi.io.settings import SolveSettings
from lgi.io.topology import topology


@pytest.fixture(scope="module")
def files(sample, tmp_path_factory):  # type: ignore[no-untyped-def]
    from pipeline_files import build_actor, write_c3d

    tmp = tmp_path_factory.mktemp("settings")
    actor, model = build_actor(tmp, sample)
    take = tmp / "take.c3d"
    write_c3d(take, sample.performance[:12], actor.names, fps=60.0, units="cm")
    return model, take


def test_settings_round_trip_as_json_and_describe_themselves() -> None:
    s = SolveSettings(marker_noise=0.05, jaw="fit", detail_weight=0.47, version="9.9")
    assert SolveSettings.from_json(s.to_json(), "x") == s
    assert s.describe("cm") == (
        "marker noise 0.05 cm per coordinate, jaw pose 'fit', detail weight 0.470, each frame "
        "alone (lgi 9.9)"
    )
    steady = SolveSettings(
        marker_noise=None, jaw=None, detail_weight=None, version="1", steady=True
    )
    assert SolveSettings.from_json(steady.to_json(), "x") == steady
    assert ", dropouts filled and detail steady over frames (lgi 1)" in steady.describe(None)
    # A model with a jaw rig solved with jaw=None is at the rest pose; a pose array is 'given'.
    of = SolveSettings.of
    assert of(has_jaw_rig=True, jaw=None, marker_noise=None, detail_weight=None).jaw == "rest"
    given = of(has_jaw_rig=True, jaw=np.zeros((2, 3)), marker_noise=None, detail_weight=None)
    assert given.jaw == "given"
    assert of(has_jaw_rig=False, jaw="fit", marker_noise=None, detail_weight=None).jaw is None
    plain = SolveSettings(marker_noise=None, jaw=None, detail_weight=None, version="9.9")
    assert SolveSettings.from_json(plain.to_json(), "x") == plain
    assert "no marker noise" in plain.describe(None)
    assert "all of the dataset's detail" in plain.describe(None)
    # A denoised take's settings say the noise it was given and the directions it kept.
    from lgi.plan.denoise import DenoisedTake

    taken = DenoisedTake(np.zeros((2, 1, 3)), 0.0168, 0.05, 15, 1)
    den = of(
        has_jaw_rig=False,
        jaw=None,
        marker_noise=taken.marker_noise,
        detail_weight=None,
        denoised=taken,
    )
    assert SolveSettings.from_json(den.to_json(), "x") == den
    # The residuals a denoised solve writes are the given markers': read with their noise.
    assert den.given_noise == 0.05 and plain.given_noise is None
    assert (
        SolveSettings(marker_noise=0.02, jaw=None, detail_weight=None, version="1").given_noise
        == 0.02
    )
    assert den.describe("cm").startswith(
        "marker noise 0.0168 cm per coordinate (the take denoised from 0.05 cm, 15 directions of "
        "motion kept)"
    )


def test_how_dropouts_were_filled_round_trips_and_is_said() -> None:
    steady = SolveSettings(
        marker_noise=None, jaw=None, detail_weight=None, version="1", steady=True
    )
    by_motion = steady.with_fill(True, 5)
    assert (by_motion.dropout_fill, by_motion.fill_rank) == ("motion", 5)
    assert SolveSettings.from_json(by_motion.to_json(), "x") == by_motion
    assert (
        ", dropouts filled from the take's own motion (5 directions), detail steady over frames "
        "(lgi 1)" in by_motion.describe(None)
    )
    by_neighbours = steady.with_fill(True, None)
    assert SolveSettings.from_json(by_neighbours.to_json(), "x") == by_neighbours
    assert "dropouts filled from each marker's neighbours, detail" in by_neighbours.describe(None)
    # Nothing filled (a take without dropouts): nothing recorded, as older files read.
    assert steady.with_fill(False, 5) == steady
    old = json.loads(steady.to_json())
    del old["dropout_fill"], old["fill_rank"]
    assert SolveSettings.from_json(json.dumps(old), "x") == steady


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("{not json", "not the JSON text lgi writes"),
        ('{"marker_noise": 0.1}', "expected the keys"),
        (
            '{"marker_noise": "a lot", "jaw": null, "detail_weight": null, "version": "1"}',
            "marker_noise must be a finite number or null, got 'a lot'",
        ),
        (
            '{"marker_noise": null, "jaw": 3, "detail_weight": null, "version": "1"}',
            "jaw must be text or null, got 3",
        ),
        (
            '{"marker_noise": null, "jaw": null, "detail_weight": null, "version": "1", '
            '"steady": "yes"}',
            "steady must be true or false, got 'yes'",
        ),
        (
            '{"marker_noise": null, "jaw": null, "detail_weight": NaN, "version": "1"}',
            "detail_weight must be a finite number or null",
        ),
        (
            '{"marker_noise": 0.1, "jaw": null, "detail_weight": null, "version": "1", '
            '"denoised_from": 0.2, "denoised_rank": -3}',
            "denoised_rank must be a whole number >= 0 or null, got -3",
        ),
        (
            '{"marker_noise": 0.1, "jaw": null, "detail_weight": null, "version": "1", '
            '"denoised_from": "much", "denoised_rank": 3}',
            "denoised_from must be a finite number or null, got 'much'",
        ),
        (
            '{"marker_noise": null, "jaw": null, "detail_weight": null, "version": "1", '
            '"dropout_fill": "motion", "fill_rank": 0}',
            "dropout_fill must be 'motion' with a fill_rank >= 1, 'neighbours' or null",
        ),
        (
            '{"marker_noise": null, "jaw": null, "detail_weight": null, "version": "1", '
            '"dropout_fill": "neighbours", "fill_rank": 3}',
            "got 'neighbours' and 3",
        ),
        (
            '{"marker_noise": null, "jaw": null, "detail_weight": null, "version": "1", '
            '"dropout_fill": "guessed"}',
            "got 'guessed' and None",
        ),
    ],
)
def test_damaged_settings_are_refused_naming_the_file_and_key(text: str, message: str) -> None:
    with pytest.raises(InputError, match=r"f\.npz: 'solve_settings'") as e:
        SolveSettings.from_json(text, "f.npz: 'solve_settings'")
    assert message in str(e.value)


def test_lgi_solve_records_its_settings_in_the_npz_and_info_and_report_show_them(
    files, tmp_path: Path, capsys
) -> None:  # type: ignore[no-untyped-def]
    from lgi.app import cli

    model, take = files
    out = tmp_path / "o.npz"
    argv = ["solve", model, take, "-o", out, "--marker-noise", "0.03", "--detail-weight", "0.4"]
    assert cli.main([str(a) for a in [*argv, "-q"]]) == 0
    got = read_result_npz(out).settings
    has_jaw = lgi.Model.load(model).jaw_rig is not None
    assert got == SolveSettings(
        marker_noise=0.03,
        jaw="auto" if has_jaw else None,
        detail_weight=0.4,
        version=lgi.__version__,
        steady=True,
        # The sample's dropouts, in a 12-frame take too short to read its motion's rank on.
        dropout_fill="neighbours",
    )
    capsys.readouterr()
    assert cli.main(["info", str(out)]) == 0
    assert "solved with: marker noise 0.03 cm per coordinate" in capsys.readouterr().out
    page = tmp_path / "r.html"
    assert cli.main(["report", str(out), "-o", str(page)]) == 0
    assert "detail weight 0.400" in page.read_text(encoding="utf-8")
    # Without the options: the exact interpolation and all the detail, recorded as such.
    plain = tmp_path / "p.npz"
    assert cli.main(["solve", str(model), str(take), "-o", str(plain), "-q"]) == 0
    s = read_result_npz(plain).settings
    assert s is not None and s.marker_noise is None and s.detail_weight is None
    # --no-steady: each frame from its own markers alone, recorded and said.
    alone = tmp_path / "a.npz"
    assert cli.main(["solve", str(model), str(take), "-o", str(alone), "-q", "--no-steady"]) == 0
    s = read_result_npz(alone).settings
    assert s is not None and not s.steady and "each frame alone" in s.describe("cm")


def test_the_usd_cache_keeps_the_settings_and_export_carries_them_on(
    files, tmp_path: Path, capsys
) -> None:  # type: ignore[no-untyped-def]
    from pxr import Usd

    from lgi.app import cli
    from lgi.io.usd import read_usd_cache

    model, take = files
    npz = tmp_path / "o.npz"
    argv = ["solve", model, take, "-o", npz, "--detail-weight", "0.25", "-q"]
    assert cli.main([str(a) for a in argv]) == 0
    usd = tmp_path / "o.usda"
    assert cli.main(["export", str(npz), "-o", str(usd), "-q"]) == 0
    stage = Usd.Stage.Open(str(usd))
    attr = stage.GetPrimAtPath("/Face/Mesh").GetAttribute("lgi:solveSettings")
    assert json.loads(attr.Get())["detail_weight"] == 0.25
    assert read_usd_cache(usd).settings == read_result_npz(npz).settings
    direct = tmp_path / "d.usdc"
    argv = ["solve", model, take, "-o", direct, "--detail-weight", "0.25", "-q"]
    assert cli.main([str(a) for a in argv]) == 0
    assert read_usd_cache(direct).settings == read_result_npz(npz).settings
    # Solved in chunks, the settings are written when the fill is known: the same.
    chunked = tmp_path / "c.usdc"
    argv = ["solve", model, take, "-o", chunked, "--detail-weight", "0.25", "--chunk", "5", "-q"]
    assert cli.main([str(a) for a in argv]) == 0
    assert read_usd_cache(chunked).settings == read_result_npz(npz).settings
    assert read_result_npz(npz).settings.dropout_fill == "neighbours"  # type: ignore[union-attr]
    # `lgi info` on a USD cache names the noise in the stage's unit.
    noisy = tmp_path / "n.usda"
    argv = ["solve", model, take, "-o", noisy, "--marker-noise", "0.02", "-q"]
    assert cli.main([str(a) for a in argv]) == 0
    capsys.readouterr()
    assert cli.main(["info", str(noisy)]) == 0
    assert "solved with: marker noise 0.02 cm per coordinate" in capsys.readouterr().out


def test_a_result_written_before_settings_were_kept_reads_and_reports_not_recorded(
    sample_dataset, tmp_path: Path
) -> None:  # type: ignore[no-untyped-def]
    from lgi.review.report import render_report

    topo = topology(sample_dataset)
    f, b = 2, 5
    path = write_result_npz(
        tmp_path / "old.npz",
        topo,
        np.zeros((f, topo.num_vertices, 3)),
        np.zeros((f, b)),
        np.zeros((f, b), dtype=bool),
        [f"m{i}" for i in range(b)],
        fps=30.0,
    )
    solved = read_result_npz(path)
    assert solved.settings is None
    assert "not recorded" in render_report(solved, source=str(path))
    # A damaged record is refused by the reader, naming the file and the key.
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["solve_settings"] = np.str_("{oops")
    bad = tmp_path / "bad.npz"
    np.savez_compressed(bad, **arrays)
    with pytest.raises(InputError, match=r"bad.npz: 'solve_settings': not the JSON text"):
        read_result_npz(bad)
