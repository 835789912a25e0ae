"""Leave-one-marker-out on real marker takes: accuracy where no dense truth exists.

A real take (the shared AnimFace recordings: one performer, 41 markers, 60 Hz) is put on a
model's neutral in four steps, each a fixed rule:

1. **Stabilise.** Every frame is aligned rigidly to the take's first frame on the markers that
   move with the skull (forehead and nose bridge, `RIGID`), by `lgi.capture.stabilize.align`.
2. **Similarity to the model.** The first frame's landmark markers are mapped onto the model's
   landmark vertices (ICT: the 68 iBUG points of `vertex_indices.json`) by the least-squares
   similarity (Umeyama 1991: rotation, translation and one scale; the performer's face is not
   the model's, so ~1 cm of residual remains).
3. **Rest layout.** Each marker's rest position is the closest point of its mapped first-frame
   position on the model's face (`closest_surface_points`).
4. **Motion.** Each frame is the rest layout plus the marker's mapped displacement from the
   first frame (the first frame is taken as the neutral: both takes start at rest).

Each compared method then solves the take without marker j (its layout, its model and its
frames have 40 markers), and the error is the distance between marker j's capture and its
surface position on the result (barycentric at its rest triangle), over every frame; held-out
markers are picked by `held_out_markers` (spread over the face, most-moving first)."""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

import lgi._lgi as _lgi
from lgi.capture.stabilize import align
from lgi.data.dataset import Dataset
from lgi.errors import InputError, LgiWarning
from lgi.io.takes import RawTake

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
Row = dict[str, Any]

__all__ = [
    "ANIMFACE_IBUG",
    "LOMO_COLUMNS",
    "RIGID",
    "Retargeted",
    "Scores",
    "closest_surface_points",
    "held_out_markers",
    "lomo",
    "retarget",
    "rows",
    "similarity",
]

ANIMFACE_IBUG: dict[str, int] = {
    "Chin": 8,
    "Mouth_Up": 51,
    "Mouth_Down": 57,
    "NoseTop": 27,
    "NoseHead": 30,
    "Mouth_Lend": 54,
    "Mouth_Rend": 48,
    "Leye_Inside": 42,
    "Leye_Outside": 45,
    "Reye_Inside": 39,
    "Reye_Outside": 36,
    "Leyebrow_Inside": 22,
    "Leyebrow_Outside": 26,
    "Reyebrow_Inside": 21,
    "Reyebrow_Outside": 17,
    "NoseHead_L": 35,
    "NoseHead_R": 31,
}
"""AnimFace marker name -> iBUG 68-point landmark number (the data's README)."""

RIGID = ("ForeHead_M", "ForeHead_L", "ForeHead_R", "NoseTop")
"""AnimFace markers that move with the skull: the stabilisation's reference."""

MIN_LANDMARKS = 4
"""Fewest landmark markers a similarity is fitted from (3 fix it; one more checks it)."""

LOMO_COLUMNS = ["method", "markers", "frames", "mean", "p95", "max", "best_of", "ms_per_frame"]
"""Row keys: the held-out markers' capture-to-surface distance over frames and held-out markers
(data units); `frames` per held-out marker; `best_of`, how many held-out markers this method
had the lowest mean error on."""


def similarity(source: ArrayLike, target: ArrayLike) -> tuple[float, F64, F64]:
    """The least-squares similarity (scale s, rotation R, translation t) with
    s R source_i + t ~ target_i (Umeyama 1991; a reflection is never returned)."""
    src = np.asarray(source, dtype=np.float64)
    dst = np.asarray(target, dtype=np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3 or src.shape[0] < 3:
        raise InputError(
            f"similarity: expected two (N >= 3, 3) arrays, got {src.shape}, {dst.shape}"
        )
    ms, md = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - ms, dst - md
    var = float((a * a).sum(axis=1).mean())
    if var <= 0:
        raise InputError("similarity: the source points coincide")
    u, sv, vt = np.linalg.svd(b.T @ a / src.shape[0])
    fix = np.array([1.0, 1.0, np.sign(np.linalg.det(u @ vt)) or 1.0])
    rot = u @ np.diag(fix) @ vt
    scale = float((sv * fix).sum() / var)
    return scale, rot, md - scale * rot @ ms


def closest_surface_points(
    points: ArrayLike, vertices: ArrayLike, triangles: ArrayLike
) -> tuple[I64, F64, F64]:
    """Each point's closest point on the triangles (the core's exact query,
    `lgi._lgi.closest_surface_points`): the row of `triangles` it lies on, its barycentric
    coordinates (P, 3) and the point itself (P, 3)."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    rows, bary = _lgi.closest_surface_points(v, t, points)
    return rows, bary, np.einsum("pk,pkd->pd", bary, v[t[rows]])


@dataclass(frozen=True)
class Retargeted:
    """A real take on a model's neutral (`retarget`)."""

    names: list[str]
    rest: F64
    """(B, 3) rest layout on the model's face."""
    frames: F64
    """(F, B, 3) markers on the model: rest plus each marker's mapped displacement."""
    corners: I64
    """(B, 3) the vertices of the model triangle each rest position lies on."""
    barycentrics: F64
    """(B, 3) its barycentric coordinates there."""
    scale: float
    """The similarity's scale (model size / performer size)."""
    landmark_residual: float
    """Mean distance of the mapped landmark markers to the model's landmark vertices."""
    stabilised_rms: F64
    """(F,) RMS of the rigid markers after stabilisation (how rigid the skull reference is)."""


def retarget(
    take: RawTake,
    neutral: ArrayLike,
    triangles: ArrayLike,
    landmarks: Mapping[str, int],
    rigid: Sequence[str] = RIGID,
) -> Retargeted:
    """Puts `take` (a real take, its first frame at rest) on a model: stabilised on the `rigid`
    markers, mapped by the similarity of the `landmarks` markers (name -> model vertex) onto
    the model, rest positions the closest points on `triangles` (the face the markers may lie
    on) and frames rest + mapped displacement (the module's four steps). InputError naming the
    file when the take lacks rigid or landmark markers, or misses one in its first frame."""
    names = list(take.labels)
    where = {n: i for i, n in enumerate(names)}
    lacking = [n for n in rigid if n not in where]
    if len(rigid) - len(lacking) < 3:
        raise InputError(
            f"{take.path}: needs at least 3 of the skull markers {', '.join(rigid)} to "
            f"stabilise; missing {', '.join(lacking)}"
        )
    marks = [n for n in landmarks if n in where]
    if len(marks) < MIN_LANDMARKS:
        raise InputError(
            f"{take.path}: needs at least {MIN_LANDMARKS} landmark markers "
            f"({', '.join(landmarks)}) to map onto the model; has {len(marks)}"
        )
    x = np.asarray(take.points, dtype=np.float64)
    if np.isnan(x[0]).any():
        gone = [names[i] for i in np.flatnonzero(np.isnan(x[0]).any(axis=1))]
        raise InputError(
            f"{take.path}: frame 1 (the rest frame) misses {', '.join(gone[:5])}; the take "
            "must start with every marker"
        )
    w = np.zeros(len(names))
    w[[where[n] for n in rigid if n in where]] = 1.0
    stab = align(x, x[0], w)
    nv = np.asarray(neutral, dtype=np.float64)
    src = stab.frames[0, [where[n] for n in marks]]
    dst = nv[[landmarks[n] for n in marks]]
    s, rot, t = similarity(src, dst)
    mapped = s * np.einsum("ij,fbj->fbi", rot, stab.frames) + t
    residual = float(np.linalg.norm(mapped[0, [where[n] for n in marks]] - dst, axis=1).mean())
    tri, bary, rest = closest_surface_points(mapped[0], nv, triangles)
    return Retargeted(
        names=names,
        rest=rest,
        frames=rest[None] + (mapped - mapped[0][None]),
        corners=np.asarray(triangles, dtype=np.int64)[tri],
        barycentrics=bary,
        scale=s,
        landmark_residual=residual,
        stabilised_rms=stab.rms,
    )


def held_out_markers(
    rest: ArrayLike, frames: ArrayLike, candidates: Sequence[int], count: int
) -> list[int]:
    """`count` of the `candidates` spread over the face: the one moving most (mean distance
    from rest over the frames) first, then each farthest (at rest) from those picked."""
    r = np.asarray(rest, dtype=np.float64)
    cand = np.asarray(candidates, dtype=np.int64)
    if count < 1 or count > cand.size:
        raise InputError(f"held-out markers: need 1..{cand.size}, got {count}")
    motion = np.nanmean(np.linalg.norm(np.asarray(frames) - r[None], axis=2), axis=0)
    picked = [int(cand[np.argmax(motion[cand])])]
    while len(picked) < count:
        d = np.linalg.norm(r[cand][:, None] - r[picked][None], axis=2).min(axis=1)
        picked.append(int(cand[np.argmax(d)]))
    return picked


class Rest:
    """The reference that never moves: every frame is the neutral (how much the markers move)."""

    label = "no motion"

    def __init__(self, dataset: Dataset) -> None:
        self.neutral = np.asarray(dataset.neutral, dtype=np.float64)

    def solve(self, frames: ArrayLike, *, quiet: bool = True, **_: Any) -> Any:
        n = np.asarray(frames).shape[0]
        return _Vertices(np.broadcast_to(self.neutral, (n, *self.neutral.shape)))


@dataclass(frozen=True)
class _Vertices:
    vertices: F64


MethodsFor = Callable[[Dataset, F64, F64], Mapping[str, Any]]
"""(dataset, rest layout, frames) -> named methods with `solve(frames, temporal=, quiet=)`."""


@dataclass(frozen=True)
class Scores:
    """What `lomo` measured on one take."""

    errors: dict[str, dict[str, F64]]
    """method -> held-out marker name -> (F,) capture-to-surface distance per frame."""
    seconds: dict[str, float]
    """method -> seconds spent solving (every held-out marker together)."""


def lomo(
    dataset: Dataset,
    take: Retargeted,
    held_out: Sequence[int],
    methods_for: MethodsFor,
    *,
    step: int = 1,
) -> Scores:
    """Solves every `step`-th frame of `take` once per held-out marker j with every method
    `methods_for` builds on the layout without j (given every frame: a noise estimate needs
    the capture rate), and scores j's capture against its surface position on each result."""
    errors: dict[str, dict[str, F64]] = {}
    seconds: dict[str, float] = {}
    for j in held_out:
        keep = np.array([i for i in range(len(take.names)) if i != j])
        with warnings.catch_warnings():
            # Only the noise estimate's frames-too-far-apart warning is silenced (docs/results.md
            # gives the estimates); anything else a method's build warns of still shows.
            warnings.filterwarnings("ignore", message="marker noise:", category=LgiWarning)
            methods = methods_for(dataset, take.rest[keep], take.frames[:, keep])
        fr = take.frames[::step, keep]
        for name, m in methods.items():
            t0 = time.perf_counter()
            # Every `step`-th frame: no performance to fill gaps or steady detail over.
            res = m.solve(fr, temporal=True, steady=False, quiet=True)
            seconds[name] = seconds.get(name, 0.0) + time.perf_counter() - t0
            v = np.asarray(res.vertices)
            at = np.einsum("fkd,k->fd", v[:, take.corners[j]], take.barycentrics[j])
            errors.setdefault(name, {})[take.names[j]] = np.linalg.norm(
                at - take.frames[::step, j], axis=1
            )
    return Scores(errors=errors, seconds=seconds)


def rows(scores: Sequence[Scores], label: str) -> list[Row]:
    """One row per method (`LOMO_COLUMNS`, "label: method") over every held-out marker and
    frame of `scores` (one take, or several pooled)."""
    methods = list(scores[0].errors)
    means = np.array([[e.mean() for s in scores for e in s.errors[m].values()] for m in methods])
    best = np.argmin(means, axis=0)
    out: list[Row] = []
    for k, m in enumerate(methods):
        e = np.concatenate([e for s in scores for e in s.errors[m].values()])
        out.append(
            {
                "method": f"{label}: {m}",
                "markers": means.shape[1],
                "frames": sum(next(iter(s.errors[m].values())).size for s in scores),
                "mean": float(e.mean()),
                "p95": float(np.percentile(e, 95)),
                "max": float(e.max()),
                "best_of": int((best == k).sum()),
                "ms_per_frame": 1e3 * sum(s.seconds[m] for s in scores) / e.size,
            }
        )
    return out
