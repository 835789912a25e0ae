"""Point caches the DCCs read natively: PC2 (Blender's Mesh Cache modifier, 3ds Max, Houdini)
and MDD (LightWave's, read by the same), written chunk by chunk and whole or not at all.

PC2, little-endian (the layout Blender's `io_export_pc2` and Mesh Cache modifier use): the
12 bytes `POINTCACHE2\\0`, int32 version 1, int32 point count, float32 start frame, float32
sample rate (frames per sample: 1), int32 sample count, then per sample the points as float32
x, y, z. MDD, big-endian (LightWave's layout, Blender's `io_shape_mdd`): int32 frame count,
int32 point count, float32 time of each frame in seconds, then per frame the points as float32
x, y, z. PC2 keeps the first frame number; MDD has no such field, so its times are the time
codes over the rate (frame `start` at `start / fps` s). Neither has units: the points are in
the model's unit."""

from __future__ import annotations

import os
import shutil
import struct
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from lgi.errors import FileWriteError, InputError
from lgi.io.atomic import temporary_beside

__all__ = ["POINT_CACHE_SUFFIXES", "PointCache"]

POINT_CACHE_SUFFIXES = {".pc2": "pc2", ".mdd": "mdd"}
"""Output suffixes of the point caches and their kinds."""

_PC2_HEADER = struct.Struct("<12siiffi")


class PointCache:
    """A PC2 or MDD cache of `num_points` points: `add` frames (F, V, 3), `close` renames the
    complete file onto `path`; `discard` drops it (a failure, Ctrl-C)."""

    def __init__(
        self, path: str | os.PathLike[str], num_points: int, *, fps: float | None, start: int
    ) -> None:
        self.path = Path(path)
        kind = POINT_CACHE_SUFFIXES.get(self.path.suffix.lower())
        if kind is None:
            raise InputError(f"point cache {self.path}: the suffix must be .pc2 or .mdd")
        if kind == "mdd" and fps is None:
            raise InputError(f"MDD output {self.path}: its frame times need a rate (--fps)")
        self.kind, self.num_points, self.fps, self.start = kind, int(num_points), fps, int(start)
        self.frames = 0
        self._tmp = temporary_beside(self.path)
        # MDD's header holds every frame's time before the points: they go to a second
        # temporary and are copied behind the header at `close`.
        self._body = temporary_beside(self.path) if kind == "mdd" else self._tmp
        try:
            self._fh: BinaryIO = open(self._body, "wb")
            if kind == "pc2":
                self._fh.write(_PC2_HEADER.pack(b"POINTCACHE2\0", 1, self.num_points, 0.0, 1.0, 0))
        except OSError as e:
            self.discard()
            raise FileWriteError(f"cannot write {self.path}: {e.strerror}") from None

    def add(self, vertices: Any) -> None:
        v = np.asarray(vertices)
        if v.ndim == 2:
            v = v[None]
        if v.ndim != 3 or v.shape[1:] != (self.num_points, 3):
            self.discard()
            raise InputError(
                f"point cache {self.path}: frames must be (F, {self.num_points}, 3), got {v.shape}"
            )
        dtype = "<f4" if self.kind == "pc2" else ">f4"
        try:
            self._fh.write(np.ascontiguousarray(v, dtype=dtype).tobytes())
        except OSError as e:
            self.discard()
            raise FileWriteError(f"cannot write {self.path}: {e.strerror}") from None
        self.frames += v.shape[0]

    def close(self) -> Path:
        if self.frames == 0:
            self.discard()
            raise InputError(f"point cache {self.path}: no frames were added")
        try:
            if self.kind == "pc2":
                self._fh.seek(0)
                self._fh.write(
                    _PC2_HEADER.pack(
                        b"POINTCACHE2\0", 1, self.num_points, float(self.start), 1.0, self.frames
                    )
                )
                self._fh.flush()
                os.fsync(self._fh.fileno())
                self._fh.close()
            else:
                self._fh.close()
                assert self.fps is not None
                times = (self.start + np.arange(self.frames)) / self.fps
                with open(self._tmp, "wb") as out, open(self._body, "rb") as body:
                    out.write(struct.pack(">ii", self.frames, self.num_points))
                    out.write(times.astype(">f4").tobytes())
                    shutil.copyfileobj(body, out, 1 << 22)
                    out.flush()
                    os.fsync(out.fileno())
                self._body.unlink(missing_ok=True)
            os.replace(self._tmp, self.path)
        except OSError as e:
            self.discard()
            raise FileWriteError(f"cannot write {self.path}: {e.strerror}") from None
        return self.path

    def discard(self) -> None:
        fh = getattr(self, "_fh", None)
        if fh is not None and not fh.closed:
            fh.close()
        self._tmp.unlink(missing_ok=True)
        self._body.unlink(missing_ok=True)
