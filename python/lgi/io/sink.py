"""Solved frames out by kind, chunk after chunk (`FrameSink`): the one place that turns
frames into a USD point cache, an OBJ sequence or a solved-take `.npz`, for `lgi solve`,
`lgi export` and `lgi batch`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lgi.errors import InputError
from lgi.io.atomic import discard_staging, replace_sequence, sequence_staging
from lgi.io.frame import OutputFrame
from lgi.io.obj import write_obj_sequence
from lgi.io.pointcache import PointCache
from lgi.io.result import write_result_npz
from lgi.io.settings import SolveSettings
from lgi.io.takes import HeadMotion
from lgi.io.topology import Topology
from lgi.io.usd import UsdCache

__all__ = ["FrameSink"]


class FrameSink:
    """Where solved frames go, chunk after chunk: a USD cache (`UsdCache`), OBJ files, or
    float32 copies gathered for one solved-take `.npz` (written at `close`). `kind` is
    "usd", "obj" or "npz"; `close` returns the path written (`NAME.NNNN.obj` for a
    sequence). Nothing appears at the output until `close`: the USD cache is saved under a
    temporary name and renamed, the OBJ frames are gathered in a hidden folder beside the
    sequence and moved in (replacing an older sequence of the same name, never mixing with
    it), the npz is written whole; `abort` drops everything (a failure, Ctrl-C)."""

    def __init__(
        self,
        kind: str,
        out: Path,
        topo: Topology,
        *,
        names: list[str],
        fps: float | None,
        start: int,
        units: str | None,
        frame: OutputFrame | None = None,
        settings: SolveSettings | None = None,
    ) -> None:
        if frame is not None:
            frame.check_writer(kind, f"--out {out}")
        self.frame = frame if frame is not None and not frame.identity else None
        if self.frame is not None:
            units = self.frame.units
        self.kind, self.out, self.topo, self.names = kind, out, topo, names
        self.fps, self.start, self.units = fps, start, units
        self.settings = settings
        self.next = start
        self.usd: UsdCache | None = None
        self.cache: PointCache | None = None
        self.staging: Path | None = None
        if kind in ("pc2", "mdd"):
            self.cache = PointCache(out, topo.num_vertices, fps=fps, start=start)
        if kind == "obj":
            self.staging = sequence_staging(out.parent, out.stem)
        if kind == "usd":
            if fps is None:
                raise InputError("a USD point cache needs a frame rate (--fps)")
            up = "y" if self.frame is None else self.frame.up
            self.usd = UsdCache(
                out,
                topo,
                fps=fps,
                units=units,
                start=start,
                up=up,
                marker_names=names,
                settings=settings,
            )
        self.parts: list[
            tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]
        ] = []

    def add(
        self,
        vertices: np.ndarray,
        residuals: np.ndarray,
        missing: np.ndarray,
        jaw_theta: np.ndarray | None,
        head: HeadMotion | None = None,
        markers: np.ndarray | None = None,
    ) -> None:
        if self.frame is not None:
            vertices = self.frame.points(vertices)
            residuals = self.frame.lengths(residuals)
            if jaw_theta is not None:  # open and lateral are angles; forward is a length
                jaw_theta = np.asarray(jaw_theta, dtype=np.float64).copy()
                jaw_theta[:, 2] *= self.frame.scale
            if head is not None:
                head = HeadMotion(
                    self.frame.rotations(head.rotations), self.frame.points(head.translations)
                )
        if self.usd is not None:
            self.usd.add(
                vertices,
                jaw_theta=jaw_theta,
                marker_residuals=residuals,
                head_rotations=None if head is None else head.rotations,
                head_translations=None if head is None else head.translations,
            )
        elif self.cache is not None:
            self.cache.add(vertices)
        elif self.staging is not None:
            write_obj_sequence(
                self.staging, self.topo, vertices, name=self.out.stem, start=self.next
            )
        else:
            self.parts.append((vertices.astype(np.float32), residuals, missing, jaw_theta, markers))
        self.next += int(vertices.shape[0])

    def close(self, settings: SolveSettings | None = None) -> Path:
        """The output finished and in place; `settings`, where given, replace the ones the sink
        was opened with (what a solve learns as it goes: how its dropouts were filled)."""
        if settings is not None:
            self.settings = settings
            if self.usd is not None:
                self.usd.record(settings)
        if self.usd is not None:
            return self.usd.close()
        if self.cache is not None:
            return self.cache.close()
        if self.staging is not None:
            replace_sequence(self.staging, self.out.parent, self.out.stem)
            self.staging = None
            return self.out.parent / f"{self.out.stem}.NNNN.obj"
        jaws = [p[3] for p in self.parts if p[3] is not None]
        marks = [p[4] for p in self.parts if p[4] is not None]
        return write_result_npz(
            self.out,
            self.topo,
            [p[0] for p in self.parts],
            np.concatenate([p[1] for p in self.parts]),
            np.concatenate([p[2] for p in self.parts]),
            self.names,
            fps=self.fps,
            start=self.start,
            units=self.units,
            jaw_theta=np.concatenate(jaws) if len(jaws) == len(self.parts) else None,
            markers=np.concatenate(marks) if len(marks) == len(self.parts) else None,
            settings=self.settings,
        )

    def abort(self) -> None:
        """Drops what was added: nothing is left at the output or beside it."""
        if self.usd is not None:
            self.usd.discard()
        if self.cache is not None:
            self.cache.discard()
        if self.staging is not None:
            discard_staging(self.staging)
            self.staging = None
        self.parts.clear()
