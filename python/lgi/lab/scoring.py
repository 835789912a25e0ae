"""How a method is scored against ground truth: per-vertex error statistics, bundle residuals,
temporal jitter and speed (`score`), the sweeps of the paper's comparisons (verification on the
dataset's own shapes, leave-one-shape-out, noise, dropouts) and the tables they print."""

from __future__ import annotations

import csv
import os
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi._lgi import SolveResult
from lgi.data.dataset import Dataset, without_shapes
from lgi.lab.capture import (
    box_diagonal,
    marker_samples,
)

F64 = NDArray[np.float64]
Row = dict[str, Any]


COLUMNS = [
    "method",
    "frames",
    "mean",
    "p95",
    "max",
    "max_residual_rel",
    "jitter",
    "pops_2mm",
    "pops_5mm",
    "ms_per_frame",
]
"""Row keys: errors (mean, p95, max of per-vertex distances) and jitter (mean norm of the second
difference of vertex positions over time) are in data units; the bundle residual is relative to
the bounding-box diagonal; pops are frames where some vertex's error jumps (`pops`)."""

POP_CM = (0.2, 0.5)
"""A pop: a frame where some vertex's error jumps by more than this in one frame (2 and 5 mm;
the lab's data are in cm). An animator sees a pop before any mean error."""


def pops(err: F64, limit: float) -> int:
    """Frames of a sequence's per-vertex errors `err` (F, V) where some vertex's error jumps by
    more than `limit`: its second difference in time, |e(t+1) - 2 e(t) + e(t-1)|, a one-frame
    excursion (a steady drift is no pop)."""
    if err.shape[0] < 3:
        return 0
    jump = np.abs(err[2:] - 2.0 * err[1:-1] + err[:-2]).max(axis=1)
    return int((jump > limit).sum())


class Solver(Protocol):
    def solve(
        self, frames: ArrayLike, *, temporal: bool = ..., steady: bool = ..., quiet: bool = ...
    ) -> Any: ...


def score(
    name: str,
    result: SolveResult,
    truth: F64,
    seconds: float,
    region: ArrayLike | None = None,
    diagonal: float | None = None,
) -> Row:
    """One row for a solved sequence against `truth` (F, V, 3)."""
    verts = np.asarray(result.vertices)
    idx = slice(None) if region is None else np.asarray(region)
    err = np.linalg.norm(verts[:, idx] - truth[:, idx], axis=2)
    diag = diagonal if diagonal is not None else box_diagonal(truth[0])
    nf = verts.shape[0]
    jitter = (
        float(np.linalg.norm(np.diff(verts[:, idx], n=2, axis=0), axis=2).mean())
        if nf >= 3
        else float("nan")
    )
    return {
        "method": name,
        "frames": nf,
        "mean": float(err.mean()),
        "p95": float(np.percentile(err, 95)),
        "max": float(err.max()),
        "max_residual_rel": float(np.max(result.bundle_residuals)) / diag,
        "jitter": jitter,
        "pops_2mm": pops(err, POP_CM[0]),
        "pops_5mm": pops(err, POP_CM[1]),
        "ms_per_frame": 1e3 * seconds / max(nf, 1),
    }


def evaluate(
    methods: Mapping[str, Solver],
    frames: ArrayLike,
    truth: ArrayLike,
    region: ArrayLike | None = None,
    diagonal: float | None = None,
    temporal: bool = True,
    quiet: bool = True,
) -> list[Row]:
    """Solves `frames` (F, B, 3) with every method and scores it against `truth` (F, V, 3) on
    the vertices `region` (default all; ICT: the face skin, `lgi.lab.ict.skin()`); a progress bar
    over the methods unless `quiet`."""
    fr = np.asarray(frames, dtype=np.float64)
    tr = np.asarray(truth, dtype=np.float64)
    rows = []
    for name, m in steps(list(methods.items()), "lgi evaluate", quiet):
        t0 = time.perf_counter()
        res = m.solve(fr, temporal=temporal, quiet=True)
        rows.append(score(name, res, tr, time.perf_counter() - t0, region, diagonal))
    return rows


def verification(dataset: Dataset, markers: ArrayLike) -> tuple[F64, F64]:
    """Frames (S, B, 3): the markers on each dataset shape, and the shapes (S, V, 3) as truth."""
    truth = np.asarray(dataset.neutral)[None] + np.asarray(dataset.shapes, dtype=np.float64)
    return marker_samples(dataset, markers, truth), truth


def without(dataset: Dataset, k: int) -> Dataset:
    return without_shapes(dataset, [k])


def leave_one_out(
    dataset: Dataset,
    markers: ArrayLike,
    method_factory: Callable[[Dataset, ArrayLike], Mapping[str, Solver]],
    shapes: Sequence[int] | None = None,
    region: ArrayLike | None = None,
    quiet: bool = True,
) -> list[Row]:
    """For each shape k: methods built without k solve the markers on shape k; the rows pool
    all held-out shapes (build time not counted; jitter is not meaningful and is NaN); a
    progress bar over the shapes unless `quiet`."""
    frames, truth = verification(dataset, markers)
    ks = list(range(dataset.num_shapes)) if shapes is None else list(shapes)
    verts: dict[str, list[F64]] = {}
    res_max: dict[str, float] = {}
    secs: dict[str, float] = {}
    for k in steps(ks, "lgi evaluate: leave one out", quiet):
        methods = method_factory(without(dataset, k), markers)
        for name, m in methods.items():
            t0 = time.perf_counter()
            r = m.solve(frames[k : k + 1], temporal=False, quiet=True)
            secs[name] = secs.get(name, 0.0) + time.perf_counter() - t0
            verts.setdefault(name, []).append(np.asarray(r.vertices)[0])
            res_max[name] = max(res_max.get(name, 0.0), float(np.max(r.bundle_residuals)))
    rows = []
    diag = box_diagonal(np.asarray(dataset.neutral))
    for name, vs in verts.items():
        fake = SolveResult(
            vertices=np.stack(vs),
            bundle_residuals=np.array([[res_max[name]]]),
            bundle_positions=np.zeros((0, 0, 3)),
            missing=np.zeros((0, 0), dtype=bool),
            choices=None,  # type: ignore[arg-type]
        )
        row = score(name, fake, truth[ks], secs[name], region, diag)
        row["jitter"] = float("nan")
        rows.append(row)
    return rows


def _sweep(
    methods: Mapping[str, Solver],
    frames: ArrayLike,
    truth: ArrayLike,
    key: str,
    values: Sequence[float],
    perturb: Callable[[F64, float, np.random.Generator], F64],
    seed: int,
    region: ArrayLike | None,
    temporal: bool,
) -> list[Row]:
    """Evaluates every method on `perturb(frames, value, rng)` for each value; rows get `key`."""
    fr = np.asarray(frames, dtype=np.float64)
    rows = []
    for v in values:
        changed = perturb(fr, v, np.random.default_rng(seed))
        for row in evaluate(methods, changed, truth, region, temporal=temporal):
            rows.append({key: v, **row})
    return rows


def noise_sweep(
    methods: Mapping[str, Solver],
    frames: ArrayLike,
    truth: ArrayLike,
    sigmas: Sequence[float] = (0.0, 0.05, 0.1, 0.2),
    seed: int = 0,
    region: ArrayLike | None = None,
    temporal: bool = True,
) -> list[Row]:
    """Gaussian marker noise of each standard deviation (data units; 0..0.2 cm = 0..2 mm)."""

    def noisy(fr: F64, s: float, rng: np.random.Generator) -> F64:
        return fr + rng.normal(scale=s, size=fr.shape)

    return _sweep(methods, frames, truth, "sigma", sigmas, noisy, seed, region, temporal)


def dropout_sweep(
    methods: Mapping[str, Solver],
    frames: ArrayLike,
    truth: ArrayLike,
    rates: Sequence[float] = (0.0, 0.05, 0.1, 0.2),
    seed: int = 0,
    region: ArrayLike | None = None,
    temporal: bool = True,
) -> list[Row]:
    """A fraction `rate` of marker entries set missing (NaN), uniformly at random."""

    def holey(fr: F64, r: float, rng: np.random.Generator) -> F64:
        return np.where((rng.random(fr.shape[:2]) < r)[..., None], np.nan, fr)

    return _sweep(methods, frames, truth, "dropout", rates, holey, seed, region, temporal)


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return "nan" if np.isnan(v) else f"{v:.4g}"
    return str(v)


def to_markdown(rows: Sequence[Row]) -> str:
    """A Markdown table of `rows` (columns in the order of the first row)."""
    if not rows:
        return ""
    keys = list(rows[0])
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(_fmt(r.get(k)) for k in keys) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def to_csv(rows: Sequence[Row], path: str | os.PathLike[str]) -> None:
    """Writes `rows` as CSV with a header, whole or not at all (`lgi.io.atomic`); nothing
    for no rows."""
    from lgi.io.atomic import atomic_path

    if not rows:
        return
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def steps(items: Sequence[Any], desc: str, quiet: bool) -> Any:
    """`items` with a progress bar on stderr (none when `quiet`)."""
    from tqdm import tqdm

    return tqdm(items, desc=desc, disable=quiet or len(items) < 2, leave=False)
