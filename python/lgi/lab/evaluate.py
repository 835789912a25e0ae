"""The protocols of `lgi evaluate`: LGI and the peers (`lgi.lab.methods`) scored
(`lgi.lab.scoring`) against ground truth on the capture protocol (real motion on a dataset with a
hinged jaw, shapes held out), the scans protocol (whole-face scans of the performer), the real
takes' leave-markers-out protocol and the built-in sample's, with `run_protocol` choosing one."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi._lgi import SolveResult
from lgi.data.dataset import Dataset
from lgi.errors import InputError
from lgi.lab.capture import (
    CaptureTake,
    HingeJaw,
    NonlinearTruth,
    departure,
    make_capture,
)
from lgi.lab.methods import (
    AS_RECOMMENDED,
    AsRecommended,
    Recommended,
    add_as_recommended,
    add_denoised,
    add_unbounded,
    capture_methods,
    default_methods,
)
from lgi.lab.scoring import (
    Solver,
    dropout_sweep,
    evaluate,
    leave_one_out,
    noise_sweep,
    score,
    steps,
    to_csv,
    to_markdown,
    verification,
    without,
)

F64 = NDArray[np.float64]
Row = dict[str, Any]

__all__ = ["capture", "capture_protocol", "lomo_protocol", "run_protocol", "scans_protocol"]


def performance_take(
    dataset: Dataset,
    curves: F64,
    markers: ArrayLike,
    *,
    frames: int,
    sigma: float,
    dropout: float,
    holdout: float,
    seed: int,
    hinge: HingeJaw,
    truth: NonlinearTruth | None,
    region: ArrayLike | None,
) -> tuple[CaptureTake, float]:
    """A protocol's performance: `curves` (F, S) subsampled to about `frames` frames, made
    into a capture take (`make_capture`: the hinge's linear rig, or `truth`), and how far its
    truth is from the linear rig (`departure`; NaN for the linear rig itself)."""
    w = curves[:: max(1, curves.shape[0] // max(1, frames))]
    take = make_capture(
        dataset,
        w,
        markers,
        sigma=sigma,
        dropout=dropout,
        holdout=holdout,
        seed=seed,
        jaw=hinge,
        nonlinear=truth,
    )
    apart = float("nan") if truth is None else departure(take.truth, truth.linear(w), region)
    return take, apart


def capture_protocol(
    dataset: Dataset,
    markers: ArrayLike,
    recordings: Sequence[str | os.PathLike[str]],
    *,
    sigma: float,
    holdout: float,
    jaw_rigid: ArrayLike,
    region: ArrayLike | None = None,
    frames: int = 200,
    dropout: float = 0.02,
    seed: int = 3,
    panel: str | os.PathLike[str] | None = None,
    nonlinear: bool = False,
    quiet: bool = True,
    only: Sequence[str] | None = None,
) -> list[Row]:
    """The capture protocol: each Live Link Face recording (`lgi.io.livelink.read_livelinkface`,
    subsampled to about `frames` frames) drives `dataset`, its jaw-open shape turning about the
    hinge fitted to the `jaw_rigid` vertices (`lgi.lab.capture.HingeJaw`); markers carry noise
    `sigma` and `dropout`; a `holdout` fraction of the shapes is kept from the methods
    (`lgi.lab.capture.make_capture`). Rows per recording and method ("recording: method"). With
    `panel`, the first recording's most expressive frame as a heatmap panel (`error_panel`);
    with `nonlinear`, the truth is `lgi.lab.capture.NonlinearTruth`'s (rows then say how far
    it is from the linear rig: `truth_departure`); a progress bar over the recordings unless
    `quiet`. `only`: the methods run, by name (None: all)."""
    from lgi.io.livelink import read_livelinkface

    hinge = HingeJaw.fit(dataset, jaw_rigid)
    truth = NonlinearTruth(dataset) if nonlinear else None
    rows: list[Row] = []
    for i, rec in enumerate(steps(list(recordings), "lgi evaluate: capture", quiet)):
        take, apart = performance_take(
            dataset,
            read_livelinkface(rec).for_dataset(dataset.names),
            markers,
            frames=frames,
            sigma=sigma,
            dropout=dropout,
            holdout=holdout,
            seed=seed,
            hinge=hinge,
            truth=truth,
            region=region,
        )
        methods = capture_methods(take.dataset, markers, sigma)
        add_denoised(methods, unbounded=False)
        add_as_recommended(methods)
        if only is not None:
            methods = {k: v for k, v in methods.items() if k in only}
        if panel is not None and i == 0:
            f = _most_expressive(take.truth, np.asarray(dataset.neutral))
            error_panel(panel, methods, take.frames[f], take.truth[f], dataset.triangles, region)
        for row in capture(methods, take.frames, take.truth, take.jaw_open, region):
            row["method"] = f"{Path(rec).stem}: {row['method']}"
            row["truth_departure"] = apart
            rows.append(row)
    return rows


def scans_protocol(
    dataset: Dataset,
    markers: ArrayLike,
    recordings: Sequence[str | os.PathLike[str]],
    *,
    scans: int,
    sigma: float,
    jaw_rigid: ArrayLike,
    region: ArrayLike | None = None,
    frames: int = 200,
    dropout: float = 0.02,
    seed: int = 3,
    nonlinear: bool = False,
    quiet: bool = True,
    only: Sequence[str] | None = None,
) -> list[Row]:
    """The whole-face-scans protocol (`lgi.lab.scans`): for each Live Link Face recording as
    the performance, `scans` scans picked from the other recordings' curves and made by the
    capture truth rig on `dataset` (the jaw turning about the hinge fitted to `jaw_rigid`)
    are the methods' dataset, with the dataset's jaw rig and each scan's pose; the
    performance (about `frames` frames) is a capture take of `dataset` with noise `sigma`
    and `dropout` (`lgi.lab.capture.make_capture`). Rows per performance and method
    ("performance: method", `CAPTURE_COLUMNS`) plus `bundles_fit`, the share of LGI's bundles
    that took the global fit. With `nonlinear`, the scans and the performance are
    `lgi.lab.capture.NonlinearTruth`'s meshes (`truth_departure`: the performance's mean
    distance from the linear rig). `only`: the methods run, by name (None: all)."""
    from lgi.io.livelink import read_livelinkface
    from lgi.lab.scans import scan_session
    from lgi.solve.jaw import auto_rig

    if len(recordings) < 2:
        raise InputError("the scans protocol needs two recordings: scans from one, a performance")
    hinge = HingeJaw.fit(dataset, jaw_rigid)
    rig, theta = auto_rig(dataset)
    truth = NonlinearTruth(dataset) if nonlinear else None
    curves = [read_livelinkface(r).for_dataset(dataset.names) for r in recordings]
    shares: dict[str, float] = {}

    def bundles_fit(name: str, res: SolveResult) -> None:
        """The share of a method's bundles that took the global fit (LGI's only)."""
        if res.choices.fit is not None:
            shares[name] = float(np.mean(res.choices.fit))

    rows: list[Row] = []
    for i, rec in enumerate(steps(list(recordings), "lgi evaluate: scans", quiet)):
        source = np.concatenate([c for k, c in enumerate(curves) if k != i])
        count = min(scans, source.shape[0])
        session = scan_session(dataset, source, count, hinge, theta, nonlinear=truth)
        take, apart = performance_take(
            dataset,
            curves[i],
            markers,
            frames=frames,
            sigma=sigma,
            dropout=dropout,
            holdout=0.0,
            seed=seed,
            hinge=hinge,
            truth=truth,
            region=region,
        )
        given = None if rig is None or session.theta is None else (rig, session.theta)
        methods = capture_methods(session.dataset, markers, sigma, jaw=given)
        add_unbounded(methods)
        add_denoised(methods, unbounded=True)
        add_as_recommended(methods)
        if only is not None:
            methods = {k: v for k, v in methods.items() if k in only}
        shares.clear()
        got = capture(methods, take.frames, take.truth, take.jaw_open, region, bundles_fit)
        share = shares.get("LGI", float("nan"))
        for row in got:
            row["bundles_fit"] = share if row["method"] == "LGI" else float("nan")
            row["method"] = f"{Path(rec).stem}: {row['method']}"
            row["scans"] = session.dataset.num_shapes
            row["truth_departure"] = apart
            rows.append(row)
    return rows


def lomo_protocol(
    dataset: Dataset,
    takes: Sequence[str | os.PathLike[str]],
    landmarks: ArrayLike,
    face: ArrayLike,
    *,
    frames: int = 250,
    held_out: int = 8,
    quiet: bool = True,
) -> tuple[list[Row], list[Row]]:
    """Leave-one-marker-out on real takes (`lgi.lab.lomo`): each TRC/C3D take with AnimFace's
    labels is retargeted onto `dataset` (`landmarks`: the 68 iBUG vertices; `face`: the
    triangles a marker may lie on), and `held_out` of its non-skull markers are left out one at
    a time; the methods are the capture protocol's (LGI's noise estimated from the whole take
    at its capture rate, as `--marker-noise auto` does), the neutral, and LGI with the detail
    weight the frames it solves call for (`--detail-weight auto`), each solving about
    `frames` evenly spaced frames.
    Returns the rows ("take: method", `lomo.LOMO_COLUMNS`, then "all takes: method" over
    every held-out marker) and one row per take and held-out marker (each method's mean)."""
    from lgi.io.takes import read_raw
    from lgi.lab import lomo

    lm = np.asarray(landmarks, dtype=np.int64)
    marks = {name: int(lm[k]) for name, k in lomo.ANIMFACE_IBUG.items()}

    def methods_for(ds: Dataset, rest: F64, fr: F64) -> dict[str, Any]:
        methods: dict[str, Any] = {
            lomo.Rest.label: lomo.Rest(ds),
            **capture_methods(ds, rest, None, fr),
        }
        lgi = methods["LGI"]
        methods["LGI + detail weight"] = Recommended(lgi.model, lgi.marker_noise, detail="auto")
        methods[AS_RECOMMENDED] = AsRecommended(lgi.model, fr, step)
        return methods

    rows: list[Row] = []
    markers: list[Row] = []
    measured: list[lomo.Scores] = []
    for path in steps(list(takes), "lgi evaluate: lomo", quiet):
        take = lomo.retarget(read_raw(path), dataset.neutral, face, marks)
        step = max(1, take.frames.shape[0] // max(1, frames))
        rigid = set(lomo.RIGID)
        cand = [i for i, n in enumerate(take.names) if n not in rigid]
        picked = lomo.held_out_markers(take.rest, take.frames, cand, held_out)
        got = lomo.lomo(dataset, take, picked, methods_for, step=step)
        measured.append(got)
        stem = Path(path).stem
        rows += lomo.rows([got], stem)
        for j in picked:
            name = take.names[j]
            means = {m: float(e[name].mean()) for m, e in got.errors.items()}
            markers.append({"take": stem, "marker": name, **means})
    if len(measured) > 1:
        rows += lomo.rows(measured, "all takes")
    return rows, markers


def error_panel(
    path: str | os.PathLike[str],
    methods: Mapping[str, Solver],
    frame: ArrayLike,
    truth: ArrayLike,
    triangles: ArrayLike,
    region: ArrayLike | None = None,
) -> None:
    """Writes the heatmap panel (`lgi.lab.render.panel`) of one frame: the truth, then each
    method's per-vertex error (cm) on one colour scale; vertices outside `region` are drawn
    with error 0."""
    from lgi.lab import render

    fr = np.asarray(frame, dtype=np.float64)[None]
    tr = np.asarray(truth, dtype=np.float64)
    keep = np.zeros(tr.shape[0], dtype=bool)
    keep[slice(None) if region is None else np.asarray(region)] = True
    meshes: dict[str, ArrayLike] = {"ground truth": tr}
    errors: dict[str, ArrayLike] = {}
    for name, m in methods.items():
        v = np.asarray(m.solve(fr, temporal=False, quiet=True).vertices)[0]
        meshes[name] = v
        errors[name] = np.where(keep, np.linalg.norm(v - tr, axis=1), 0.0)
    render.panel(path, meshes, triangles, errors, units="cm")


def _most_expressive(truth: F64, neutral: F64) -> int:
    """The frame that moves furthest from the neutral on average."""
    return int(np.argmax(np.linalg.norm(truth - neutral[None], axis=2).mean(axis=1)))


def run_protocol(
    data: str,
    protocol: str,
    out: str | os.PathLike[str],
    ict_dir: str | os.PathLike[str] | None,
    *,
    sigma: float = 0.05,
    holdout: float = 0.0,
    takes: Sequence[str | os.PathLike[str]] = (),
    frames_per_take: int | None = None,
    held_out: int = 8,
    scans: int = 120,
    nonlinear: bool = False,
    quiet: bool = False,
) -> list[Row]:
    """Runs `protocol` on `data` ("sample", or "ict" read from the folder `ict_dir`) and writes
    results.md, results.csv and panel.png (the heatmap of one frame: the most expressive; for
    leave-one-out, the most displaced shape held out; none for lomo, which has no dense truth,
    and scans)
    into `out`. `sigma` and `holdout` are the capture protocol's (ICT with the Live Link Face
    recordings beside it); `takes` (default: the shared AnimFace takes) and `held_out` the lomo
    protocol's (`lomo_protocol`), `scans` (and `sigma`) the scans protocol's
    (`scans_protocol`); `frames_per_take` both's (None: 250 for lomo, 200 for scans);
    `nonlinear` the capture and scans protocols' truth (`lgi.lab.capture.NonlinearTruth`).
    Progress bars on stderr unless `quiet`."""
    from lgi.lab import ict
    from lgi.lab.sample import make_sample, sample_dataset

    outp = Path(out)
    outp.mkdir(parents=True, exist_ok=True)
    region: ArrayLike | None = None
    extra = ""
    if data == "sample":
        s = make_sample(0)
        ds = sample_dataset(s)
        markers: F64 = s.markers_rest
        perf: tuple[F64, F64] | None = (s.performance, s.truth)
    elif data == "ict":
        if ict_dir is None:
            raise InputError(
                f"ICT-FaceKit data not found: give its folder (--ict-dir) or set ${ict.ENV} "
                "to the folder above it"
            )
        ds = ict.load_dataset(ict_dir)
        markers = ict.load_markers(ict_dir)
        perf = None
        region = ict.skin()
    else:
        raise InputError(f"unknown data '{data}' (sample or ict)")
    if protocol == "capture":
        if data != "ict" or ict_dir is None:
            raise InputError("the capture protocol needs --data ict")
        recordings = ict.livelinkface(Path(ict_dir).parent)
        if not recordings:
            raise InputError(
                f"the capture protocol needs Live Link Face recordings in "
                f"{Path(ict_dir).parent / 'livelinkface'}"
            )
        rows = capture_protocol(
            ds,
            markers,
            recordings,
            sigma=sigma,
            holdout=holdout,
            jaw_rigid=ict.lower_teeth(),
            region=region,
            panel=outp / "panel.png",
            nonlinear=nonlinear,
            quiet=quiet,
        )
    elif protocol == "scans":
        if data != "ict" or ict_dir is None:
            raise InputError("the scans protocol needs --data ict")
        recordings = ict.livelinkface(Path(ict_dir).parent)
        if len(recordings) < 2:
            raise InputError(
                f"the scans protocol needs two Live Link Face recordings in "
                f"{Path(ict_dir).parent / 'livelinkface'} (scans from one, the performance "
                f"from the other); found {len(recordings)}"
            )
        rows = scans_protocol(
            ds,
            markers,
            recordings,
            scans=scans,
            sigma=sigma,
            jaw_rigid=ict.lower_teeth(),
            region=region,
            frames=frames_per_take or 200,
            nonlinear=nonlinear,
            quiet=quiet,
        )
    elif protocol == "lomo":
        if data != "ict" or ict_dir is None:
            raise InputError("the lomo protocol needs --data ict (ICT-FaceKit and real takes)")
        found = ict.animface(Path(ict_dir).parent)
        chosen = list(takes) if takes else found
        if not chosen:
            raise InputError(
                f"the lomo protocol needs real takes: give them (--take) or put the AnimFace "
                f"takes in {Path(ict_dir).parent / 'animface'}"
            )
        rows, per_marker = lomo_protocol(
            ds,
            chosen,
            ict.load_landmarks(ict_dir),
            ict.face_triangles(ds),
            frames=frames_per_take or 250,
            held_out=held_out,
            quiet=quiet,
        )
        extra = "\n## Each held-out marker: mean error per method\n\n" + to_markdown(per_marker)
    elif protocol == "loo":
        rows = leave_one_out(ds, markers, default_methods, region=region, quiet=quiet)
        frames, truth = verification(ds, markers)
        k = _most_expressive(truth, np.asarray(ds.neutral))
        error_panel(
            outp / "panel.png",
            default_methods(without(ds, k), markers),
            frames[k],
            truth[k],
            ds.triangles,
            region,
        )
    else:
        methods = default_methods(ds, markers)
        if protocol == "performance":
            if perf is None:
                raise InputError("the performance protocol needs --data sample")
            frames, truth = perf
            temporal = True
        elif protocol in ("verification", "noise", "dropout"):
            frames, truth = (
                perf
                if (perf is not None and protocol != "verification")
                else (verification(ds, markers))
            )
            temporal = perf is not None and protocol != "verification"
        else:
            raise InputError(f"unknown protocol '{protocol}'")
        if protocol == "noise":
            rows = noise_sweep(methods, frames, truth, region=region, temporal=temporal)
        elif protocol == "dropout":
            rows = dropout_sweep(methods, frames, truth, region=region, temporal=temporal)
        else:
            rows = evaluate(methods, frames, truth, region, temporal=temporal, quiet=quiet)
        f = _most_expressive(np.asarray(truth), np.asarray(ds.neutral))
        error_panel(outp / "panel.png", methods, frames[f], truth[f], ds.triangles, region)
        if not temporal:
            for r in rows:
                r["jitter"] = float("nan")  # independent frames: not a sequence
    from lgi.io.atomic import write_text

    write_text(
        outp / "results.md",
        f"# lgi evaluate: data {data}, protocol {protocol}\n\n" + to_markdown(rows) + extra,
    )
    to_csv(rows, outp / "results.csv")
    return rows


CAPTURE_COLUMNS = [
    "method",
    "frames",
    "mean",
    "p95",
    "max",
    "open_mean",
    "open_p95",
    "pops_2mm",
    "pops_5mm",
    "ms_per_frame",
    "plan",
]
"""Row keys of the capture protocol: per-vertex error over all frames, and over the jaw-open
frames (`open_*`, NaN when the take has none), in data units; pops as `scoring.pops` counts
them on the frames solved."""


def capture(
    methods: Mapping[str, Solver],
    frames: ArrayLike,
    truth: ArrayLike,
    jaw_open: ArrayLike,
    region: ArrayLike | None = None,
    on_result: Callable[[str, SolveResult], None] | None = None,
) -> list[Row]:
    """Scores each method's solve of a capture take (`lgi.lab.capture.make_capture`): the `score`
    row (mean, p95 and max per-vertex error over `region`, residual, jitter, speed) plus the
    error on the `jaw_open` frames (F,) bool and, for `AsRecommended`, the plan it read
    (`SolvePlan.summary`; "" for the others) (`CAPTURE_COLUMNS`). `on_result(name, result)`,
    when given, sees each method's solve before it is let go (for what the rows do not hold)."""
    fr = np.asarray(frames, dtype=np.float64)
    tr = np.asarray(truth, dtype=np.float64)
    opened = np.asarray(jaw_open, dtype=bool)
    idx = slice(None) if region is None else np.asarray(region)
    rows: list[Row] = []
    for name, m in methods.items():
        t0 = time.perf_counter()
        # A protocol's performance is a take subsampled in time (`performance_take`): no
        # consecutive frames to fill gaps or steady detail over.
        res = m.solve(fr, temporal=True, steady=False, quiet=True)
        row = score(name, res, tr, time.perf_counter() - t0, region)
        if on_result is not None:
            on_result(name, res)
        err = np.linalg.norm(np.asarray(res.vertices)[opened][:, idx] - tr[opened][:, idx], axis=2)
        row["open_mean"] = float(err.mean()) if opened.any() else float("nan")
        row["open_p95"] = float(np.percentile(err, 95)) if opened.any() else float("nan")
        plan = m.last_plan if isinstance(m, AsRecommended) else None
        row["plan"] = "" if plan is None else plan.summary()
        rows.append(row)
    return rows
