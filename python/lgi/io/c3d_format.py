"""A small C3D reader from the format's published description (c3d.org, "The C3D File Format
User Guide"), for the files ezc3d refuses: it needs only what a take needs (the 3D points,
their labels, rate, unit and first frame) and reads past two defects real writers leave, as
BTK does, saying what was off:

- a parameter's description-length byte missing (OptiTrack's `POINT:LABELS`): each record's
  next-record offset is followed, so a description is never needed;
- a wrong next-record offset (`badParameterOffset.c3d`): when the offset does not land on a
  valid record, the record's own length (name, data, description) gives the next one.

Layout: a 512-byte header (word 1: the parameter section's first block, byte 2 = 0x50; word 2:
points; word 3: analog values per frame; words 4-5: first and last frame; word 7-8: the POINT
scale, float; word 9: the data's first block; words 11-12: the frame rate, float), then the
parameter section (4-byte header, byte 4: processor 84 Intel, 85 DEC, 86 MIPS), then frames of
`points` x (x, y, z, residual word) followed by the analog values, as int16 when the scale is
positive, float32 when negative."""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lgi.errors import InputError

__all__ = ["C3dContents", "read_c3d_file"]


@dataclass
class C3dContents:
    labels: list[str]
    points: NDArray[np.float64]
    """(F, N, 3), NaN where a sample is invalid (negative residual word)."""
    fps: float | None
    units: str | None
    first_frame: int
    defects: list[str] = field(default_factory=list)
    """What was off in the file and read past."""


def _dec_to_ieee(raw: bytes) -> float:
    """A DEC (VAX F) float's 4 bytes as a number: its words swapped, divided by 4."""
    swapped = raw[2:4] + raw[0:2]
    return float(struct.unpack("<f", swapped)[0]) / 4.0


class _Reader:
    def __init__(self, path: str, data: bytes) -> None:
        self.path, self.data = path, data
        if len(data) < 512:
            raise InputError(f"{path}: truncated C3D file: {len(data)} bytes, the header is 512")
        if data[1] != 0x50:
            raise InputError(f"{path}: not a C3D file (byte 2 is {data[1]:#04x}, not 0x50)")
        self.param_start = (max(data[0], 1) - 1) * 512
        if self.param_start + 4 > len(data):
            raise InputError(f"{path}: truncated C3D file: the parameter section is missing")
        processor = data[self.param_start + 3]
        if processor not in (84, 85, 86):
            raise InputError(
                f"{path}: unknown processor type {processor} in the parameter section "
                "(84 Intel, 85 DEC, 86 MIPS)"
            )
        self.processor = processor
        self.order = ">" if processor == 86 else "<"

    def word(self, offset: int) -> int:
        return int(struct.unpack(f"{self.order}H", self.data[offset : offset + 2])[0])

    def real(self, raw: bytes) -> float:
        if self.processor == 85:
            return _dec_to_ieee(raw)
        return float(struct.unpack(f"{self.order}f", raw)[0])


def _record_ok(data: bytes, at: int, end: int) -> bool:
    """Whether a parameter-section record plausibly starts at `at`: a name of 1..127
    printable characters and a group id that is not 0."""
    if at + 2 > end:
        return False
    n = abs(struct.unpack("b", data[at : at + 1])[0])
    gid = struct.unpack("b", data[at + 1 : at + 2])[0]
    name = data[at + 2 : at + 2 + n]
    return 0 < n and gid != 0 and len(name) == n and all(32 < c < 127 for c in name)


def _parameters(r: _Reader, defects: list[str]) -> dict[tuple[str, str], Any]:
    """The parameter section as {(GROUP, NAME): value}; char arrays as lists of strings."""
    data = r.data
    blocks = data[r.param_start + 2] or 1
    end = min(len(data), r.param_start + 512 * blocks)
    groups: dict[int, str] = {}
    params: list[tuple[int, str, Any]] = []
    at = r.param_start + 4
    while at + 2 <= end:
        n = struct.unpack("b", data[at : at + 1])[0]
        if n == 0:
            break
        n = abs(n)
        gid = struct.unpack("b", data[at + 1 : at + 2])[0]
        name = data[at + 2 : at + 2 + n].decode("latin-1").strip().upper()
        off_at = at + 2 + n
        if off_at + 2 > end:
            break
        offset = r.word(off_at)
        body = off_at + 2
        try:
            if gid < 0:
                groups[-gid] = name
                dlen = data[body]
                own_next = body + 1 + dlen
            else:
                kind = struct.unpack("b", data[body : body + 1])[0]
                ndims = data[body + 1]
                dims = list(data[body + 2 : body + 2 + ndims])
                start = body + 2 + ndims
                size = abs(kind) * int(np.prod(dims)) if dims else abs(kind)
                raw = data[start : start + size]
                params.append((gid, name, _value(r, kind, dims, raw)))
                dlen = data[start + size] if start + size < end else 0
                own_next = start + size + 1 + dlen
        except (IndexError, struct.error, ValueError):
            break
        if offset == 0:
            break
        by_offset = off_at + offset
        if by_offset != own_next and not _record_ok(data, by_offset, end):
            if not _record_ok(data, own_next, end):
                break
            defects.append(
                f"parameter {name}: its next-record offset ({offset}) points off the records; "
                "the record's own length was followed"
            )
            at = own_next
            continue
        if by_offset != own_next and name:
            # The offset lands on a record the record's own length misses: a missing or
            # wrong description length, harmless since descriptions are not read.
            group = groups.get(gid, "?")
            defects.append(
                f"parameter {group}:{name}: its description length does not fit the record "
                "(the next-record offset was followed)"
            )
        at = by_offset
    return {(groups.get(g, "?"), nm): v for g, nm, v in params}


def _text(raw: bytes) -> str:
    """A C3D string: fixed width, padded with spaces or NULs."""
    return raw.decode("latin-1").replace("\0", " ").strip()


def _value(r: _Reader, kind: int, dims: list[int], raw: bytes) -> Any:
    if kind == -1:  # characters: dims[0] per string
        if not dims:
            return [_text(raw)]
        width = dims[0]
        count = int(np.prod(dims[1:])) if len(dims) > 1 else 1
        return [_text(raw[k * width : (k + 1) * width]) for k in range(count)]
    if kind == 1:
        return list(raw)
    if kind == 2:
        n = len(raw) // 2
        return list(struct.unpack(f"{r.order}{n}h", raw[: 2 * n]))
    if kind == 4:
        return [r.real(raw[k : k + 4]) for k in range(0, len(raw) - 3, 4)]
    raise ValueError(kind)


def read_c3d_file(path: str) -> C3dContents:
    """Reads a C3D file's 3D points (`InputError` naming the defect when it cannot)."""
    try:
        return _read(path)
    except (struct.error, ValueError, IndexError, OverflowError, MemoryError) as e:
        raise InputError(f"{path}: a malformed C3D file ({type(e).__name__}: {e})") from None


def _read(path: str) -> C3dContents:
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as e:
        raise InputError(f"{path}: cannot read: {e.strerror}") from None
    if not data:
        raise InputError(f"{path}: the file is empty")
    r = _Reader(path, data)
    defects: list[str] = []
    params = _parameters(r, defects)
    n_points = r.word(2)
    analog = r.word(4)
    first, last = r.word(6), r.word(8)
    scale = r.real(data[12:16])
    data_block = r.word(16)
    rate = r.real(data[20:24])
    used = params.get(("POINT", "USED"))
    if used:
        n_points = int(used[0]) & 0xFFFF
    if params.get(("POINT", "SCALE")):
        scale = float(params[("POINT", "SCALE")][0])
    if params.get(("POINT", "DATA_START")):
        data_block = int(params[("POINT", "DATA_START")][0]) & 0xFFFF
    if params.get(("POINT", "RATE")):
        rate = float(params[("POINT", "RATE")][0])
    if n_points == 0:
        raise InputError(f"{path}: the C3D file holds no 3D marker points (only analog data)")
    labels: list[str] = []
    for key in ["LABELS", *(f"LABELS{k}" for k in range(2, 100))]:
        if ("POINT", key) not in params:
            break
        labels += list(params[("POINT", key)])
    if len(labels) < n_points:
        defects.append(f"POINT:LABELS names {len(labels)} of {n_points} points; the rest are P#")
        labels += [f"P{k + 1}" for k in range(len(labels), n_points)]
    frames = last - first + 1
    declared = params.get(("POINT", "FRAMES"))
    if last == 0xFFFF and declared:  # the header's ceiling: the parameter holds the count
        frames = int(declared[0]) & 0xFFFF if isinstance(declared[0], int) else int(declared[0])
    if frames <= 0:
        raise InputError(f"{path}: the header's frames {first}-{last} hold no frame")
    floats = scale < 0
    width = 4 if floats else 2
    per_frame = (4 * n_points + analog) * width
    start = (max(data_block, 1) - 1) * 512
    have = (len(data) - start) // per_frame if per_frame else 0
    if have < frames:
        raise InputError(
            f"{path}: truncated C3D file: its header gives frames {first}-{last} ({frames}), "
            f"only {max(have, 0)} are in the file"
        )
    block = np.frombuffer(
        data,
        dtype=np.dtype(f"{r.order}{'f4' if floats else 'i2'}"),
        count=frames * per_frame // width,
        offset=start,
    ).reshape(frames, -1)
    if r.processor == 85 and floats:
        raw = np.frombuffer(data, dtype="<u2", count=block.size * 2, offset=start)
        block = raw.reshape(-1, 2)[:, ::-1].copy().view("<f4").reshape(frames, -1) / 4.0
    pts = block[:, : 4 * n_points].reshape(frames, n_points, 4).astype(np.float64)
    xyz = pts[..., :3] * (1.0 if floats else abs(scale))
    invalid = pts[..., 3] < 0
    xyz[invalid] = np.nan
    xyz[np.all(xyz == 0.0, axis=2)] = np.nan
    units = params.get(("POINT", "UNITS"))
    unit = str(units[0]).strip() if units and str(units[0]).strip() else None
    return C3dContents(
        labels=labels[:n_points],
        points=xyz,
        fps=rate if rate > 0 else None,
        units=unit,
        first_frame=first,
        defects=defects,
    )
