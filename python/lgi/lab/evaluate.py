"""Evaluation of LGI and the baselines against ground truth: per-vertex error statistics, bundle
residuals, temporal jitter and speed, on the protocols of the paper's comparisons (held-out
performance, verification on the dataset's own shapes, leave-one-shape-out, noise, dropouts)."""

from __future__ import annotations

import csv
import os
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi._lgi import JawRig, SolveResult
from lgi.baselines import FitJaw, FitJawResidual, FitJawUnbounded, FitJawUnboundedResidual
from lgi.choices import SolvePlan, plan_solve
from lgi.dataset import Dataset, without_shapes
from lgi.denoise import denoise_take
from lgi.errors import InputError, LgiWarning
from lgi.lab.capture import (
    CaptureTake,
    HingeJaw,
    NonlinearTruth,
    box_diagonal,
    departure,
    make_capture,
    marker_samples,
)
from lgi.local import UNBOUNDED
from lgi.model import Model
from lgi.noise import estimate_marker_noise

F64 = NDArray[np.float64]
Row = dict[str, Any]

__all__ = [
    "COLUMNS",
    "Solver",
    "dropout_sweep",
    "evaluate",
    "leave_one_out",
    "noise_sweep",
    "score",
    "to_csv",
    "to_markdown",
    "verification",
]

COLUMNS = [
    "method",
    "frames",
    "mean",
    "p95",
    "max",
    "max_residual_rel",
    "jitter",
    "ms_per_frame",
]
"""Row keys: errors (mean, p95, max of per-vertex distances) and jitter (mean norm of the second
difference of vertex positions over time) are in data units; the bundle residual is relative to
the bounding-box diagonal."""


class Solver(Protocol):
    def solve(self, frames: ArrayLike, *, temporal: bool = ..., quiet: bool = ...) -> Any: ...


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
    for name, m in _steps(list(methods.items()), "lgi evaluate", quiet):
        t0 = time.perf_counter()
        res = m.solve(fr, temporal=temporal, quiet=True)
        rows.append(score(name, res, tr, time.perf_counter() - t0, region, diagonal))
    return rows


def verification(dataset: Dataset, markers: ArrayLike) -> tuple[F64, F64]:
    """Frames (S, B, 3): the markers on each dataset shape, and the shapes (S, V, 3) as truth."""
    truth = np.asarray(dataset.neutral)[None] + np.asarray(dataset.shapes, dtype=np.float64)
    return marker_samples(dataset, markers, truth), truth


def _without(dataset: Dataset, k: int) -> Dataset:
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
    for k in _steps(ks, "lgi evaluate: leave one out", quiet):
        methods = method_factory(_without(dataset, k), markers)
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


def default_methods(dataset: Dataset, markers: ArrayLike) -> dict[str, Solver]:
    """The four compared methods (LGI and LGI-RBF share one built model)."""
    from lgi.baselines import BlendshapeFit, DisplacementInterpolation, LgiRbf

    lgi_rbf = LgiRbf(dataset, markers)
    return {
        DisplacementInterpolation.label: DisplacementInterpolation(dataset, markers),
        BlendshapeFit.label: BlendshapeFit(dataset, markers),
        LgiRbf.label: lgi_rbf,
        "LGI": lgi_rbf.model,
    }


class Recommended:
    """LGI's recommended path as a compared method: `model.solve(frames, marker_noise=sigma)`
    on a model built with defaults (`sigma` None: the paper's exact mode). With `detail`
    "auto", the frames' detail weight (`lgi.estimate_detail_weight`, read from the frames
    solved, with the same sigma) is kept too, the call for a performer the dataset is not
    (`last_detail_weight` says which); with `local_fits`, the pieces are local fits
    (`lgi.local`); `fit` is `Model.solve`'s (e.g. "unbounded"); with `take_prior`, the
    unbounded fit takes the prior read from the frames solved (`lgi.estimate_take_prior`); with
    `denoise`, the frames are first denoised by the take's own low-rank structure
    (`lgi.denoise_take`) and solved with the noise it leaves. The steps are `lgi.plan_solve`'s
    with these options given (as `lgi solve` takes them)."""

    def __init__(
        self,
        model: Model,
        marker_noise: float | None,
        detail: str | None = None,
        local_fits: bool | str = False,
        fit: str | None = None,
        take_prior: bool = False,
        denoise: bool = False,
    ) -> None:
        if fit not in (None, UNBOUNDED):
            raise InputError(f"fit: expected None or {UNBOUNDED!r}, got {fit!r}")
        self.model, self.marker_noise, self.detail = model, marker_noise, detail
        self.local_fits, self.fit, self.take_prior = local_fits, fit, take_prior
        self.denoise = denoise
        self.last_detail_weight: float | None = None

    def solve(self, frames: ArrayLike, *, temporal: bool = True, quiet: bool = True) -> SolveResult:
        # The plan `lgi solve` makes with these options given (one definition of the steps).
        plan = plan_solve(
            np.asarray(frames, dtype=np.float64),
            self.model,
            noise=self.marker_noise,
            denoise=self.denoise,
            local_fits=self.local_fits,
            unbounded_fit=self.fit == UNBOUNDED,
            take_prior=self.take_prior,
            detail=self.detail,
        )
        if self.detail == "auto":
            self.last_detail_weight = plan.detail_weight
        return self.model.solve(plan.frames, temporal=temporal, quiet=quiet, **plan.solve_options())


#: The name of LGI with local fits (`Model.solve(local_fits=True)`) among compared methods.
LOCAL_FITS = "LGI + local fits"
#: The same with unbounded local fits (`Model.solve(local_fits="unbounded")`, which start from
#: the unbounded global fit).
LOCAL_FITS_UNBOUNDED = "LGI + local fits (unbounded)"
#: LGI's recommended call with the unbounded global fit (`Model.solve(fit="unbounded")`).
UNBOUNDED_FIT = "LGI (unbounded fit)"
#: The same with the take's prior on the unbounded fit (`lgi.estimate_take_prior`).
TAKE_PRIOR = "LGI (take prior)"
#: Unbounded local fits from the unbounded fit with the take's prior.
LOCAL_FITS_TAKE_PRIOR = "LGI + local fits (take prior)"
#: LGI's recommended call (and with local fits) on the take denoised by its own low-rank
#: structure (`lgi.denoise_take`): bounded where the protocol's LGI is (FACS shapes), with the
#: unbounded fit and unbounded local fits in the scans protocol.
DENOISED = "LGI (denoised)"
LOCAL_FITS_DENOISED = "LGI + local fits (denoised)"
#: A peer's name when it is given the same denoised markers (not a peer a TD has: it says how
#: much of a denoised method's gain is the denoising's).
DENOISED_PEER = "{} on denoised markers"
#: The peers a TD has (`lgi.baselines`): the rig solve with the jaw as a joint and its residual
#: corrective, boxed and (the scans protocol's) unbounded.
PEER_NAMES = (
    FitJaw.label,
    FitJawResidual.label,
    FitJawUnbounded.label,
    FitJawUnboundedResidual.label,
)


class OnDenoised:
    """A compared method given the take denoised by `lgi.denoise_take` with `sigma`."""

    def __init__(self, method: Solver, sigma: float) -> None:
        self.method, self.sigma = method, sigma

    def solve(self, frames: ArrayLike, *, temporal: bool = True, quiet: bool = True) -> Any:
        den = denoise_take(frames, self.sigma)
        return self.method.solve(den.frames, temporal=temporal, quiet=quiet)


def add_denoised(methods: dict[str, Solver], unbounded: bool) -> None:
    """`DENOISED` and `LOCAL_FITS_DENOISED` beside a protocol's noisy LGI (`unbounded`: with
    the unbounded fit and unbounded local fits, the scans' calls; else the boxed ones), and
    each of the protocol's peers (`PEER_NAMES`) on the denoised markers (`DENOISED_PEER`)."""
    lgi = methods["LGI"]
    if not isinstance(lgi, Recommended) or not lgi.marker_noise:
        return
    sigma, model = lgi.marker_noise, lgi.model
    fit = UNBOUNDED if unbounded else None
    methods[DENOISED] = Recommended(model, sigma, fit=fit, denoise=True)
    if model.jaw_bins is None:
        local: bool | str = "unbounded" if unbounded else True
        methods[LOCAL_FITS_DENOISED] = Recommended(model, sigma, local_fits=local, denoise=True)
    for name in PEER_NAMES:
        if name in methods:
            methods[DENOISED_PEER.format(name)] = OnDenoised(methods[name], sigma)


#: LGI as `lgi solve --recommended` solves a take: every choice read from the take given, its
#: marker noise included (`lgi.choices.plan_solve`), not the protocol's sigma.
AS_RECOMMENDED = "LGI --recommended"


class AsRecommended:
    """`AS_RECOMMENDED` as a compared method: the plan `lgi solve --recommended` reads from the
    frames given (with `take`: from that whole take, of which the frames given are every
    `step`-th, as a TD gives a whole take and the protocol scores some of its frames), then
    `model.solve` of it. `last_plan` is the plan of the last solve."""

    def __init__(self, model: Model, take: ArrayLike | None = None, step: int = 1) -> None:
        self.model, self.step = model, step
        self.take = None if take is None else np.asarray(take, dtype=np.float64)
        self.last_plan: SolvePlan | None = None

    def solve(self, frames: ArrayLike, *, temporal: bool = True, quiet: bool = True) -> Any:
        x = np.asarray(frames, dtype=np.float64)
        whole = x if self.take is None else self.take
        with warnings.catch_warnings():
            # Only the noise estimate's frames-too-far-apart warning is silenced (the row's
            # plan gives the noise read); anything else still shows.
            warnings.filterwarnings("ignore", message="marker noise:", category=LgiWarning)
            plan = plan_solve(whole, self.model, recommended=True)
        solved = plan.frames if self.take is None else plan.frames[:: self.step]
        if solved.shape != x.shape:
            raise InputError(
                f"as recommended: {x.shape[0]} frames given are not every {self.step}-th of "
                f"the take's {whole.shape[0]}"
            )
        self.last_plan = plan
        return self.model.solve(solved, temporal=temporal, quiet=quiet, **plan.solve_options())


def add_as_recommended(methods: dict[str, Solver]) -> None:
    """`AS_RECOMMENDED` beside a protocol's LGI (its model)."""
    lgi = methods["LGI"]
    if isinstance(lgi, Recommended):
        methods[AS_RECOMMENDED] = AsRecommended(lgi.model)


def capture_methods(
    dataset: Dataset,
    markers: ArrayLike,
    sigma: float | None,
    frames: ArrayLike | None = None,
    *,
    jaw: tuple[JawRig, ArrayLike] | None = None,
) -> dict[str, Solver]:
    """The methods of the capture protocol: the two baselines, the fit with the jaw as a joint
    (`FitJaw`, the production rig solve, where the dataset gives a jaw rig) and the same with
    its residual corrective (`FitJawResidual`), LGI in the paper's
    exact mode (no jaw rig, no fit: tets only), LGI's recommended path (defaults,
    `marker_noise` = `sigma`; None: estimated from `frames` with the model, as
    `--marker-noise auto` does) and the same with local fits (`LOCAL_FITS`,
    `lgi.local`). `jaw`: the rig and each shape's pose for a dataset without
    ICT's jaw shapes (None: the rig `Model.build` finds, if any)."""
    from lgi.baselines import BlendshapeFit, DisplacementInterpolation, FitJaw, FitJawResidual

    if jaw is None:
        recommended = Model.build(dataset, markers)
    else:
        recommended = Model.build(dataset, markers, jaw=jaw[0], shape_theta=jaw[1])
    if sigma is None:
        if frames is None:
            raise InputError("capture methods: sigma None needs the frames to estimate it from")
        sigma = estimate_marker_noise(frames, recommended)
    methods: dict[str, Solver] = {
        DisplacementInterpolation.label: DisplacementInterpolation(dataset, markers),
        BlendshapeFit.label: BlendshapeFit(dataset, markers),
    }
    if recommended.jaw_rig is not None:
        peer = FitJaw(recommended)
        methods[FitJaw.label] = peer
        methods[FitJawResidual.label] = FitJawResidual(peer)
    methods["LGI (paper)"] = Recommended(Model.build(dataset, markers, jaw=None), None)
    methods["LGI"] = Recommended(recommended, sigma)
    if recommended.jaw_bins is None:
        methods[LOCAL_FITS] = Recommended(recommended, sigma, local_fits=True)
    return methods


def _add_unbounded(methods: dict[str, Solver]) -> None:
    """The scans protocol's unbounded methods beside the bounded ones: a scan's weight is no
    activation, so the peers' fit without its [0, 1] bound is a peer too (`FitJawUnbounded`
    and its corrective), and LGI without it: the recommended call (`UNBOUNDED_FIT`) and with
    local fits (`LOCAL_FITS_UNBOUNDED`); with noisy markers, both with the take's prior on the
    unbounded fit (`TAKE_PRIOR`, `LOCAL_FITS_TAKE_PRIOR`)."""
    from lgi.baselines import FitJawUnbounded, FitJawUnboundedResidual

    lgi = methods["LGI"]
    if not isinstance(lgi, Recommended) or lgi.model.jaw_rig is None:
        return
    peer = FitJawUnbounded(lgi.model)
    methods[FitJawUnbounded.label] = peer
    methods[FitJawUnboundedResidual.label] = FitJawUnboundedResidual(peer)
    methods[UNBOUNDED_FIT] = Recommended(lgi.model, lgi.marker_noise, fit="unbounded")
    if lgi.model.jaw_bins is None:
        methods[LOCAL_FITS_UNBOUNDED] = Recommended(
            lgi.model, lgi.marker_noise, local_fits="unbounded"
        )
    if lgi.marker_noise and lgi.model.jaw_bins is None:
        # Noise-free markers need no prior (the solve would be the unbounded fit's).
        methods[TAKE_PRIOR] = Recommended(
            lgi.model, lgi.marker_noise, fit="unbounded", take_prior=True
        )
        methods[LOCAL_FITS_TAKE_PRIOR] = Recommended(
            lgi.model, lgi.marker_noise, local_fits="unbounded", take_prior=True
        )


def _performance(
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
    for i, rec in enumerate(_steps(list(recordings), "lgi evaluate: capture", quiet)):
        take, apart = _performance(
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
    from lgi.model import _auto_rig

    if len(recordings) < 2:
        raise InputError("the scans protocol needs two recordings: scans from one, a performance")
    hinge = HingeJaw.fit(dataset, jaw_rigid)
    rig, theta = _auto_rig(dataset)
    truth = NonlinearTruth(dataset) if nonlinear else None
    curves = [read_livelinkface(r).for_dataset(dataset.names) for r in recordings]
    shares: dict[str, float] = {}

    def bundles_fit(name: str, res: SolveResult) -> None:
        """The share of a method's bundles that took the global fit (LGI's only)."""
        if res.choices.fit is not None:
            shares[name] = float(np.mean(res.choices.fit))

    rows: list[Row] = []
    for i, rec in enumerate(_steps(list(recordings), "lgi evaluate: scans", quiet)):
        source = np.concatenate([c for k, c in enumerate(curves) if k != i])
        count = min(scans, source.shape[0])
        session = scan_session(dataset, source, count, hinge, theta, nonlinear=truth)
        take, apart = _performance(
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
        _add_unbounded(methods)
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
    for path in _steps(list(takes), "lgi evaluate: lomo", quiet):
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


def _steps(items: Sequence[Any], desc: str, quiet: bool) -> Any:
    """`items` with a progress bar on stderr (none when `quiet`)."""
    from tqdm import tqdm

    return tqdm(items, desc=desc, disable=quiet or len(items) < 2, leave=False)


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
            default_methods(_without(ds, k), markers),
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
    "ms_per_frame",
    "plan",
]
"""Row keys of the capture protocol: per-vertex error over all frames, and over the jaw-open
frames (`open_*`, NaN when the take has none), in data units."""


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
        res = m.solve(fr, temporal=True, quiet=True)
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
