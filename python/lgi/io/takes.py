"""Marker takes in: recordings from the capture stage, read into arrays in the model's terms.

Marker takes (`read`): C3D (`lgi.io.c3d_format`), TRC, labelled CSV and `.npz`, with their labels
matched to the model's marker names and their units converted to the model's
(`lgi.io.units`); marker layouts (`read_layout`: CSV `name,x,y,z`).
"""

from __future__ import annotations

import itertools
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lgi.errors import InputError, LgiWarning
from lgi.io.csv_rows import read_csv_rows
from lgi.io.units import convert_units, normalize_unit

F64 = NDArray[np.float64]

__all__ = [
    "NPZ_TAKE_KEYS",
    "TAKE_SUFFIXES",
    "HeadMotion",
    "Layout",
    "RawTake",
    "Take",
    "label_columns",
    "match_layout",
    "plain_label",
    "read",
    "read_c3d",
    "read_csv",
    "read_layout",
    "read_npz",
    "read_raw",
    "read_trc",
]


@dataclass(frozen=True)
class HeadMotion:
    """The head's rigid motion per frame as `lgi.capture.stabilize.align` found it (capture =
    R_f rest + t_f), kept with the take so an exporter can write it beside the solved face."""

    rotations: F64
    """(F, 3, 3)."""
    translations: F64
    """(F, 3), in the take's units."""

    def __getitem__(self, frames: slice) -> HeadMotion:
        return HeadMotion(self.rotations[frames], self.translations[frames])


TAKE_SUFFIXES = (".c3d", ".trc", ".csv", ".npz")
"""File suffixes `read` understands (case-insensitive)."""


@dataclass(frozen=True)
class Layout:
    """A named marker layout (`read_layout`)."""

    names: list[str]
    """B marker names, in file order."""
    positions: F64
    """(B, 3) rest positions."""
    path: str


def read_layout(path: str | os.PathLike[str]) -> Layout:
    """Reads a marker layout CSV: a header `name,x,y,z`, then one marker per line. Raises
    `InputError` naming the file and line: missing file, bad header, wrong column count, a
    coordinate that is not a finite number, an empty or repeated name."""
    p, rows = read_csv_rows(path, "the marker layout")
    header = [c.strip().lower() for c in rows[0]] if rows else []
    if header != ["name", "x", "y", "z"]:
        raise InputError(
            f"{p}, line 1: a marker layout's header is 'name,x,y,z' "
            f"(got {','.join(rows[0]) if rows else 'an empty file'!r})"
        )
    names: list[str] = []
    positions: list[list[float]] = []
    seen: dict[str, int] = {}
    for i, row in enumerate(rows[1:]):
        line = i + 2
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != 4:
            raise InputError(f"{p}, line {line}: {len(row)} columns, expected 4 (name,x,y,z)")
        name = row[0].strip()
        if not name:
            raise InputError(f"{p}, line {line}: empty marker name")
        if name in seen:
            raise InputError(f"{p}, line {line}: marker {name!r} repeats line {seen[name]}")
        seen[name] = line
        try:
            xyz = [float(c) for c in row[1:]]
        except ValueError:
            raise InputError(
                f"{p}, line {line}: marker {name!r}: a coordinate is not a number"
            ) from None
        if not all(np.isfinite(xyz)):
            raise InputError(f"{p}, line {line}: marker {name!r}: a coordinate is not finite")
        names.append(name)
        positions.append(xyz)
    if not names:
        raise InputError(f"{p}: the marker layout has no markers")
    return Layout(names=names, positions=np.array(positions, dtype=np.float64), path=p)


@dataclass(frozen=True)
class RawTake:
    """A marker take as its file holds it: labels in file order, NaN where a sample is
    missing, the file's own units (None when the format has none)."""

    labels: list[str]
    points: F64
    """(F, N, 3) coordinates, file units; NaN rows are missing samples."""
    fps: float | None
    units: str | None
    path: str
    first_frame: int = 0
    """The file's number of the first frame (C3D header, TRC `Frame#`)."""
    head: HeadMotion | None = None
    """The head's rigid motion per frame, when the file carries it (`lgi triangulate`)."""


@dataclass(frozen=True)
class Take:
    """A marker take matched to a layout (`read`): ready for `Model.solve`."""

    frames: F64
    """(F, B, 3) in the layout's order and the target units; NaN rows are missing markers."""
    names: list[str]
    """The B layout names the columns follow."""
    fps: float | None
    units: str | None
    """Units of `frames` (the target's; the file's when no target was given)."""
    source_units: str | None
    """Units the file declared (None when it has none)."""
    path: str
    first_frame: int = 0
    ignored: tuple[str, ...] = ()
    """Labels of the file unknown to the layout, left out (only with `allow_missing`)."""
    head: HeadMotion | None = None
    """The head's rigid motion per frame, when the file carries it (`lgi triangulate`:
    the stabilisation's transforms), translations in `units`."""

    @property
    def num_frames(self) -> int:
        return int(self.frames.shape[0])


def read_c3d(path: str | os.PathLike[str]) -> RawTake:
    """Reads a C3D file (`lgi.io.c3d_format`): labels from `POINT:LABELS` (then `LABELS2`,
    ... past 255), units from `POINT:UNITS`, rate from `POINT:RATE`, the first frame from the
    header (1-based, as a TRC's `Frame#`); a sample with a negative residual or all-zero
    coordinates is missing (NaN). Not ezc3d: it refuses real writers' files (OptiTrack, BTK's
    tests) and crashed the process (a segmentation fault) on damaged ones the fuzz suite
    made; on every shared file ezc3d reads, the two agree to the float
    (`tests/test_set_files.py`)."""
    p = os.fspath(path)
    if not os.path.isfile(p):
        raise InputError(f"{p}: no such take file")
    if os.path.getsize(p) == 0:
        raise InputError(f"{p}: the file is empty")
    return _read_c3d_ourselves(p)


def _read_c3d_ourselves(p: str) -> RawTake:
    """`lgi.io.c3d_format`'s reading (tolerant of the defects BTK reads past, each said in a
    warning); its `InputError` names the defect when the file cannot be read at all."""
    from lgi.io.c3d_format import read_c3d_file

    c = read_c3d_file(p)
    if c.defects:
        more = f" (and {len(c.defects) - 1} more)" if len(c.defects) > 1 else ""
        warnings.warn(
            f"{p}: read past a defect in the file: {c.defects[0]}{more}",
            LgiWarning,
            stacklevel=3,
        )
    return RawTake(c.labels, c.points, c.fps, c.units, p, c.first_frame)


def read_trc(path: str | os.PathLike[str]) -> RawTake:
    """Reads a TRC file (Motion Analysis / OpenSim, tab-separated): line 2 names the fields
    of line 3 (`DataRate`, `NumFrames`, `Units`, ...), line 4 is `Frame#`, `Time` and one name
    per marker (each over 3 columns), line 5 the `X1 Y1 Z1 ...` headers, then one row per
    frame; empty cells are missing samples. Time is kept: `Frame#` numbers the frames (a gap
    becomes missing frames at their numbers, with an `LgiWarning`; a repeated or backward
    number is an error), `Time` must agree with it at `DataRate`, a row with fewer columns
    than the markers need (a cut row) and a `NumFrames` that is not the rows' count are
    errors naming the line. Values past the named markers (some writers leave unnamed
    columns) are not read, with a warning."""
    p = os.fspath(path)
    try:
        with open(p, encoding="utf-8-sig") as fh:
            lines = fh.read().splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"{p}: cannot read a TRC file: {e}") from None
    if not lines or not any(line.strip() for line in lines):
        raise InputError(f"{p}: the file is empty")
    if not lines[0].startswith("PathFileType"):
        raise InputError(f"{p}: not a TRC file (line 1 must start with 'PathFileType')")
    if len(lines) < 5:
        raise InputError(
            f"{p}: truncated TRC file: it ends at line {len(lines)}, inside the header (a TRC "
            "file has 5 header lines before the frames)"
        )
    keys = [k.strip() for k in lines[1].split("\t")]
    vals = [v.strip() for v in lines[2].split("\t")]
    meta = dict(zip(keys, vals, strict=False))
    head = lines[3].split("\t")
    if len(head) < 3 or head[0].strip() != "Frame#":
        raise InputError(f"{p}, line 4: expected 'Frame#', 'Time' and the marker names")
    labels = [h.strip() for h in head[2:] if h.strip()]
    n = len(labels)
    try:
        fps = float(meta["DataRate"]) if meta.get("DataRate") else None
    except ValueError:
        raise InputError(f"{p}, line 3: DataRate {meta['DataRate']!r} is not a number") from None
    declared_markers = _header_count(p, meta, "NumMarkers")
    if declared_markers is not None and declared_markers != n:
        warnings.warn(
            f"{p}: line 3 gives NumMarkers {declared_markers}, line 4 names {n} markers; "
            f"the {n} named ones are read",
            LgiWarning,
            stacklevel=2,
        )
    need = 2 + 3 * n
    rows: list[list[float]] = []
    numbers: list[int] = []
    times: list[tuple[int, float]] = []
    extra = 0
    for i, raw in enumerate(lines[5:]):
        line = i + 6
        if not raw.strip():
            continue
        cells = raw.split("\t")
        if len(cells) < need and any(c.strip() for c in cells):
            raise InputError(
                f"{p}, line {line}: the row has {len(cells)} of {need} columns ({n} markers): "
                "a cut row"
            )
        if any(c.strip() for c in cells[need:]):
            extra = max(extra, len(cells))
        try:
            number = float(cells[0])
            if number != int(number):
                raise ValueError
            rows.append([float(c) if c.strip() else np.nan for c in cells[2:need]])
        except ValueError:
            raise InputError(f"{p}, line {line}: a value is not a number") from None
        if numbers and int(number) <= numbers[-1]:
            raise InputError(
                f"{p}, line {line}: Frame# {int(number)} after {numbers[-1]}: frame numbers "
                "must increase"
            )
        numbers.append(int(number))
        if cells[1].strip():
            try:
                times.append((line, float(cells[1])))
            except ValueError:
                raise InputError(f"{p}, line {line}: Time {cells[1]!r} is not a number") from None
        else:
            times.append((line, np.nan))
    if not rows:
        raise InputError(f"{p}: the take has no frames")
    declared_frames = _header_count(p, meta, "NumFrames")
    if declared_frames is not None and declared_frames != len(rows):
        raise InputError(
            f"{p}, line 3: NumFrames is {declared_frames} but the file holds {len(rows)} frame "
            "rows: a truncated or edited file"
        )
    if extra:
        warnings.warn(
            f"{p}: rows carry values past the {n} markers named in line 4 (up to column "
            f"{extra}); those columns have no names and are not read",
            LgiWarning,
            stacklevel=2,
        )
    _check_trc_times(p, numbers, times, fps)
    first, last = numbers[0], numbers[-1]
    xyz = np.full((last - first + 1, n, 3), np.nan)
    xyz[np.asarray(numbers) - first] = np.array(rows, dtype=np.float64).reshape(len(rows), n, 3)
    if len(rows) < xyz.shape[0]:
        gaps = _gaps(numbers)
        shown = ", ".join(f"{a}-{b}" if a != b else f"{a}" for a, b in gaps[:3])
        warnings.warn(
            f"{p}: Frame# skips {xyz.shape[0] - len(rows)} frames ({shown}"
            f"{', ...' if len(gaps) > 3 else ''}); they are missing frames at their time codes",
            LgiWarning,
            stacklevel=2,
        )
    if np.isinf(xyz).any():
        raise InputError(f"{p}: infinite coordinate")
    units = meta.get("Units") or None
    return RawTake(labels, xyz, fps, units, p, first)


def _header_count(p: str, meta: dict[str, str], key: str) -> int | None:
    """A whole-number field of a TRC's line 3 (`NumFrames`, `NumMarkers`), None if absent."""
    v = meta.get(key, "").strip()
    if not v:
        return None
    try:
        return int(v)
    except ValueError:
        raise InputError(f"{p}, line 3: {key} {v!r} is not a whole number") from None


def _gaps(numbers: list[int]) -> list[tuple[int, int]]:
    """Runs of frame numbers absent between consecutive `numbers`."""
    return [(a + 1, b - 1) for a, b in itertools.pairwise(numbers) if b - a > 1]


def _check_trc_times(
    p: str, numbers: list[int], times: list[tuple[int, float]], fps: float | None
) -> None:
    """Each row's `Time` must be the first row's plus (Frame# - first Frame#) / DataRate,
    to half a frame: a `Time` that disagrees means the frame numbers cannot be trusted."""
    if fps is None or fps <= 0:
        return
    t0 = next((t for _, t in times if np.isfinite(t)), None)
    if t0 is None:
        return
    k0 = numbers[next(k for k, (_, t) in enumerate(times) if np.isfinite(t))]
    for number, (line, t) in zip(numbers, times, strict=True):
        if not np.isfinite(t):
            continue
        want = t0 + (number - k0) / fps
        if abs(t - want) > 0.5 / fps:
            raise InputError(
                f"{p}, line {line}: Time {t:g} s does not match Frame# {number} at "
                f"{fps:g} frames per second ({want:g} s)"
            )


_AXES = ("x", "y", "z")


def _split_axis(column: str) -> tuple[str, str] | None:
    """`NAME_x` / `NAME.x` / `NAME:x` / `NAME x` (any case) -> (`NAME`, `x`)."""
    c = column.strip()
    if len(c) >= 3 and c[-1].lower() in _AXES and c[-2] in "_.: ":
        return c[:-2], c[-1].lower()
    return None


def read_csv(path: str | os.PathLike[str], fps: float | None = None) -> RawTake:
    """Reads a labelled marker CSV: one row per frame, three columns per marker named
    `NAME_x,NAME_y,NAME_z` (`.`, `:` or a space may replace `_`; any case), optionally led by
    a `frame` and/or `time` column (seconds: gives the rate when `fps` is None). Empty or
    `nan` cells are missing samples. CSV has no units: the coordinates are taken to be in the
    target's units unless `read(take_units=...)` says otherwise."""
    p, rows = read_csv_rows(path, "a marker CSV")
    if not rows:
        raise InputError(f"{p}: empty file")
    header = [h.strip() for h in rows[0]]
    # Leading `frame` / `time` columns (either, both, any order), then the coordinates.
    skip = 0
    while skip < min(2, len(header)) and header[skip].lower() in ("frame", "time"):
        skip += 1
    lead = [h.lower() for h in header[:skip]]
    time_col = lead.index("time") if "time" in lead else None
    columns = header[skip:]
    if not columns or len(columns) % 3:
        raise InputError(
            f"{p}, line 1: expected a frame/time column and three columns per marker "
            f"(NAME_x, NAME_y, NAME_z); got {len(columns)} coordinate columns"
        )
    labels: list[str] = []
    for k in range(0, len(columns), 3):
        parts = [_split_axis(c) for c in columns[k : k + 3]]
        split = [q for q in parts if q is not None]
        if (
            len(split) != 3
            or [q[1] for q in split] != list(_AXES)
            or len({q[0] for q in split}) != 1
        ):
            raise InputError(
                f"{p}, line 1: columns {skip + k + 1}-{skip + k + 3} "
                f"({', '.join(columns[k : k + 3])}) are not NAME_x, NAME_y, NAME_z"
            )
        labels.append(split[0][0])
    data = np.empty((len(rows) - 1, len(columns)))
    times: list[float] = []
    for i, row in enumerate(rows[1:]):
        line = i + 2
        if len(row) != len(header):
            raise InputError(f"{p}, line {line}: {len(row)} columns, the header has {len(header)}")
        try:
            data[i] = [float(c) if c.strip() else np.nan for c in row[skip:]]
            if time_col is not None:
                times.append(float(row[time_col]))
        except ValueError:
            raise InputError(f"{p}, line {line}: a value is not a number") from None
    if data.shape[0] == 0:
        raise InputError(f"{p}: the take has no frames")
    if np.isinf(data).any():
        line = int(np.argmax(np.isinf(data).any(axis=1))) + 2
        raise InputError(f"{p}, line {line}: infinite coordinate")
    if fps is None and len(times) >= 2 and np.all(np.diff(times) > 0):
        fps = float(1.0 / np.median(np.diff(times)))
    return RawTake(labels, data.reshape(len(data), -1, 3), fps, None, p)


NPZ_TAKE_KEYS = ("markers", "names", "fps", "units")
"""Arrays of a take `.npz`: `markers` (F, N, 3) float (NaN = missing), `names` (N,) str, and
optionally `fps` (scalar) and `units` (str)."""


def read_npz(path: str | os.PathLike[str]) -> RawTake:
    """Reads a take `.npz` of the `NPZ_TAKE_KEYS` layout (`allow_pickle=False`)."""
    p = os.fspath(path)
    try:
        with np.load(p, allow_pickle=False) as z:
            if not isinstance(z, np.lib.npyio.NpzFile):  # pragma: no cover - .npy given
                raise InputError(f"{p}: not an .npz archive")
            missing = [k for k in NPZ_TAKE_KEYS[:2] if k not in z.files]
            if missing:
                raise InputError(
                    f"{p}: a take .npz needs arrays {list(NPZ_TAKE_KEYS[:2])}; missing "
                    f"{missing} (the archive has {z.files})"
                )
            markers = np.asarray(z["markers"])
            names = [str(x) for x in np.asarray(z["names"]).ravel()]
            fps = float(z["fps"]) if "fps" in z.files else None
            units = str(z["units"]) if "units" in z.files else None
            head = None
            if "rotations" in z.files and "translations" in z.files:
                head = HeadMotion(
                    np.asarray(z["rotations"], dtype=np.float64),
                    np.asarray(z["translations"], dtype=np.float64),
                )
    except InputError:
        raise
    except Exception as e:  # garbled archive: numpy raises various classes
        raise InputError(f"{p}: not a readable take .npz: {e}") from None
    if markers.ndim != 3 or markers.shape[2] != 3 or markers.dtype.kind not in "iuf":
        raise InputError(f"{p}: 'markers' must be (F, N, 3) numbers, got {markers.shape}")
    if markers.shape[1] != len(names):
        raise InputError(f"{p}: {markers.shape[1]} marker columns but {len(names)} names")
    m = markers.astype(np.float64)
    if np.isinf(m).any():
        raise InputError(f"{p}: infinite coordinate")
    f = m.shape[0]
    if head is not None and (
        head.rotations.shape != (f, 3, 3)
        or head.translations.shape != (f, 3)
        or not (np.isfinite(head.rotations).all() and np.isfinite(head.translations).all())
    ):
        raise InputError(
            f"{p}: 'rotations' must be ({f}, 3, 3) and 'translations' ({f}, 3), finite; got "
            f"{head.rotations.shape} and {head.translations.shape}"
        )
    return RawTake(names, m, fps, units or None, p, head=head)


_READERS = {".c3d": read_c3d, ".trc": read_trc, ".csv": read_csv, ".npz": read_npz}


def read_raw(path: str | os.PathLike[str]) -> RawTake:
    """Reads a take by its suffix (`TAKE_SUFFIXES`), without matching it to a layout."""
    p = os.fspath(path)
    suffix = os.path.splitext(p)[1].lower()
    if suffix not in _READERS:
        raise InputError(
            f"{p}: unknown take format {suffix or '(no suffix)'!r}; "
            f"known: {', '.join(TAKE_SUFFIXES)}"
        )
    if not os.path.isfile(p):
        raise InputError(f"{p}: no such take file")
    return _READERS[suffix](p)


def plain_label(label: str) -> str:
    """A label without a `Subject:` prefix (Vicon and others prefix labels with it)."""
    return label.rsplit(":", 1)[-1].strip()


def label_columns(
    raw: RawTake, names: Sequence[str]
) -> tuple[list[int], list[str], tuple[str, ...]]:
    """For each of `names`, the take column whose label is that name (exactly, or after
    dropping a `Subject:` prefix), -1 when none; the names without a column; the labels no
    name took. A label that appears twice is an `InputError`."""
    where: dict[str, int] = {}
    for j, lab in enumerate(raw.labels):
        if lab in where:
            raise InputError(f"{raw.path}: label {lab!r} appears twice (columns {where[lab]}, {j})")
        where[lab] = j
    wanted = set(names)
    for lab, j in list(where.items()):
        plain = plain_label(lab)
        if lab not in wanted and plain in wanted and plain not in where:
            where[plain] = j
    cols = [where.get(n, -1) for n in names]
    absent = [n for n, c in zip(names, cols, strict=True) if c < 0]
    used = {c for c in cols if c >= 0}
    unknown = tuple(lab for j, lab in enumerate(raw.labels) if j not in used)
    return cols, absent, unknown


SHOWN_LABELS = 8
"""Labels an error lists before "... and N more"."""


def _some(labels: Sequence[str]) -> str:
    shown = ", ".join(labels[:SHOWN_LABELS])
    more = len(labels) - SHOWN_LABELS
    return shown + (f", ... and {more} more" if more > 0 else "")


def label_hint(unknown: Sequence[str], names: Sequence[str]) -> str | None:
    """Why a take's labels miss the layout when the reason is mechanical: a common prefix
    or suffix (`Actor1_m000`, `m000_R`), a separator, or letter case. None otherwise."""
    wanted = set(names)
    if not unknown:
        return None
    lowered = {n.lower(): n for n in names}
    if sum(lab.lower() in lowered for lab in unknown) >= len(unknown) / 2:
        return "the labels differ from the layout's names only in letter case: rename them"
    best: tuple[int, str, str] = (0, "", "")
    for side in ("prefix", "suffix"):
        counts: dict[str, int] = {}
        for lab in unknown:
            for n in wanted:
                if len(lab) > len(n) and (
                    lab.endswith(n) if side == "prefix" else lab.startswith(n)
                ):
                    cut = lab[: len(lab) - len(n)] if side == "prefix" else lab[len(n) :]
                    counts[cut] = counts.get(cut, 0) + 1
        for cut, k in counts.items():
            if k > best[0]:
                best = (k, side, cut)
    k, side, cut = best
    if k < max(1, len(unknown) // 2):
        return None
    example = next(
        lab for lab in unknown if (lab.startswith(cut) if side == "prefix" else lab.endswith(cut))
    )
    return (
        f"{k} of the {len(unknown)} unknown labels are layout names with the {side} {cut!r} "
        f"(e.g. {example!r}): remove it from the take's labels, or name the layout's markers "
        "with it"
    )


def match_layout(
    raw: RawTake, names: Sequence[str], allow_missing: bool = False
) -> tuple[F64, tuple[str, ...]]:
    """The take's columns in the order of `names` (F, B, 3), and the labels left out
    (`label_columns`). A name the take lacks or a label the layout lacks is an `InputError`
    listing them; with `allow_missing` the first become NaN columns and the second are left
    out."""
    cols, absent, unknown = label_columns(raw, names)
    if (absent or unknown) and not allow_missing:
        parts = []
        if absent:
            parts.append(f"{len(absent)} layout markers are not in the take: {_some(absent)}")
        if unknown:
            parts.append(f"{len(unknown)} take labels are not in the layout: {_some(unknown)}")
        hint = label_hint(unknown, names)
        raise InputError(
            f"{raw.path}: labels do not match the model's markers: {'; '.join(parts)}"
            + (f". {hint}" if hint else "")
            + " (allow_missing / --allow-missing solves with the absent markers missing and "
            "the unknown labels left out)"
        )
    out = np.full((raw.points.shape[0], len(names), 3), np.nan)
    for b, c in enumerate(cols):
        if c >= 0:
            out[:, b] = raw.points[:, c]
    return out, unknown


def read(
    path: str | os.PathLike[str],
    layout: Sequence[str] | None = None,
    *,
    units: str | None = None,
    take_units: str | None = None,
    allow_missing: bool = False,
) -> Take:
    """Reads a marker take (C3D, TRC, labelled CSV or `.npz`, by suffix) as (F, B, 3) frames
    for a model: columns matched to `layout` (the model's `marker_names`; None keeps the
    file's labels and order) by name (`match_layout`), coordinates converted from the file's
    units (or `take_units`, which overrides them) to `units` (the model's). A file without
    units (CSV, most `.npz`) is taken to be in `units` already. A file with units read for a
    target without units is an `InputError` (say the model's units: `lgi build --units`)."""
    raw = read_raw(path)
    source = normalize_unit(take_units, "take_units") if take_units else None
    if source is None and raw.units is not None:
        source = normalize_unit(raw.units, f"{raw.path}: units")
    target = normalize_unit(units, "units") if units else None
    ignored: tuple[str, ...] = ()
    if layout is None:
        frames, names = raw.points.copy(), list(raw.labels)
    else:
        frames, ignored = match_layout(raw, layout, allow_missing)
        names = list(layout)
    head = raw.head
    if source is not None and target is not None:
        frames = convert_units(frames, source, target)
        if head is not None:
            head = HeadMotion(head.rotations, convert_units(head.translations, source, target))
    elif source is not None and target is None and layout is not None:
        raise InputError(
            f"{raw.path}: the take is in {source!r} but the model has no unit to convert to; "
            "build the model with units (lgi build --units, Model.build(units=...))"
        )
    return Take(
        frames=frames,
        names=names,
        fps=raw.fps,
        units=target or source,
        source_units=source,
        path=raw.path,
        first_frame=raw.first_frame,
        ignored=ignored,
        head=head,
    )
