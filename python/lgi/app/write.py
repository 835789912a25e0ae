"""Solved frames to files: by `--out`'s kind, chunk by chunk with a progress bar
(`lgi.io.sink`), whole or not at all; `lgi solve --curves` and `--report` beside them."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lgi._lgi import SolveResult
from lgi.errors import InputError
from lgi.io import takes
from lgi.io.frame import OutputFrame
from lgi.io.result import Result
from lgi.io.settings import SolveSettings
from lgi.io.sink import FrameSink
from lgi.io.topology import Topology
from lgi.solve.diagnose import Finding
from lgi.solve.model import Model

CHUNK_FRAMES = 100
"""Frames written per chunk (one progress step)."""


def write_output(
    kind: str,
    out: Path,
    topo: Topology,
    vertices: np.ndarray,
    *,
    residuals: np.ndarray,
    missing: np.ndarray,
    names: list[str],
    fps: float | None,
    start: int,
    units: str | None,
    jaw_theta: np.ndarray | None,
    head: takes.HeadMotion | None = None,
    markers: np.ndarray | None = None,
    frame: OutputFrame | None = None,
    quiet: bool = False,
    settings: SolveSettings | None = None,
) -> Path:
    """Writes solved frames as `kind` (`output_kind`) to `out`, `CHUNK_FRAMES` at a time with
    a progress bar (the head transform, when known, beside them in a USD cache; the take's
    `markers` and the `settings` it was solved with in an npz, the settings in a USD cache);
    returns the path written (`NAME.NNNN.obj` for a sequence). Nothing is left at `out` if it
    fails or is interrupted."""
    from tqdm import tqdm

    sink = FrameSink(
        kind,
        out,
        topo,
        names=names,
        fps=fps,
        start=start,
        units=units,
        frame=frame,
        settings=settings,
    )
    n = vertices.shape[0]
    try:
        with tqdm(
            total=n, desc=f"lgi write {kind}", unit="frame", disable=quiet, leave=False
        ) as bar:
            for a in range(0, n, CHUNK_FRAMES):
                b = min(n, a + CHUNK_FRAMES)
                sink.add(
                    vertices[a:b],
                    residuals[a:b],
                    missing[a:b],
                    None if jaw_theta is None else jaw_theta[a:b],
                    None if head is None else head[a:b],
                    None if markers is None else markers[a:b],
                )
                bar.update(b - a)
        return sink.close()
    except BaseException:
        sink.abort()
        raise


def write_solved(
    kind: str,
    out: Path,
    topo: Topology,
    res: SolveResult,
    m: Model,
    *,
    fps: float | None,
    start: int,
    head: takes.HeadMotion | None = None,
    markers: np.ndarray | None = None,
    frame: OutputFrame | None = None,
    quiet: bool = False,
    settings: SolveSettings | None = None,
    residuals: np.ndarray | None = None,
) -> Path:
    """`write_output` of a whole `SolveResult` of model `m` (its marker names and unit);
    `residuals` in place of the result's (e.g. the given markers', `solved_residuals`)."""
    return write_output(
        kind,
        out,
        topo,
        res.vertices,
        residuals=res.bundle_residuals if residuals is None else residuals,
        missing=res.missing,
        names=m.marker_names,
        fps=fps,
        start=start,
        units=m.units,
        jaw_theta=res.jaw_theta,
        head=head,
        markers=markers,
        frame=frame,
        quiet=quiet,
        settings=settings,
    )


def _joined(parts: list[np.ndarray | None]) -> np.ndarray | None:
    """Chunks' arrays end to end; None if any chunk had none."""
    whole = [p for p in parts if p is not None]
    return np.concatenate(whole) if whole and len(whole) == len(parts) else None


def _write_curves(
    out: Path,
    fit: np.ndarray | None,
    jaw_theta: np.ndarray | None,
    m: Model,
    *,
    fps: float | None,
    start: int,
    frame: OutputFrame | None = None,
) -> None:
    """`lgi solve --curves`: the solve's global fit weights and jaw pose as curves (a USD rig
    in the output's frame)."""
    from lgi.io.curves import write_curves

    if fit is None:
        raise InputError(
            "--curves: this solve made no global fit (a model built with fit off, or without "
            "shapes), so there are no curves to write"
        )
    write_curves(
        out, m.dataset, fit, fps=fps, start=start, units=m.units, jaw_theta=jaw_theta, frame=frame
    )


def _write_solve_report(
    page: Path,
    res: SolveResult,
    m: Model,
    topo: Topology,
    markers: np.ndarray,
    found: list[Finding],
    *,
    fps: float | None,
    start: int,
    source: Path,
    settings: SolveSettings | None = None,
    residuals: np.ndarray | None = None,
) -> None:
    """`lgi solve --report`: `lgi report`'s page of the solve just made, from memory, with
    the findings the summary printed and the settings it was solved with (`residuals` as
    `write_solved`'s)."""
    from lgi.io.atomic import atomic_path
    from lgi.review.report import render_report

    solved = Result(
        vertices=np.asarray(res.vertices, dtype=np.float32),
        bundle_residuals=res.bundle_residuals if residuals is None else residuals,
        missing=res.missing,
        marker_names=list(m.marker_names),
        fps=fps,
        start=start,
        units=m.units,
        topology=topo,
        jaw_theta=res.jaw_theta,
        markers=np.asarray(markers, dtype=np.float32),
        settings=settings,
    )
    lines = [f.describe(start, m.units) for f in found]
    with atomic_path(page) as tmp:
        tmp.write_text(render_report(solved, source=str(source), findings=lines), encoding="utf-8")
