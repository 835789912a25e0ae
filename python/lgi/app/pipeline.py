"""One pipeline of a take, for `lgi solve` and `lgi batch` alike: the take read for the model
(labels, units, its size against the model's layout), its solve planned (`lgi.plan_solve`: each
option as given or read from the take), solved, and written with the settings it was solved
with; the residuals written and the findings are always the given markers'. `solve_file` is
`lgi solve` (one take, optionally chunk by chunk, with its summary, report and curves);
`lgi.app.batch` runs `read_take`, `plan_take` and `write_solved` per shot."""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lgi._lgi import SolveResult
from lgi.app.files import (
    Say,
    _silent,
    existing_file,
    frame_range,
    frame_rate,
    not_an_input,
    output_kind,
    ready_output,
)
from lgi.app.write import _joined, _write_curves, _write_solve_report, write_solved
from lgi.errors import InputError
from lgi.io import takes
from lgi.io.frame import output_frame
from lgi.io.paths import output_file
from lgi.io.settings import SolveSettings
from lgi.io.sink import FrameSink
from lgi.io.topology import topology
from lgi.plan.choices import SolvePlan, plan_solve
from lgi.plan.denoise import DenoisedTake
from lgi.solve.diagnose import Finding, diagnose, face_size, summary
from lgi.solve.model import PROGRESS_DELAY, Model
from lgi.solve.options import JAW_MODES, SolveOptions
from lgi.solve.placement import ScaleFit, check_scale
from lgi.solve.repair import repaired
from lgi.solve.steady import PULL_SIGMAS

__all__ = [
    "JAW_POSES",
    "PlannedTake",
    "check_take_scale",
    "plan_take",
    "read_take",
    "solve_file",
    "solved_residuals",
]

JAW_POSES = (*JAW_MODES, "rest")
"""`lgi solve --jaw`: `Model.solve`'s jaw modes for models with a rig ("rest" = None)."""


def solved_residuals(res: SolveResult, given: np.ndarray, den: DenoisedTake | None) -> np.ndarray:
    """The residuals (F, B) a solve of the markers `given` writes and is read by: the result's
    own (a copy), or where the take was denoised first (`den`: other markers were solved), each
    given marker's distance from its position on the surface; 0 where it is missing."""
    if den is None:
        return np.array(res.bundle_residuals)
    d = np.linalg.norm(np.asarray(given, dtype=np.float64) - res.bundle_positions, axis=2)
    return np.where(np.isnan(d), 0.0, d)


def _say_summary(
    say: Say,
    residuals: np.ndarray,
    missing: np.ndarray,
    found: list[Finding],
    m: Model,
    start: int,
) -> None:
    """The solve's summary (`lgi.solve.diagnose.summary`): residuals, then the findings."""
    for line in summary(residuals, missing, m.marker_names, found, start=start, units=m.units):
        say(line)


def check_take_scale(
    t: takes.Take, frames: np.ndarray, m: Model, *, stated: bool
) -> ScaleFit | None:
    """`lgi.solve.placement.check_scale` of a take read for model `m` (its frames `frames`)."""
    return check_scale(
        frames,
        m.markers_rest,
        path=t.path,
        file_units=t.source_units,
        model_units=m.units,
        stated=stated,
    )


def read_take(
    path: str | os.PathLike[str],
    m: Model,
    *,
    take_units: str | None = None,
    allow_missing: bool = False,
) -> takes.Take:
    """The take file at `path` read for model `m` (`lgi.io.takes.read`: its labels matched to
    the model's markers, in the model's units)."""
    return takes.read(
        existing_file(os.fspath(path), "TAKE"),
        m.marker_names,
        units=m.units,
        take_units=take_units,
        allow_missing=allow_missing,
    )


@dataclass(frozen=True)
class PlannedTake:
    """A take's frames planned for a solve (`plan_take`): `given` (the markers as given: the
    residuals written and the findings are theirs), the `plan` (what is solved and how) and the
    `settings` its output records."""

    given: np.ndarray
    plan: SolvePlan
    settings: SolveSettings

    def residuals(self, res: SolveResult, rows: slice = slice(None)) -> np.ndarray:
        """The given markers' residuals of `res`, the solve of `rows` of the plan's frames."""
        return solved_residuals(res, self.given[rows], self.plan.denoised)

    def filled_by(self, res: SolveResult) -> PlannedTake:
        """This take with its settings saying how the solve `res` filled its dropouts."""
        settings = self.settings.with_fill(_filled_count(res) > 0, res.fill_rank)
        return PlannedTake(self.given, self.plan, settings)

    def findings(
        self, residuals: np.ndarray, missing: np.ndarray, first_frame: np.ndarray, m: Model
    ) -> list[Finding]:
        """What a solve of this take shows (`lgi.solve.diagnose`), read from its `residuals`
        (`PlannedTake.residuals`), `missing` samples and first solved frame as `lgi info` reads
        the file: against the given markers, with their noise."""
        return diagnose(
            residuals,
            missing,
            m.marker_names,
            size=face_size(first_frame),
            markers=self.given,
            noise=self.plan.given_noise,
        )


def plan_take(
    frames: np.ndarray, m: Model, options: SolveOptions, *, say: Say = _silent
) -> PlannedTake:
    """The plan of a solve of `frames` (the take as given) with model `m` and `options`
    (`lgi.plan_solve`; a model without a jaw rig solves at its rest pose)."""
    if m.jaw_rig is None and options.jaw is not None:
        options = options.replace(jaw=None)
    plan = plan_solve(frames, m, options, say=say)
    return PlannedTake(frames, plan, plan.settings(has_jaw_rig=m.jaw_rig is not None))


def solve_take(
    planned: PlannedTake,
    m: Model,
    options: SolveOptions,
    *,
    start: int = 0,
    quiet: bool = True,
    say: Say = _silent,
) -> tuple[PlannedTake, SolveResult, list[Finding] | None]:
    """The planned take solved; with `options.repair`, the marker faults that solve shows (label
    swaps, spikes, markers off their track: `PlannedTake.findings`, told from model gaps) are
    repaired (`lgi.solve.repair`), said in one line each, and the repaired take planned and
    solved again, its settings recording the repairs. The settings returned also say how the
    solve filled the take's dropouts. Returns what was solved, its result
    and, where they were read (a solve with repair that found no fault), that result's
    findings; None otherwise (the take given is never touched)."""
    # The pipeline repairs itself (against the given markers, the take planned again).
    res = m.solve(
        planned.plan.frames, quiet=quiet, options=planned.plan.options.replace(repair=False)
    )
    if not options.repair:
        return planned.filled_by(res), res, None
    found = planned.findings(planned.residuals(res), res.missing, res.vertices[0], m)
    faults = [f for f in found if f.fault]
    if not faults:
        return planned.filled_by(res), res, found
    x, _, done = repaired(planned.given, faults, m.marker_names)
    # Planned again: a fault read into the first plan's choices costs the repaired frames
    # accuracy (a repaired swap kept 1.17 x the clean error with the first plan's choices, 1.00 x
    # planned again: docs/journal/2026-12-07-recommended-cost.md).
    again = plan_take(x, m, options)
    settings = dataclasses.replace(again.settings, repairs=done)
    for line in settings.repair_lines(start):
        say(f"repaired: {line}")
    again = PlannedTake(again.given, again.plan, settings)
    say("solved again with the repaired markers (--no-repair keeps them as given)")
    kept = again.plan.options.replace(repair=False)
    res = m.solve(again.plan.frames, quiet=quiet, options=kept)
    return again.filled_by(res), res, None


def solve_file(
    model: str | os.PathLike[str],
    take: str | os.PathLike[str],
    out: str | os.PathLike[str],
    options: SolveOptions | None = None,
    *,
    frames: str | None = None,
    fps: float | None = None,
    allow_missing: bool = False,
    take_units: str | None = None,
    chunk: int | None = None,
    force: bool = False,
    report: str | os.PathLike[str] | None = None,
    curves: str | os.PathLike[str] | None = None,
    units: str | None = None,
    scale: float | None = None,
    up: str = "y",
    quiet: bool = False,
    say: Say = _silent,
) -> tuple[Path, int]:
    """`lgi solve`: the take file solved with the model file with `options` (built once from
    the command line, `SolveOptions.from_cli`; default: the paper's exact interpolation),
    written by `out`'s suffix (`output_kind`); `frames` is `--frames A:B`. The plan
    (`plan_take`) reads what `options` leave to the take; residuals and findings are the given
    markers'. By default the range is solved in one `Model.solve` (frames prefer their
    predecessor's choices across the whole range), then written chunk by chunk; `chunk`
    (`--chunk N`) solves and writes N frames at a time into one reused buffer, so the solve's
    memory stays that of N frames (each chunk continues from the last frame of the one before:
    the same frames as one solve, except with `--jaw track`, tracked chunk by chunk). Returns
    the path written (the `NAME.NNNN.obj` pattern for OBJ sequences) and the frame count.
    `options.repair` (default; `--no-repair` off): marker faults the solve shows are repaired
    and the take solved again (`solve_take`); with `chunk` they are named, not repaired
    (repairing needs the whole take's residuals)."""
    options = SolveOptions() if options is None else options
    if chunk is not None and (isinstance(chunk, bool) or int(chunk) < 1):
        raise InputError(f"--chunk {chunk}: must be a whole number of frames >= 1")
    not_an_input(output_file(os.fspath(out), "--out"), model, take)
    kind = output_kind(os.fspath(out))
    dest = ready_output(out, model, take, force=force)
    page = None
    if report is not None:
        if chunk is not None:
            raise InputError(
                "--report needs the whole take solved at once; without --chunk, or run "
                "lgi report on an .npz output"
            )
        if Path(report).suffix.lower() not in (".html", ".htm"):
            raise InputError(f"--report {report}: the report is an .html file")
        page = ready_output(report, model, take, out, force=force)
    curves_out = None
    if curves is not None:
        from lgi.io.curves import CURVE_SUFFIXES

        if Path(curves).suffix.lower() not in CURVE_SUFFIXES:
            raise InputError(
                f"--curves {curves}: use .usd/.usda/.usdc (UsdSkel) or .csv (Live Link Face)"
            )
        curves_out = ready_output(curves, model, take, out, force=force)
    m = Model.load(existing_file(os.fspath(model), "MODEL"))
    frame = output_frame(m.units, units=units, scale=scale, up=up)
    frame.check_writer(kind, f"--out {dest}")  # before the take is read
    t = read_take(take, m, take_units=take_units, allow_missing=allow_missing)
    if t.ignored:
        say(f"left out {len(t.ignored)} labels unknown to the model: {', '.join(t.ignored)}")
    rng = frame_range(frames, t.num_frames)
    x = t.frames[rng]
    check_take_scale(t, x, m, stated=take_units is not None)
    head = None if t.head is None else t.head[rng]
    rate = frame_rate(fps, t.fps, kind)
    planned = plan_take(x, m, options, say=say)
    plan, settings = planned.plan, planned.settings
    # What is solved: the given markers, or the take denoised with the noise it leaves. The
    # residuals written and the findings are always the given markers' (`given`).
    given = x
    x, sigma, weight = plan.frames, plan.marker_noise, plan.detail_weight
    missing = np.isnan(x).any(axis=2)
    say(
        f"{x.shape[0]} frames of {x.shape[1]} markers "
        f"({100 * missing.mean():.1f}% samples missing)"
        + ("" if sigma is None else f", marker noise {sigma:.4g}")
        + ("" if weight is None else f", detail weight {weight:.3f}")
        + settings.pieces()
    )
    topo = topology(m.dataset)
    start = t.first_frame + rng.start
    if chunk is None:
        planned, res, found = solve_take(planned, m, options, start=start, quiet=quiet, say=say)
        given, settings = planned.given, planned.settings
        if curves_out is not None:
            _write_curves(
                curves_out, res.fit_weights, res.jaw_theta, m, fps=rate, start=start, frame=frame
            )
            say(f"wrote the curves {curves_out}")
        given_residuals = planned.residuals(res)
        written = write_solved(
            kind,
            dest,
            topo,
            res,
            m,
            fps=rate,
            start=start,
            head=head,
            markers=given,
            frame=frame,
            quiet=quiet,
            settings=settings,
            residuals=given_residuals,
        )
        _say_fill(say, settings, _filled_count(res))
        _say_pulls(say, *_pulled(res), m.units)
        if found is None:
            found = planned.findings(given_residuals, res.missing, res.vertices[0], m)
        _say_summary(say, given_residuals, res.missing, found, m, start)
        if page is not None:
            _write_solve_report(
                page,
                res,
                m,
                topo,
                given,
                found,
                fps=rate,
                start=start,
                source=dest,
                settings=settings,
                residuals=given_residuals,
            )
            say(f"wrote the report {page}")
        return written, int(x.shape[0])
    from tqdm import tqdm

    n, size = int(x.shape[0]), int(chunk)
    sink = FrameSink(
        kind,
        dest,
        topo,
        names=m.marker_names,
        fps=rate,
        start=start,
        units=m.units,
        frame=frame,
        settings=settings,
    )
    buf = np.empty((min(size, n), m.num_vertices, 3))
    # Each chunk continues the temporal solve from the last frame of the one before
    # (`Model.solve_iter`): the chunks together are one `solve` of the range.
    chunks = m.solve_iter(x, chunk=size, quiet=True, out=buf, options=plan.options)
    residuals: list[np.ndarray] = []
    absent: list[np.ndarray] = []
    fits: list[np.ndarray | None] = []
    first_frame: np.ndarray | None = None
    jaws: list[np.ndarray | None] = []
    filled_count, fill_rank = 0, None
    pulled, farthest = 0, 0.0
    try:
        with tqdm(
            total=n,
            desc="lgi solve",
            unit="frame",
            disable=quiet,
            leave=False,
            delay=PROGRESS_DELAY,
        ) as bar:
            for a, res in zip(range(0, n, size), chunks, strict=True):
                b = min(n, a + size)
                if first_frame is None:
                    first_frame = res.vertices[0].copy()
                chunk_residuals = planned.residuals(res, slice(a, b))
                residuals.append(chunk_residuals)
                absent.append(res.missing.copy())
                fits.append(None if res.fit_weights is None else res.fit_weights.copy())
                jaws.append(None if res.jaw_theta is None else res.jaw_theta.copy())
                # Every chunk is filled by the whole take's motion (`Model.solve_iter`).
                filled_count += _filled_count(res)
                fill_rank = res.fill_rank if res.fill_rank is not None else fill_rank
                count, most = _pulled(res)
                pulled, farthest = pulled + count, max(farthest, most)
                sink.add(
                    res.vertices,
                    chunk_residuals,
                    res.missing,
                    res.jaw_theta,
                    None if head is None else head[a:b],
                    given[a:b],
                )
                bar.update(b - a)
        if curves_out is not None:
            weights = _joined(fits)
            jaw_all = _joined(jaws)
            _write_curves(curves_out, weights, jaw_all, m, fps=rate, start=start, frame=frame)
            say(f"wrote the curves {curves_out}")
        settings = settings.with_fill(filled_count > 0, fill_rank)
        written = sink.close(settings)
    except BaseException:
        sink.abort()
        raise
    assert first_frame is not None  # a take has at least one frame (takes.read)
    _say_fill(say, settings, filled_count)
    _say_pulls(say, pulled, farthest, m.units)
    all_residuals, all_absent = np.concatenate(residuals), np.concatenate(absent)
    found = planned.findings(all_residuals, all_absent, first_frame, m)
    _say_summary(say, all_residuals, all_absent, found, m, start)
    if options.repair and any(f.fault for f in found):
        say("not repaired with --chunk (repairing needs the whole take's residuals)")
    return written, n


def _filled_count(res: SolveResult) -> int:
    """How many missing samples the solve `res` filled from the take (`SolveResult.filled`)."""
    return 0 if res.filled is None else int(np.count_nonzero(res.filled))


def _say_fill(say: Say, settings: SolveSettings, count: int) -> None:
    """Says how many missing samples (`count`) the solve filled and how (`settings`), where it
    filled any."""
    words = settings.fill_words()
    if count and words is not None:
        say(f"{count} missing samples filled {words} before the solve")


def _pulled(res: SolveResult) -> tuple[int, float]:
    """How many marker samples the steady surface of `res` followed beyond their noise
    (`SolveResult.marker_pulls`), and the longest pull."""
    if res.marker_pulls is None:
        return 0, 0.0
    size = np.linalg.norm(np.asarray(res.marker_pulls), axis=2)
    return int(np.count_nonzero(size)), float(size.max(initial=0.0))


def _say_pulls(say: Say, count: int, farthest: float, units: str | None) -> None:
    """Says how many marker samples the surface followed beyond their noise, where any."""
    if count:
        unit = f" {units}" if units else ""
        say(
            f"the surface follows {count} marker samples beyond {PULL_SIGMAS:g} sigma of where "
            f"the solve put them (up to {farthest:.3g}{unit}): motion the dataset does not reach"
        )
