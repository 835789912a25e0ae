"""Missing marker samples filled from the take before the per-frame solve.

A frame solved alone with one marker missing leans on local geometry that its neighbouring
frames, which have the marker, do not use: the surface moves off and back, a pop. A missing
sample is read from what the take says about it, in one of two ways, whichever predicts the
take's own samples better (`fill_motion`, below):

- **the take's motion** (`lgi.solve.motion`): the take's few strongest directions of motion
  predict the sample from the frame's other markers (a blink moves an eyelid's markers with
  the other eyelid's); what that prediction misses at the frames either side of the gap,
  where the marker was seen, is interpolated linearly in time across it and added;
- **the marker's neighbours**: its position relative to its `NEIGHBOURS` nearest markers (their
  median displacement from rest) interpolated linearly in time across the gap, and the
  neighbours' displacement at the missing frame added back.

`fill_motion` holds out runs of samples the take has (`HELD_RUNS` of each length in
`HELD_LENGTHS`, at places drawn with a fixed seed), fills them each way (the motion at every
rank up to `MOTION_RANK`) and keeps the way, and the rank, whose fills land nearest the samples
held out (root mean square). A gap longer than `MAX_GAP` frames, a frame where fewer than
`MIN_SEEN` of the markers are seen (a frame lost, not a dropout: the solve says so), a marker
never seen and, by its neighbours, a frame where none of them is seen stay missing (the
solve's own estimate).
Filled samples stay missing in the result (`SolveResult.missing`, residual 0): they are the
take's estimate, not a measurement.

Everything a filled sample depends on lies within `MAX_GAP + 1` frames of it, and the take's
motion, read once from the whole take: a take filled in chunks with that many frames of context
either side and the whole take's motion equals the take filled whole (`Model.solve_iter`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from lgi.solve.motion import TakeMotion, read_motion

__all__ = [
    "CONTEXT",
    "HELD_LENGTHS",
    "HELD_RUNS",
    "HELD_SHARE",
    "MAX_GAP",
    "MIN_SEEN",
    "MOTION_RANK",
    "NEIGHBOURS",
    "fill_motion",
    "filled",
    "nearest",
]

F64 = NDArray[np.float64]

NEIGHBOURS = 4
"""Markers a missing sample is read against: its nearest at rest (skin moves them together)."""

MAX_GAP = 30
"""Longest run of missing frames filled (half a second at 60 Hz); a longer gap is no longer
a dropout but a marker gone, and stays the solve's."""

MIN_SEEN = 0.5
"""The share of a frame's markers that must be seen for its dropouts to be filled."""

CONTEXT = MAX_GAP + 1
"""Frames either side of a chunk that its fill reads (see the module's note)."""

MOTION_RANK = 16
"""Directions of the take's motion a fill may use at most (`fill_motion` reads how many from
the take; on the 1,200-frame takes measured it picked 3-8, docs/reliability.md)."""

HELD_LENGTHS = (1, 2, 4, 8)
"""Lengths (frames) of the runs `fill_motion` holds out: dropouts are mostly short."""

HELD_RUNS = 60
"""Runs of each length `fill_motion` holds out (fewer where the take has no room)."""

HELD_SHARE = 0.05
"""The most of a frame's markers `fill_motion` holds out (at least one)."""

HELD_SEED = 0
"""The seed of the places `fill_motion` holds out: the same take reads the same way."""


def nearest(rest: F64) -> NDArray[np.int64]:
    """(B, k) each marker's `NEIGHBOURS` nearest other markers at `rest` (B, 3), nearest
    first (k = min(NEIGHBOURS, B - 1))."""
    b = rest.shape[0]
    d = np.linalg.norm(rest[:, None] - rest[None], axis=2)
    np.fill_diagonal(d, np.inf)
    return np.argsort(d, axis=1, kind="stable")[:, : min(NEIGHBOURS, b - 1)]


def _runs(flags: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """The [start, stop) ranges where `flags` (F,) is True."""
    edges = np.diff(np.concatenate(([0], flags.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


def _frames_kept(seen: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """(F,) the frames that are there, a few markers lost (at least `MIN_SEEN` of them seen):
    the frames whose dropouts are filled."""
    return np.asarray(seen.mean(axis=1) >= MIN_SEEN)


def _gaps(
    usable: NDArray[np.bool_], fillable: NDArray[np.bool_]
) -> list[tuple[NDArray[np.int64], list[int]]]:
    """One marker's gaps (F,): its runs of frames not `usable`, no longer than `MAX_GAP`, each
    with its `fillable` frames (none: no gap) and its bounds, the usable frames either side (one
    at the take's first or last frame). No gap of a marker no frame says anything of."""
    f = usable.size
    found: list[tuple[NDArray[np.int64], list[int]]] = []
    if not usable.any():
        return found
    for a, z in _runs(~usable):
        if z - a > MAX_GAP:
            continue
        gone = np.flatnonzero(fillable[a:z]) + a
        if gone.size:
            lo, hi = max(a - 1, 0), min(z, f - 1)
            found.append((gone, [int(t) for t in (lo, hi) if usable[t]]))
    return found


def filled(
    frames: F64, rest: F64, motion: TakeMotion | None = None
) -> tuple[F64, NDArray[np.bool_]]:
    """`frames` (F, B, 3; NaN rows missing) with the missing samples the take can fill filled
    (a new array; present samples as given), and the (F, B) mask of the samples filled: by the
    take's `motion` where given (`fill_motion` reads it), else by each marker's neighbours at
    `rest`, the markers' rest positions (B, 3)."""
    x = np.array(frames, dtype=np.float64)
    f, b = x.shape[:2]
    done = np.zeros((f, b), dtype=bool)
    seen: NDArray[np.bool_] = np.asarray(np.isfinite(x).all(axis=2))
    if f < 2 or b < 2 or seen.all():
        return x, done
    if motion is not None:
        frame_at, marker_at, values = _by_motion(x, seen, motion, [motion.rank], _motion_runs(seen))
        x[frame_at, marker_at] = values[0]
        done[frame_at, marker_at] = True
        return x, done
    _by_neighbours(x, seen, np.asarray(rest, dtype=np.float64), done)
    return x, done


def _by_neighbours(
    x: F64,
    seen: NDArray[np.bool_],
    rest: F64,
    done: NDArray[np.bool_],
    wanted: NDArray[np.bool_] | None = None,
) -> None:
    """`x`'s gaps filled in place by each marker's neighbours, `done` marked (module text);
    `wanted` (F, B): only the gaps filling one of these samples."""
    f = x.shape[0]
    near = nearest(rest)
    frame_kept = _frames_kept(seen)
    moved = x - rest[None]  # each marker's displacement from rest; NaN where missing
    lacking = ~seen.all(axis=0) if wanted is None else wanted.any(axis=0)
    for k in np.flatnonzero(lacking):
        with_neighbour: NDArray[np.bool_] = np.asarray(seen[:, near[k]].any(axis=1))
        usable = seen[:, k] & with_neighbour  # frames that say where the marker sits
        runs = _gaps(usable, ~seen[:, k] & with_neighbour & frame_kept)
        if wanted is not None:
            runs = [(gone, ends) for gone, ends in runs if wanted[gone, k].any()]
        if not runs:
            continue
        # The neighbours' median displacement, read only where a fill needs it.
        need = np.unique(np.concatenate([np.r_[gone, ends] for gone, ends in runs]))
        carried = np.zeros((f, 3))
        carried[need] = np.nanmedian(moved[need][:, near[k]], axis=1)
        offset = x[:, k] - carried  # the marker relative to its neighbours
        for gone, ends in runs:
            value = np.stack([np.interp(gone, ends, offset[ends, c]) for c in range(3)], axis=1)
            x[gone, k] = value + carried[gone]
            done[gone, k] = True


_Run = tuple[int, NDArray[np.int64], list[int]]
"""A gap to fill: the marker, its missing frames to fill and the frames either side where it
was seen (one at the take's first or last frame, else two)."""


def _motion_runs(seen: NDArray[np.bool_]) -> list[_Run]:
    """The gaps the take's motion fills: each marker's runs of missing frames no longer than
    `MAX_GAP`, in frames where at least `MIN_SEEN` of the markers are seen, with a frame either
    side where the marker was."""
    frame_kept = _frames_kept(seen)
    return [
        (int(k), gone, ends)
        for k in np.flatnonzero(~seen.all(axis=0))
        for gone, ends in _gaps(seen[:, k], frame_kept)
    ]


def _by_motion(
    x: F64, seen: NDArray[np.bool_], motion: TakeMotion, ranks: list[int], runs: list[_Run]
) -> tuple[NDArray[np.int64], NDArray[np.int64], list[F64]]:
    """The samples of `x` (F, B, 3) in `runs` filled by the take's motion at each of `ranks`:
    the motion's prediction of the marker from its frame's seen markers, plus what the
    prediction of the marker from the others misses at the run's ends, interpolated in time.
    Their frames, markers and (n, 3) values per rank."""
    f, b = seen.shape
    if not runs:
        none = np.zeros(0, dtype=np.int64)
        return none, none, [np.zeros((0, 3)) for _ in ranks]
    flat = x.reshape(f, 3 * b)
    hidden = np.repeat(~seen, 3, axis=1)
    asked = np.unique(np.concatenate([gone for _, gone, _ in runs]))
    ends = [(t, k) for k, _, e in runs for t in e]
    end_frames = np.array([t for t, _ in ends], dtype=np.int64)
    end_hidden = hidden[end_frames].copy()
    for i, (_, k) in enumerate(ends):
        end_hidden[i, 3 * k : 3 * k + 3] = True  # the marker predicted from the others
    rows = np.concatenate([flat[asked], flat[end_frames]])
    predicted = motion.predictions(rows, np.concatenate([hidden[asked], end_hidden]), ranks)
    # Every filled sample as a row: its frame, marker, row of the prediction inside the run and
    # the rows of the two ends' predictions with their weights (one end: both the same).
    at = np.full(f, -1)
    at[asked] = np.arange(asked.size)
    frame_of, marker_of, lo_row, hi_row, lo_frame, hi_frame, hi_weight = [], [], [], [], [], [], []
    e = 0
    for k, gone, where in runs:
        lo, hi = where[0], where[-1]
        frame_of.append(gone)
        marker_of.append(np.full(gone.size, k))
        lo_row.append(np.full(gone.size, e))
        hi_row.append(np.full(gone.size, e + len(where) - 1))
        lo_frame.append(np.full(gone.size, lo))
        hi_frame.append(np.full(gone.size, hi))
        hi_weight.append((gone - lo) / (hi - lo) if hi > lo else np.zeros(gone.size))
        e += len(where)
    at_frame, at_marker, rl, rh, tl, th, w = (
        np.concatenate(a)
        for a in (frame_of, marker_of, lo_row, hi_row, lo_frame, hi_frame, hi_weight)
    )
    w = w[:, None]
    out = []
    for p in predicted:
        inside = p[: asked.size].reshape(-1, b, 3)
        edge = p[asked.size :].reshape(-1, b, 3)
        m = at_marker
        missed = (1.0 - w) * (x[tl, m] - edge[rl, m]) + w * (x[th, m] - edge[rh, m])
        out.append(inside[at[at_frame], m] + missed)
    return at_frame, at_marker, out


def fill_motion(frames: F64, rest: F64, noise: float) -> TakeMotion | None:
    """The take's motion that fills `frames` (F, B, 3; NaN missing) best, at markers' noise
    `noise` (sigma per coordinate, ≥ 0), or None where each marker's neighbours at `rest`
    (B, 3) fill it better (module text): runs of samples the take has are held out, filled by
    the neighbours and by the motion at each rank, and the fill nearest them kept. None too
    for a take too short to hold out `HELD_RUNS` runs (`HELD_SHARE` of a frame at most)."""
    x = np.asarray(frames, dtype=np.float64)
    f, b = x.shape[:2]
    seen: NDArray[np.bool_] = np.asarray(np.isfinite(x).all(axis=2))
    if f < 2 or b < 2:
        return None
    frame_kept = _frames_kept(seen)
    rng = np.random.default_rng(HELD_SEED)
    held = np.zeros((f, b), dtype=bool)
    cap = max(1, int(HELD_SHARE * b))
    runs: list[_Run] = []
    for length in HELD_LENGTHS:
        if f < length + 2:
            continue
        found = 0
        for _ in range(20 * HELD_RUNS):
            k, a = int(rng.integers(b)), int(rng.integers(1, f - length))
            span = slice(a - 1, a + length + 1)
            # At most `HELD_SHARE` of a frame's markers held out: each is predicted from a
            # frame much as the take has it.
            free = held[a : a + length].sum(axis=1).max() < cap and not held[span, k].any()
            if free and seen[span, k].all() and frame_kept[a : a + length].all():
                held[a : a + length, k] = True
                runs.append((k, np.arange(a, a + length), [a - 1, a + length]))
                found += 1
                if found == HELD_RUNS:
                    break
    if len(runs) < HELD_RUNS:
        return None
    lacking = x.copy()
    lacking[held] = np.nan
    # Read without the samples held out: a motion read with them in predicts them as a fit
    # does, and more directions always look better.
    motion = read_motion(lacking, noise, MOTION_RANK)
    if motion is None:
        return None
    ranks = list(range(1, motion.rank + 1))
    frame_at, marker_at, fills = _by_motion(lacking, seen & ~held, motion, ranks, runs)
    by_neighbours, marked = lacking.copy(), np.zeros((f, b), dtype=bool)
    _by_neighbours(by_neighbours, seen & ~held, np.asarray(rest, dtype=np.float64), marked, held)
    fills.append(by_neighbours[frame_at, marker_at])
    errors = np.array([np.linalg.norm(y - x[frame_at, marker_at], axis=1) for y in fills])
    reached = np.isfinite(errors).all(axis=0)  # the neighbours leave some unfilled
    if not reached.any():
        return None
    # Root mean square: a fill that misses one sample by a centimetre pops where a fill that
    # misses a hundred by a tenth of a millimetre does not.
    best = int(np.argmin(np.sqrt(np.mean(errors[:, reached] ** 2, axis=1))))
    # Read again from the whole take at the rank chosen (its refill at that rank too).
    return None if best == len(ranks) else read_motion(x, noise, ranks[best])
