"""Evaluation metrics against hand computations, the protocols' shapes, and the CLI output."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lgi import SolveResult
from lgi.lab import evaluate as ev
from lgi.lab.baselines import DisplacementInterpolation


def test_score_matches_hand_computed_statistics() -> None:
    truth = np.zeros((3, 4, 3))
    verts = truth.copy()
    verts[:, 0, 0] = [1.0, 2.0, 4.0]  # errors 1, 2, 4 on vertex 0, 0 elsewhere
    res = SolveResult(
        verts, np.full((3, 2), 0.5), np.zeros((3, 2, 3)), np.zeros((3, 2), bool), None
    )  # type: ignore[arg-type]
    row = ev.score("m", res, truth, seconds=0.3, diagonal=2.0)
    assert row["mean"] == 7 / 12 and row["max"] == 4.0
    assert row["max_residual_rel"] == 0.25
    assert row["jitter"] == (1.0 / 4)  # second difference 4 - 2*2 + 1 = 1 on one of 4 vertices
    assert abs(row["ms_per_frame"] - 100.0) < 1e-9
    region_row = ev.score("m", res, truth, 0.3, region=[1, 2], diagonal=2.0)
    assert region_row["max"] == 0.0


def test_verification_frames_are_exact_for_interpolating_methods(sample, sample_dataset) -> None:  # type: ignore[no-untyped-def]
    frames, truth = ev.verification(sample_dataset, sample.markers_rest)
    assert frames.shape == (sample_dataset.num_shapes, len(sample.markers_rest), 3)
    di = DisplacementInterpolation(sample_dataset, sample.markers_rest)
    rows = ev.evaluate({"di": di}, frames[:5], truth[:5], temporal=False)
    assert rows[0]["max_residual_rel"] < 1e-9
    sweep = ev.dropout_sweep({"di": di}, frames[:4], truth[:4], rates=(0.0, 0.2))
    assert [r["dropout"] for r in sweep] == [0.0, 0.2]
    noisy = ev.noise_sweep({"di": di}, frames[:4], truth[:4], sigmas=(0.0, 0.2))
    assert noisy[1]["mean"] > noisy[0]["mean"]


def test_leave_one_out_pools_held_out_shapes(sample, sample_dataset) -> None:  # type: ignore[no-untyped-def]
    rows = ev.leave_one_out(
        sample_dataset,
        sample.markers_rest,
        lambda d, m: {"di": DisplacementInterpolation(d, m)},
        shapes=[0, 3],
    )
    assert rows[0]["frames"] == 2 and rows[0]["mean"] > 0


def test_markdown_and_csv_round_trip(tmp_path: Path) -> None:
    rows = [{"method": "a", "mean": 0.5}, {"method": "b", "mean": float("nan")}]
    md = ev.to_markdown(rows)
    assert md.splitlines()[0] == "| method | mean |" and "nan" in md
    ev.to_csv(rows, tmp_path / "r.csv")
    assert (tmp_path / "r.csv").read_text().splitlines()[1] == "a,0.5"


def test_cli_evaluate_writes_results_and_a_heatmap_panel_of_every_method(tmp_path: Path) -> None:
    from lgi.app.cli import main

    argv = ["evaluate", "--data", "sample", "--protocol", "performance", "--out", str(tmp_path)]
    assert main([*argv, "-q"]) == 0
    text = (tmp_path / "results.md").read_text()
    for name in ("displacement interpolation", "blendshape fit", "LGI-RBF", "| LGI |"):
        assert name in text
    assert (tmp_path / "results.csv").is_file()
    # The panel: truth plus four methods, two views (render.panel's 3-inch cells at 100 dpi).
    png = (tmp_path / "panel.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")
    assert width > 4 * height / 2 and height >= 2 * 250
    # A second run into the same folder replaces nothing unasked; with --force it replaces
    # its own files and leaves the user's.
    (tmp_path / "notes.txt").write_text("mine")
    (tmp_path / "results.md").write_text("old")
    assert main([*argv, "-q"]) == 2
    assert (tmp_path / "results.md").read_text() == "old"
    assert main([*argv, "-q", "--force"]) == 0
    assert "| LGI |" in (tmp_path / "results.md").read_text()
    assert (tmp_path / "notes.txt").read_text() == "mine"
    assert not [p.name for p in tmp_path.iterdir() if ".tmp" in p.name]


def test_pops_count_the_frames_where_some_vertexs_error_jumps_not_where_it_drifts() -> None:
    from lgi.lab.scoring import pops

    frames = np.arange(50, dtype=np.float64)
    err = np.stack([0.01 * frames, np.full(50, 0.1)], axis=1)  # a drift and a constant
    assert pops(err, 0.2) == 0
    err[20, 1] = 0.45  # one frame 0.35 cm off and back: |e(t+1) - 2e(t) + e(t-1)| = 0.7 at 20
    # ... and 0.35 at 19 and 21 (the frames either side see half the excursion)
    assert pops(err, 0.2) == 3 and pops(err, 0.5) == 1
    assert pops(err[:2], 0.0) == 0  # two frames have no second difference
