"""Real files from other capture systems (BTK's test files in ../shared/data/mocap-files) and a
TD's ordinary mistakes with takes: each file reads (frames, markers, rate, unit, first frame,
checked against the file's own header bytes or lines, and against ezc3d where it reads the
file) or fails naming the file and the defect in our words; TRC time is kept."""

from __future__ import annotations

import struct
import warnings
from pathlib import Path

import numpy as np
import pytest

from lgi.errors import InputError, LgiWarning
from lgi.io import takes
from lgi.io.c3d_format import read_c3d_file
from pipeline_files import write_c3d


def _file(name: str) -> Path:
    from conftest import ict_dir

    p = ict_dir().parent / "mocap-files" / name  # the shared data folder beside ICT-FaceKit
    if not p.exists():
        pytest.skip(f"{p} is absent (the shared data beside the checkout)")
    return p


def _header(p: Path) -> tuple[int, int, int]:
    """Points, first and last frame from a C3D header's words 2, 4, 5 (Intel files)."""
    head = p.read_bytes()[:10]
    n, _, first, last = struct.unpack("<HHHH", head[2:10])
    return n, first, last


# name -> (frames, markers, fps, unit, first frame, warning or None)
READS = {
    "Gait.c3d": (487, 33, 100.0, "mm", 1, None),
    "Res16bits.c3d": (100, 44, 100.0, "mm", 1, None),
    "parameterOverflow.c3d": (101, 142, 100.0, "mm", 1, None),
    "mocap36.c3d": (1380, 36, 100.0, "mm", 1, "POINT:LABELS: its description length"),
    "badParameterOffset.c3d": (111, 41, 250.0, "mm", 1, "read past a defect"),
    "Gait.trc": (487, 33, 100.0, "mm", 1, "rows carry values past the 33 markers"),
    "MOTEK_T.trc": (89, 41, 30.0, "mm", 1, None),
}
FAILS = {
    "Empty.c3d": "the file is empty",
    "Empty.trc": "the file is empty",
    "Truncated.trc": "truncated TRC file: it ends at line 2, inside the header",
}


@pytest.mark.parametrize("name", sorted(READS))
def test_each_vendor_file_reads_with_its_frames_markers_rate_unit_and_first_frame(
    name: str,
) -> None:
    p = _file(name)
    frames, markers, fps, unit, first, warned = READS[name]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        raw = takes.read_raw(p)
    said = [str(w.message) for w in caught if issubclass(w.category, LgiWarning)]
    assert raw.points.shape == (frames, markers, 3)
    assert (raw.fps, raw.units, raw.first_frame) == (fps, unit, first)
    if warned is None:
        assert said == []
    else:
        assert any(warned in m and str(p) in m for m in said), said
    if name.endswith(".c3d"):
        _, h_first, h_last = _header(p)  # the file's own bytes
        assert (h_first, h_last - h_first + 1) == (first, frames)
    else:  # line 3: DataRate ... NumFrames ... Units
        keys, vals = (p.read_text().splitlines()[k].split("\t") for k in (1, 2))
        meta = {k.strip(): v.strip() for k, v in zip(keys, vals, strict=False)}
        assert int(meta["NumFrames"]) == frames and meta["Units"] == unit
    assert np.isfinite(raw.points[~np.isnan(raw.points)]).all()


@pytest.mark.parametrize("name", sorted(FAILS))
def test_each_unreadable_vendor_file_fails_naming_the_file_and_the_defect(name: str) -> None:
    p = _file(name)
    with pytest.raises(InputError) as e:
        takes.read_raw(p)
    text = str(e.value)
    assert str(p) in text and FAILS[name] in text
    assert "ignoreBadFormatting" not in text and "iostream" not in text


@pytest.mark.parametrize("name", ["Gait.c3d", "Res16bits.c3d", "parameterOverflow.c3d"])
def test_our_c3d_reader_equals_ezc3d_where_ezc3d_reads_the_file(name: str) -> None:
    import ezc3d

    p = _file(name)
    ours = read_c3d_file(str(p))
    c = ezc3d.c3d(str(p))
    pts = np.asarray(c["data"]["points"], dtype=np.float64)[:3].transpose(2, 1, 0)
    res = np.asarray(c["data"]["meta_points"]["residuals"])[0].T
    missing = (res < 0) | np.all(pts == 0, axis=2)
    np.testing.assert_array_equal(np.isnan(ours.points).any(axis=2), missing)
    np.testing.assert_allclose(ours.points[~missing], pts[~missing], rtol=0, atol=1e-4)
    labels = [str(x).strip() for x in c["parameters"]["POINT"]["LABELS"]["value"]]
    assert ours.labels[: len(labels)] == labels[: len(ours.labels)]


def _analog_only_c3d(path: Path) -> Path:
    """A C3D of 10 frames with one analog channel and no 3D points, made byte by byte from
    the format's description (ezc3d cannot write one)."""
    header = bytearray(512)
    header[0], header[1] = 2, 0x50  # parameters in block 2
    struct.pack_into("<HHHH", header, 2, 0, 1, 1, 10)  # 0 points, 1 analog value, frames 1-10
    struct.pack_into("<f", header, 12, -1.0)  # float data
    struct.pack_into("<H", header, 16, 3)  # data in block 3
    struct.pack_into("<f", header, 20, 100.0)
    params = bytearray(512)
    params[0:4] = bytes([1, 0x50, 1, 84])  # 1 block, Intel
    group = bytes([5, 0xFF]) + b"POINT" + struct.pack("<H", 3) + bytes([0])
    used = bytes([4, 1]) + b"USED" + struct.pack("<H", 7) + bytes([2, 0]) + b"\0\0" + bytes([0])
    params[4 : 4 + len(group) + len(used)] = group + used
    data = np.zeros(10, dtype="<f4").tobytes().ljust(512, b"\0")
    path.write_bytes(bytes(header) + bytes(params) + data)
    return path


def test_a_c3d_without_3d_points_is_refused_in_our_words(tmp_path: Path) -> None:
    p = _analog_only_c3d(tmp_path / "analog.c3d")
    with pytest.raises(InputError, match="holds no 3D marker points"):
        takes.read_raw(p)


# --- TRC time ---------------------------------------------------------------------------------


def _trc(path: Path, numbers: list[int], fps: float = 100.0, n: int = 3, **over: str) -> Path:
    """A TRC of `n` markers whose rows carry the Frame# `numbers` (times from them)."""
    meta = {"DataRate": f"{fps:g}", "CameraRate": f"{fps:g}", "NumFrames": str(len(numbers))}
    meta |= {"NumMarkers": str(n), "Units": "mm", **over}
    names = [f"m{k}" for k in range(n)]
    lines = [
        "PathFileType\t4\t(X/Y/Z)\ttest.trc",
        "\t".join(meta),
        "\t".join(meta.values()),
        "Frame#\tTime\t" + "\t\t\t".join(names) + "\t\t",
        "\t\t" + "\t".join(f"{a}{k + 1}" for k in range(n) for a in "XYZ"),
        "",
    ]
    for f in numbers:
        vals = [f"{100 * k + f + 0.25 * a:.3f}" for k in range(n) for a in range(3)]
        lines.append(f"{f}\t{(f - numbers[0]) / fps:.5f}\t" + "\t".join(vals))
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_frame_number_gap_becomes_missing_frames_at_their_time_codes(tmp_path: Path) -> None:
    numbers = [*range(1, 51), *range(61, 101)]
    p = _trc(tmp_path / "gap.trc", numbers)
    with pytest.warns(LgiWarning, match=r"Frame# skips 10 frames \(51-60\)"):
        raw = takes.read_raw(p)
    assert raw.first_frame == 1 and raw.points.shape == (100, 3, 3)
    assert np.isnan(raw.points[50:60]).all() and not np.isnan(raw.points[:50]).any()
    # Frame# 61 is row 60 of the take: its x of marker 0 is 61 (how _trc writes it).
    assert raw.points[60, 0, 0] == 61.0 and raw.points[99, 0, 0] == 100.0


@pytest.mark.parametrize(
    ("numbers", "what"),
    [([1, 2, 3, 3, 4], "Frame# 3 after 3"), ([1, 2, 5, 4], "Frame# 4 after 5")],
)
def test_a_repeated_or_backward_frame_number_is_an_error_naming_the_line(
    tmp_path: Path, numbers: list[int], what: str
) -> None:
    p = _trc(tmp_path / "bad.trc", numbers)
    with pytest.raises(InputError, match=rf"bad.trc, line \d+: {what}"):
        takes.read_raw(p)


def test_a_cut_last_row_and_a_frame_count_mismatch_are_errors_naming_the_line(
    tmp_path: Path,
) -> None:
    p = _trc(tmp_path / "cut.trc", list(range(1, 11)))
    text = p.read_text().rstrip("\n")
    p.write_text(text[: len(text) - 12] + "\n")  # the last row loses its last columns
    with pytest.raises(InputError, match=r"cut.trc, line 16: the row has 10 of 11 columns"):
        takes.read_raw(p)
    q = _trc(tmp_path / "count.trc", list(range(1, 11)), NumFrames="328")
    with pytest.raises(InputError, match=r"line 3: NumFrames is 328 but the file holds 10"):
        takes.read_raw(q)


def test_a_time_column_that_disagrees_with_the_frame_numbers_is_an_error(tmp_path: Path) -> None:
    p = _trc(tmp_path / "time.trc", list(range(1, 11)))
    lines = p.read_text().splitlines()
    cells = lines[10].split("\t")
    cells[1] = "0.5"  # Frame# 5 at 100 fps is 0.04 s
    lines[10] = "\t".join(cells)
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"line 11: Time 0.5 s does not match Frame# 5"):
        takes.read_raw(p)


def test_the_same_take_as_c3d_and_trc_has_the_same_time_codes_and_points(tmp_path: Path) -> None:
    numbers = list(range(1, 21))
    trc = takes.read_raw(_trc(tmp_path / "t.trc", numbers))
    c3d_path = tmp_path / "t.c3d"
    write_c3d(c3d_path, trc.points, trc.labels, 100.0, "mm")
    c3d = takes.read_raw(c3d_path)
    assert c3d.first_frame == trc.first_frame == 1 == _header(c3d_path)[1]
    np.testing.assert_allclose(c3d.points, trc.points, rtol=0, atol=1e-4)
