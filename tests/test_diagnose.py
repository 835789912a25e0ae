"""Bad markers named: a swapped label pair and a spiking marker planted in a capture of ICT
driven by a real Live Link recording are named with their frames, by `lgi.review.diagnose` and by
`lgi solve` / `lgi info` on the command line; a clean take of the same capture is not
flagged."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from lgi.app import cli
from lgi.review.diagnose import Finding, diagnose, summary
from pipeline_files import write_solve


@pytest.fixture(scope="module")
def capture(ict_dataset, ict_markers, ict_path):  # type: ignore[no-untyped-def]
    """300 frames of ICT driven by the shared recording `jmtechart_myslate_3`, 0.5 mm noise,
    2 % dropouts, seed 1."""
    from lgi.io.livelink import read_livelinkface
    from lgi.lab import ict
    from lgi.lab.capture import make_capture

    rec = ict.livelinkface(ict_path.parent)
    curves = read_livelinkface(next(p for p in rec if "jmtechart" in p.name))
    w = curves.for_dataset(ict_dataset.names)[:300]
    return make_capture(
        ict_dataset, w, ict_markers, sigma=0.05, dropout=0.02, holdout=0, seed=1, jaw=None
    ).frames


def _planted(frames: np.ndarray) -> np.ndarray:
    x = frames.copy()
    x[100:150, [12, 47]] = x[100:150, [47, 12]]  # labels swapped for 50 frames
    x[200:203, 33] += [0.0, 0.0, 1.5]  # a 1.5 cm spike, 3 frames
    return x


@pytest.mark.parametrize("noise", [None, 0.05])
def test_a_swapped_pair_and_a_spike_are_named_with_their_frames(
    ict_model, capture, noise: float | None
) -> None:  # type: ignore[no-untyped-def]
    x = _planted(capture)
    res = ict_model.solve(x, marker_noise=noise, quiet=True)
    names = list(ict_model.marker_names)
    found = diagnose(res.bundle_residuals, res.missing, names, size=ict_model.diagonal, markers=x)
    assert found[0] == Finding("swap", ("m012", "m047"), 100, 149, found[0].worst)
    spikes = [f for f in found if f.kind == "spike"]
    assert [(f.markers, f.first, f.last) for f in spikes] == [(("m033",), 200, 202)]
    assert len(found) == 2


@pytest.mark.parametrize("noise", [None, 0.05])
def test_the_clean_capture_is_not_flagged(ict_model, capture, noise: float | None) -> None:  # type: ignore[no-untyped-def]
    res = ict_model.solve(capture, marker_noise=noise, quiet=True)
    names = list(ict_model.marker_names)
    assert (
        diagnose(res.bundle_residuals, res.missing, names, size=ict_model.diagonal, markers=capture)
        == []
    )


def test_residual_outliers_alone_name_a_marker_when_the_take_is_not_kept() -> None:
    rng = np.random.default_rng(0)
    r = np.abs(rng.normal(0.01, 0.003, (80, 6)))
    r[30:40, 4] = 0.5  # a marker the solve corrected hard for 10 frames
    missing = np.zeros_like(r, dtype=bool)
    missing[35, 4] = True  # a dropout inside the range does not split it
    found = diagnose(r, missing, list("abcdef"), size=20.0)
    assert found == [Finding("off", ("e",), 30, 39, 0.5)]
    lines = summary(r, missing, list("abcdef"), found, start=1001, units="cm")
    assert "largest 0.5 cm (e at time code 1031)" in lines[0]
    assert lines[1] == "marker off: e, time codes 1031-1040 (residual up to 0.5 cm)"


def test_lgi_solve_prints_the_findings_and_lgi_info_names_them_from_the_file(
    ict_model, capture, tmp_path: Path, capsys
) -> None:  # type: ignore[no-untyped-def]
    x = _planted(capture)
    solved = write_solve(tmp_path / "take.npz", ict_model, x, 0.05, fps=60.0, start=1)
    assert cli.main(["info", str(solved)]) == 0
    out = capsys.readouterr().out
    assert "likely label swap: m012 <-> m047, time codes 101-150" in out
    assert "spike: m033, time codes 201-203" in out
    assert "residual median" in out and " cm" in out
    # The two planted faults lead, each at a time code of its own range: the swapped marker
    # that the noise-aware targets pull back to the fit (its neighbours do not share its 9 cm),
    # then the spike; the worst frames are the swap's.
    worst = re.search(r"worst markers \(largest residual\): (.*)", out)
    assert worst is not None
    lead = [m.groups() for m in re.finditer(r"(m\d{3}) [\d.]+ cm at (\d+)", worst.group(1))][:2]
    assert lead[0][0] == "m047" and 101 <= int(lead[0][1]) <= 150, lead
    assert lead[1][0] == "m033" and 201 <= int(lead[1][1]) <= 203, lead
    frames = re.search(r"worst frames \(time code, largest residual, marker\): (.*)", out)
    assert frames is not None
    for code, marker in re.findall(r"(\d+) [\d.]+ cm (m\d{3})", frames.group(1)):
        assert marker == "m047" and 101 <= int(code) <= 150, frames.group(1)
