"""Marker takes in (`lgi.io.takes`; units `lgi.io.units`): C3D written by ezc3d, TRC and CSV
written by hand from their format descriptions, npz by numpy; read back against the arrays
written, labels matched by name, units converted, missing samples NaN, and every malformed file
an `InputError` naming it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from lgi import InputError
from lgi.io import takes, units
from pipeline_files import write_c3d

RNG = np.random.default_rng(7)


def frames(f: int, n: int) -> np.ndarray:
    return RNG.normal(size=(f, n, 3)) * 10.0


def test_c3d_reads_back_labels_rate_units_and_float32_points(tmp_path: Path) -> None:
    x = frames(6, 5)
    x[2, 1] = np.nan
    p = tmp_path / "t.c3d"
    write_c3d(p, x, ["a", "b", "c", "d", "e"], 120.0, "mm")
    raw = takes.read_c3d(p)
    assert raw.labels == ["a", "b", "c", "d", "e"]
    assert raw.fps == 120.0 and raw.units == "mm"
    np.testing.assert_array_equal(raw.points, x.astype(np.float32).astype(np.float64))
    assert np.isnan(raw.points[2, 1]).all() and not np.isnan(raw.points[2, 0]).any()


@pytest.mark.parametrize("keep", [0.5, 2 / 3, 0.95])
def test_a_truncated_c3d_is_refused_naming_the_frames_its_header_gives(
    tmp_path: Path, keep: float
) -> None:
    p = tmp_path / "whole.c3d"
    write_c3d(p, frames(30, 6), [f"m{i}" for i in range(6)], 60.0, "mm")
    assert takes.read_c3d(p).points.shape[0] == 30
    data = p.read_bytes()
    cut = tmp_path / "cut.c3d"
    cut.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(InputError, match=r"cut\.c3d: truncated C3D file: .*\(30\), only \d+ are"):
        takes.read_c3d(cut)


def test_c3d_zero_points_are_missing_and_labels_past_255_come_from_labels2(tmp_path: Path) -> None:
    x = frames(3, 300)
    x[1, 299] = 0.0
    p = tmp_path / "big.c3d"
    names = [f"p{i}" for i in range(300)]
    write_c3d(p, x, names, 60.0, "cm")
    raw = takes.read_c3d(p)
    assert raw.labels == names
    assert np.isnan(raw.points[1, 299]).all()
    assert np.isfinite(raw.points[0, 299]).all()


def test_read_matches_labels_by_name_and_converts_mm_to_the_models_cm(tmp_path: Path) -> None:
    x = frames(4, 3)
    p = tmp_path / "t.c3d"
    write_c3d(p, x * 10.0, ["chin", "nose", "brow"], 30.0, "mm")
    take = takes.read(p, ["brow", "chin", "nose"], units="cm")
    ref = (x * 10.0).astype(np.float32).astype(np.float64)[:, [2, 0, 1]] * 0.1
    np.testing.assert_allclose(take.frames, ref, rtol=1e-12)
    assert (
        take.units == "cm" and take.source_units == "mm" and take.names == ["brow", "chin", "nose"]
    )


def test_names_absent_or_unknown_are_listed_and_allow_missing_gives_nan_columns(
    tmp_path: Path,
) -> None:
    x = frames(2, 3)
    p = tmp_path / "t.c3d"
    write_c3d(p, x, ["a", "b", "extra"], 30.0, "cm")
    with pytest.raises(InputError, match=r"not in the take: c.*not in the layout: extra"):
        takes.read(p, ["a", "b", "c"], units="cm")
    take = takes.read(p, ["a", "b", "c"], units="cm", allow_missing=True)
    assert np.isnan(take.frames[:, 2]).all()
    np.testing.assert_allclose(take.frames[:, :2], x[:, :2], rtol=1e-6)
    assert take.ignored == ("extra",)


def test_subject_prefixed_labels_match_plain_layout_names(tmp_path: Path) -> None:
    x = frames(2, 2)
    p = tmp_path / "t.c3d"
    write_c3d(p, x, ["actor:a", "actor:b"], 30.0, "cm")
    take = takes.read(p, ["b", "a"], units="cm")
    np.testing.assert_allclose(take.frames[:, 0], x[:, 1], rtol=1e-6)


def test_a_take_with_units_for_a_model_without_units_is_refused(tmp_path: Path) -> None:
    p = tmp_path / "t.c3d"
    write_c3d(p, frames(2, 1), ["a"], 30.0, "mm")
    with pytest.raises(InputError, match="model has no unit"):
        takes.read(p, ["a"])


def write_trc(path: Path, x: np.ndarray, names: list[str], rate: float, units: str) -> None:
    """TRC as Motion Analysis describes it: tab-separated header lines, then
    Frame#, Time, X1 Y1 Z1 ...; an empty cell is a missing sample."""
    f, n, _ = x.shape
    lines = [
        f"PathFileType\t4\t(X/Y/Z)\t{path.name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{rate:g}\t{rate:g}\t{f}\t{n}\t{units}\t{rate:g}\t1\t{f}",
        "Frame#\tTime\t" + "\t\t\t".join(names) + "\t\t",
        "\t\t" + "\t".join(f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(n)),
        "",
    ]
    for k in range(f):
        cells = ["" if np.isnan(v) else repr(float(v)) for v in x[k].ravel()]
        lines.append(f"{k + 1}\t{k / rate!r}\t" + "\t".join(cells))
    path.write_text("\n".join(lines) + "\n")


def test_trc_reads_back_exactly_with_blank_cells_missing(tmp_path: Path) -> None:
    x = frames(5, 3)
    x[3, 2] = np.nan
    p = tmp_path / "t.trc"
    write_trc(p, x, ["a", "b", "c"], 100.0, "mm")
    raw = takes.read_trc(p)
    assert raw.labels == ["a", "b", "c"] and raw.fps == 100.0 and raw.units == "mm"
    assert raw.first_frame == 1
    np.testing.assert_array_equal(raw.points, x)


@given(st.sampled_from(["_", ".", ":", " "]), st.booleans())
def test_csv_reads_back_exactly_with_any_axis_separator_and_time_gives_the_rate(
    sep: str, upper: bool
) -> None:
    import tempfile

    x = frames(4, 2)
    x[1, 0] = np.nan
    axes = "XYZ" if upper else "xyz"
    head = ["frame", "time"] + [f"{n}{sep}{a}" for n in ("m1", "m2") for a in axes]
    rows = [",".join(head)]
    for k in range(4):
        cells = ["" if np.isnan(v) else repr(float(v)) for v in x[k].ravel()]
        rows.append(",".join([str(k), repr(k / 25.0), *cells]))
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "t.csv"
        p.write_text("\n".join(rows) + "\n")
        raw = takes.read_csv(p)
    assert raw.labels == ["m1", "m2"] and raw.units is None
    assert raw.fps == pytest.approx(25.0)
    np.testing.assert_array_equal(raw.points, x)


def test_npz_take_reads_back_and_a_csv_without_units_is_taken_in_the_models_units(
    tmp_path: Path,
) -> None:
    x = frames(3, 2)
    p = tmp_path / "t.npz"
    np.savez(p, markers=x, names=np.array(["a", "b"]), fps=np.float64(24.0))
    take = takes.read(p, ["b", "a"], units="mm")
    np.testing.assert_array_equal(take.frames, x[:, ::-1])
    assert take.fps == 24.0 and take.units == "mm" and take.source_units is None
    take = takes.read(p, ["b", "a"], units="mm", take_units="cm")
    np.testing.assert_allclose(take.frames, x[:, ::-1] * 10.0, rtol=1e-15)


@pytest.mark.parametrize(
    ("name", "text", "match"),
    [
        ("t.trc", "hello\n", "not a TRC file"),
        ("t.csv", "frame,a_x,a_y\n0,1,2\n", "three columns per marker"),
        ("t.csv", "frame,a_x,a_y,a_q\n0,1,2,3\n", "are not NAME_x"),
        ("t.csv", "frame,a_x,a_y,a_z\n0,1,x,3\n", "line 2: a value is not a number"),
        ("t.csv", "frame,a_x,a_y,a_z\n0,1,2\n", "line 2: 3 columns"),
        ("t.csv", "frame,a_x,a_y,a_z\n0,1,inf,3\n", "line 2: infinite"),
        ("t.c3d", "garbage" * 20, "truncated C3D file: 140 bytes"),
        ("t.npz", "garbage", "not a readable take"),
        ("t.bvh", "x", "unknown take format '.bvh'"),
    ],
)
def test_malformed_takes_raise_input_error_naming_the_file(
    tmp_path: Path, name: str, text: str, match: str
) -> None:
    p = tmp_path / name
    p.write_text(text)
    with pytest.raises(InputError, match=match) as e:
        takes.read(p, ["a"], units="cm")
    assert str(p) in str(e.value)


def test_a_missing_take_file_is_an_input_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such take file"):
        takes.read(tmp_path / "none.c3d")


def test_npz_take_without_names_lists_what_it_needs(tmp_path: Path) -> None:
    p = tmp_path / "t.npz"
    np.savez(p, markers=frames(2, 2))
    with pytest.raises(InputError, match=r"needs arrays \['markers', 'names'\]"):
        takes.read(p)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("", "header is 'name,x,y,z'"),
        ("id,x,y,z\na,1,2,3\n", "line 1: a marker layout's header"),
        ("name,x,y,z\na,1,2\n", "line 2: 3 columns"),
        ("name,x,y,z\na,1,b,3\n", "line 2: marker 'a': a coordinate is not a number"),
        ("name,x,y,z\na,1,nan,3\n", "line 2: marker 'a': a coordinate is not finite"),
        ("name,x,y,z\na,1,2,3\na,1,2,3\n", "line 3: marker 'a' repeats line 2"),
        ("name,x,y,z\n,1,2,3\n", "line 2: empty marker name"),
        ("name,x,y,z\n", "has no markers"),
    ],
)
def test_garbled_layouts_raise_input_error_naming_file_and_line(
    tmp_path: Path, text: str, match: str
) -> None:
    p = tmp_path / "markers.csv"
    p.write_text(text)
    with pytest.raises(InputError, match=match):
        takes.read_layout(p)


def test_layout_reads_names_and_positions_in_file_order(tmp_path: Path) -> None:
    p = tmp_path / "markers.csv"
    p.write_text("name,x,y,z\nchin,1.5,-2,3e-1\nnose,0,0,1\n")
    lay = takes.read_layout(p)
    assert lay.names == ["chin", "nose"]
    np.testing.assert_array_equal(lay.positions, [[1.5, -2.0, 0.3], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize(
    ("a", "b", "factor"),
    [("mm", "cm", 0.1), ("m", "mm", 1000.0), ("in", "cm", 2.54), ("Millimeters", "m", 0.001)],
)
def test_unit_scale_matches_the_definitions(a: str, b: str, factor: float) -> None:
    assert units.unit_scale(a, b) == pytest.approx(factor, rel=1e-15)


def test_unknown_units_are_refused_naming_them() -> None:
    with pytest.raises(InputError, match="unknown length unit 'furlong'"):
        units.normalize_unit("furlong", "units")


@given(st.permutations(list(range(6))), st.integers(0, 3))
def test_match_layout_puts_every_label_in_its_layout_column_whatever_the_file_order(
    order: list[int], absent: int
) -> None:
    """Brute force: column b of the result is the file column whose label is layout name b;
    names the file lacks (the last `absent` of the order) are NaN with allow_missing."""
    names = [f"n{i}" for i in range(6)]
    present = order[: 6 - absent]
    pts = RNG.normal(size=(3, len(present), 3))
    raw = takes.RawTake([names[i] for i in present], pts, None, None, "mem")
    out, ignored = takes.match_layout(raw, names, allow_missing=True)
    assert ignored == ()
    for b in range(6):
        if b in present:
            np.testing.assert_array_equal(out[:, b], pts[:, present.index(b)])
        else:
            assert np.isnan(out[:, b]).all()
    if absent:
        with pytest.raises(InputError, match="not in the take"):
            takes.match_layout(raw, names)


def test_converting_to_a_whole_multiple_unit_divides_exactly_as_a_user_would() -> None:
    x = RNG.normal(size=1000) * 100.0
    np.testing.assert_array_equal(units.convert_units(x, "mm", "cm"), x / 10.0)
    np.testing.assert_array_equal(units.convert_units(x, "mm", "m"), x / 1000.0)
    np.testing.assert_array_equal(units.convert_units(x, "cm", "mm"), x * 10.0)
    np.testing.assert_allclose(units.convert_units(x, "in", "cm"), x * 2.54, rtol=1e-15)


def test_labels_with_a_prefix_are_refused_in_a_short_message_that_names_the_prefix() -> None:
    from lgi.io.takes import RawTake, match_layout

    names = [f"m{i:03d}" for i in range(240)]
    raw = RawTake([f"Actor1_{n}" for n in names], np.zeros((2, 240, 3)), 60.0, "mm", "t.c3d")
    with pytest.raises(InputError) as e:
        match_layout(raw, names)
    text = str(e.value)
    assert "with the prefix 'Actor1_' (e.g. 'Actor1_m000')" in text
    assert "240 of the 240 unknown labels" in text
    assert "... and 232 more" in text and len(text) < 1000
    upper = RawTake([n.upper() for n in names], np.zeros((2, 240, 3)), 60.0, "mm", "t.c3d")
    with pytest.raises(InputError, match="differ from the layout's names only in letter case"):
        match_layout(upper, names)
