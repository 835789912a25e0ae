"""Which markers misbehaved, and when: after a solve, marker samples whose residual (with
`--marker-noise`, the correction the solve applied) is an outlier for the take's own spread are
gathered per marker into frame ranges, short ones called spikes; two markers off over the same
frames whose positions fit each other's tracks at the range's edges are a likely label swap. A
marker fault leaves the marker's own track where its neighbours do not follow (its position
relative to its neighbours steps at the range's edge, and the take's own motion elsewhere does
not put it there); a residual that comes and goes while the marker moves with its neighbours,
or as the take's low-rank motion predicts it from the other markers, is a model gap, where the
dataset does not reach the motion: reported as such, never as a fault. The rule
(docs/reliability.md): a sample is an outlier when its residual exceeds the median of all
present samples by `OUTLIER_MADS` scaled median absolute deviations, and is at least `FLOOR` of
the face's size (an exact solve's residuals are round-off)."""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi.io.result import Result
from lgi.solve.gaps import MAX_GAP
from lgi.solve.spectrum import shrinkage_factors, thin_svd
from lgi.solve.tracks import (
    NEIGHBOURS,
    RELATIVE_STEP_NOISE,
    nearest_markers,
    relative_steps,
    skin_track,
)

__all__ = [
    "FAULTS",
    "FLOOR",
    "NOISE_SIGMAS",
    "OUTLIER_MADS",
    "SPIKE_FRAMES",
    "Finding",
    "diagnose",
    "diagnose_result",
    "face_size",
    "finding_lines",
    "summary",
]

NOISE_SIGMAS = 5.0
"""With the solve's marker noise sigma known, a residual must also exceed this many sigma to
count: a Gaussian marker's distance from its true place exceeds 5 sigma once in 65,000 samples
(chi with 3 degrees of freedom), so a noisy take's ordinary corrections are no finding."""

OUTLIER_MADS = 8.0
"""How many scaled MADs (1.4826 x MAD: sigma for Gaussian residuals) above the median a
residual must be to count (measured false-positive rate on clean takes: docs/reliability.md)."""

FLOOR = 1e-3
"""Smallest outlier residual, as a share of the face's size: 0.25 mm on a 25 cm face."""

SPIKE_FRAMES = 5
"""A marker off for at most this many frames is a spike; longer, a marker off."""

FAULTS = ("swap", "spike", "off")
"""The kinds of finding that are a marker's fault (a "gap" is the dataset's, a "cut" the take's)."""

STEP_MADS = 8.0
"""How many scaled MADs above the median step of a marker's position relative to its
neighbours a step must be to leave its track (as `OUTLIER_MADS` for residuals)."""

_GAP = 1
"""Frames a range may skip and stay one range (a sample that dips under the threshold)."""


@dataclass(frozen=True)
class Finding:
    """One thing wrong with a take: `kind` is "swap", "spike", "off" or "cut" (the whole face
    jumps); frames are indices
    into the solve (0-based, inclusive); `worst` is the largest residual, in the take's
    unit."""

    kind: str
    markers: tuple[str, ...]
    first: int
    last: int
    worst: float

    @property
    def fault(self) -> bool:
        """A marker's fault (a swap, a spike, a marker off its track), not the dataset's."""
        return self.kind in FAULTS

    def describe(self, start: int = 0, units: str | None = None) -> str:
        u = f" {units}" if units else ""
        # A range whose samples were all solved as missing (repaired, or dropouts) has no
        # residual to give: said so, never as "nan".
        size = f"{self.worst:.3g}{u}" if np.isfinite(self.worst) else None
        span = (
            f"time code {start + self.first}"
            if self.first == self.last
            else f"time codes {start + self.first}-{start + self.last}"
        )
        if self.kind == "cut":
            return f"the whole face jumps at {span}: a cut in the take or a tracking glitch"
        if self.kind == "swap":
            a, b = self.markers
            up = f"residuals up to {size}" if size else "no residual: solved as missing"
            return f"likely label swap: {a} <-> {b}, {span} ({up})"
        if self.kind == "gap":
            return (
                f"the dataset does not follow {self.markers[0]} at {span}: "
                f"{f'up to {size}' if size else 'no residual'} (the marker moves with the "
                "face; not repaired)"
            )
        what = "spike" if self.kind == "spike" else "marker off"
        up = f"residual up to {size}" if size else "no residual: solved as missing"
        return f"{what}: {self.markers[0]}, {span} ({up})"


def _runs(flags: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Inclusive frame ranges where `flags` holds, joined across gaps of `_GAP` frames."""
    idx = np.flatnonzero(flags)
    if idx.size == 0:
        return []
    runs = [[int(idx[0]), int(idx[0])]]
    for k in idx[1:].tolist():
        if k - runs[-1][1] <= _GAP + 1:
            runs[-1][1] = k
        else:
            runs.append([k, k])
    return [(a, b) for a, b in runs]


def _above_median(vals: NDArray[np.float64], mads: float) -> float:
    """The median of `vals` plus `mads` scaled MADs (1.4826 x MAD: sigma for Gaussian values):
    every outlier limit of the findings."""
    med = float(np.median(vals))
    return med + mads * 1.4826 * float(np.median(np.abs(vals - med)))


def _threshold(r: NDArray[np.float64], size: float) -> float:
    vals = r[np.isfinite(r)]
    if vals.size == 0:
        return np.inf
    return max(_above_median(vals, OUTLIER_MADS), FLOOR * size)


def _swapped(
    x: NDArray[np.float64],
    a: int,
    b: int,
    first: int,
    last: int,
    own: tuple[tuple[int, int], tuple[int, int]] | None = None,
) -> bool:
    """Whether markers `a` and `b` trade tracks over frames first..last: at an edge of the
    range where both are seen on both sides, each one's position is nearer the other's on the
    far side than its own. `own`: each marker's own range (a, then b); where one of them is
    missing at an edge of first..last (a swap is often made where a marker drops out and is
    taken up again under the other's label), that edge is read at each marker's own edge,
    from its nearest frames seen on either side (up to `gaps.MAX_GAP` away)."""
    votes = []
    for end in (0, 1):
        inside, outside = (first, first - 1) if end == 0 else (last, last + 1)
        if not 0 <= outside < x.shape[0]:
            continue
        pa, pb, qa, qb = x[inside, a], x[inside, b], x[outside, a], x[outside, b]
        if np.isnan([pa, pb, qa, qb]).any():
            if own is None:
                continue
            near_a = _seen_across(x, a, own[0][end], end)
            near_b = _seen_across(x, b, own[1][end], end)
            if near_a is None or near_b is None:
                continue
            (pa, qa), (pb, qb) = near_a, near_b
        same = np.linalg.norm(pa - qa) + np.linalg.norm(pb - qb)
        traded = np.linalg.norm(pa - qb) + np.linalg.norm(pb - qa)
        votes.append(traded < 0.5 * same)
    return bool(votes) and all(votes)


def _seen_across(
    x: NDArray[np.float64], k: int, edge: int, end: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """Marker `k`'s positions nearest a range's edge (`end` 0: its first frame `edge`; 1: its
    last) on either side, each seen and up to `MAX_GAP` frames away: (inside, outside), or
    None where either side has none."""
    seen = np.flatnonzero(np.isfinite(x[:, k]).all(axis=1))
    if end == 0:
        ins = seen[(seen >= edge) & (seen < edge + MAX_GAP)]
        outs = seen[(seen < edge) & (seen >= edge - MAX_GAP)]
        pick = (ins[:1], outs[-1:])
    else:
        ins = seen[(seen <= edge) & (seen > edge - MAX_GAP)]
        outs = seen[(seen > edge) & (seen <= edge + MAX_GAP)]
        pick = (ins[-1:], outs[:1])
    if pick[0].size == 0 or pick[1].size == 0:
        return None
    return x[int(pick[0][0]), k], x[int(pick[1][0]), k]


JUMP_MADS = 12.0
"""How many scaled MADs above the median frame-to-frame step a marker's step must be to be a
jump (a sample leaving or rejoining its track)."""

JUMP_FLOOR = 0.02
"""Smallest jump, as a share of the face's size: 1 cm on ICT's 47.5 cm head."""

RELATIVE_JUMP_FLOOR = 0.005
"""Smallest jump of a marker against its neighbours (`relative_steps`), as a share of the
face's size (0.24 cm on ICT), read where the solve has no residual to read (a noise-free take):
the neighbours take most of fast skin's step off, and what is left of a blink or a lip is told
from a fault by the spike's shape and the take's own motion (`diagnose`)."""


FACE_SHARE = 0.1
"""Share of the markers that, jumping at one frame, make it the face's motion, not theirs."""

CUT_SHARE = 0.5
"""Share of the markers that, jumping at one frame, is reported as a cut in the take."""


def _face_moves(flags: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """(F,) the frames where more than `FACE_SHARE` of the markers (and 3) are flagged at once
    in `flags` (F, B): the face's own motion (a cut, a glitch of the head or of the
    performance), not a marker's."""
    return np.asarray(flags.sum(axis=1) > max(3, FACE_SHARE * flags.shape[1]))


def _is_spike(
    track: NDArray[np.float64], first: int, last: int, skin: NDArray[np.float64] | None = None
) -> bool:
    """Whether a marker's excursion over first..last is a spike: short, and back where it left
    (the jump back lands within half the jump away of the frame before). `skin` (F, 3): the
    marker's neighbours' motion (`skin_track`), taken off first: back where it left on the
    skin, which moved on meanwhile."""
    if last - first + 1 > SPIKE_FRAMES or first == 0 or last + 1 >= track.shape[0]:
        return False
    at = [first - 1, first, last + 1]
    before, away, back = track[at] if skin is None else track[at] - skin[at]
    if np.isnan([before, away, back]).any():
        return False
    return bool(np.linalg.norm(back - before) < 0.5 * np.linalg.norm(away - before))


def _track_ranges(
    x: NDArray[np.float64], size: float, nearest: NDArray[np.int64]
) -> dict[int, list[tuple[int, int]]]:
    """Per marker, the frame ranges it spends off its track: from a jump away to the jump
    back, read from the take alone, so an exact solve, whose residuals
    are zero, still shows them. Across a dropout the step is read against the marker's
    `nearest` neighbours' over the same frames (`relative_steps`), whole: the face moved
    for several frames, the skin between the markers barely; a label taken up again
    under another marker's name moves it by their distance."""
    f, b = x.shape[:2]
    step = np.full((f, b), np.nan)
    across = np.zeros((f, b), dtype=bool)
    for k in range(b):
        seen = np.flatnonzero(~np.isnan(x[:, k]).any(axis=1))
        if seen.size > 1:
            # Per frame elapsed for the limit's reading.
            gap = np.diff(seen).astype(np.float64)
            step[seen[1:], k] = np.linalg.norm(x[seen[1:], k] - x[seen[:-1], k], axis=1) / gap
            across[seen[1:][gap > 1], k] = True
    vals = step[np.isfinite(step)]
    if vals.size == 0:
        return {}
    limit = max(_above_median(vals, JUMP_MADS), JUMP_FLOOR * size)
    with np.errstate(invalid="ignore"):
        jumped = step > limit
        if across.any():
            jumped |= relative_steps(x, nearest, per_frame=False, only=across) > limit
    # Many markers jumping together is the whole face moving (a cut, a tracking glitch of
    # the head), not a marker leaving its track: those frames are set aside.
    count = jumped.sum(axis=1)
    jumped[_face_moves(jumped)] = False
    # Reported only when most markers jump: a fast jaw opening moves a third of them.
    out: dict[int, list[tuple[int, int]]] = {
        -1: [(int(k), int(k)) for k in np.flatnonzero(count > CUT_SHARE * b)]
    }
    for k in range(b):
        jumps = np.flatnonzero(jumped[:, k]).tolist()
        # Jumps pair up as away and back; a last jump with no return is left to the
        # residuals (one fast step of real motion must not flag the rest of the take).
        ranges = [(jumps[i], jumps[i + 1] - 1) for i in range(0, len(jumps) - 1, 2)]
        if ranges:
            out[k] = ranges
    return out


def _relative_jumps(steps: NDArray[np.float64], size: float) -> NDArray[np.bool_]:
    """(F, B) where a marker jumps against its neighbours, from `steps` (`relative_steps`, per
    frame): a step above median + `JUMP_MADS` scaled MADs of all markers' steps and
    `RELATIVE_JUMP_FLOOR` of the face's `size`. Frames where many markers jump against their
    neighbours at once (`FACE_SHARE`) are the face's own motion, and have none."""
    vals = steps[np.isfinite(steps)]
    if vals.size == 0:
        return np.zeros(steps.shape, dtype=bool)
    limit = max(_above_median(vals, JUMP_MADS), RELATIVE_JUMP_FLOOR * size)
    with np.errstate(invalid="ignore"):
        jumped: NDArray[np.bool_] = steps > limit
    jumped[_face_moves(jumped)] = False
    return jumped


def _leaves_track(
    steps: NDArray[np.float64],
    b: int,
    first: int,
    last: int,
    *,
    either: bool = False,
    noise: float | None = None,
) -> bool:
    """Whether marker `b` steps off its track relative to its neighbours both where a range of
    frames first..last begins and where it ends (the frame entering it, the frame after it;
    each within a frame, so a range read a frame long or short still meets its steps). A fault
    leaves the track and comes back to it; skin that moves fast and eases back (a blink on an
    eyelid marker) steps only once. An edge at the take's first or last frame, or without a
    step to read, is not asked. `either`: one edge's step is enough, and with the markers'
    `noise` sigma a step that noise makes once in 65,000 (`NOISE_SIGMAS` of its own sigma,
    `RELATIVE_STEP_NOISE`, as a residual must be) is a step too: the MADs of a marker's own
    steps, where its noise makes most of them, put 8 of them at 11 sigma (5.6 mm at 0.5 mm)."""
    col = steps[:, b]
    vals = col[np.isfinite(col)]
    if vals.size < 3:
        return True  # too little track to read: a fault, as before this test
    limit = _above_median(vals, STEP_MADS)
    if either and noise:
        limit = min(limit, NOISE_SIGMAS * RELATIVE_STEP_NOISE * noise)
    stepped = []
    for edge in (first, last + 1):
        if not 0 < edge < col.shape[0]:
            continue
        near = col[max(edge - 1, 0) : edge + 2]
        near = near[np.isfinite(near)]
        if near.size:
            stepped.append(bool(near.max() > limit))
    return any(stepped) if either and stepped else all(stepped)


FOLD_FRAMES = 8
"""`_take_deviations` reads the take's motion from every other block of this many frames and
predicts the blocks between: every sample is judged by motion read without it (a sample read
into the motion it is judged by looks predicted, a spike's included)."""


MOTION_FRAMES = 200
"""Frames a take needs for samples off its own motion to be ranges of their own (a spike the
solve followed): a take of 40 frames a second apart named a marker's noise a spike. Shorter takes
are still asked whether a range is off their motion (`_off_the_take`)."""


def _take_deviations(
    x: NDArray[np.float64], sigma: float, left_out: NDArray[np.bool_] | None = None
) -> NDArray[np.float64] | None:
    """(F, B) each present marker's distance from where the take's own motion puts it given the
    frame's other markers (NaN where missing), or None for a take too short to read (fewer than
    two blocks of `FOLD_FRAMES` frames) or a `sigma` that is not > 0. The take's motion is a
    Gaussian of low rank (probabilistic PCA: its directions above the noise's bulk edge at `sigma`,
    `lgi.solve.spectrum`, each with its variance less the noise's, plus white noise `sigma`),
    read from every other block of frames for the blocks between (`FOLD_FRAMES`), and each
    marker's distance is from its conditional mean given the rest, `x_b - P_bb⁻¹ (P x)_b` for
    the precision `P`; a frame's missing samples are first filled by their conditional mean
    given its present ones. Skin that moves fast, a blink, a lip the dataset cannot follow,
    still moves as the take moves elsewhere and is predicted; a spike or a marker off its track
    is not. `left_out` (F, B): samples not read into the motion (still judged): a 2 cm spike
    is a direction of its own, carried by its marker alone, which makes that marker's
    conditional ill-posed in the blocks beside it."""
    f, b = x.shape[:2]
    if f < 2 * FOLD_FRAMES or not (np.isfinite(sigma) and sigma > 0.0):
        return None
    flat = x.reshape(f, 3 * b)
    missing = np.isnan(flat)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a marker never seen: NaN, left out
        mean = np.nanmean(flat, axis=0)
    missing |= ~np.isfinite(mean)
    centred = np.where(missing, 0.0, flat - np.where(np.isfinite(mean), mean, 0.0))
    fold = (np.arange(f) // FOLD_FRAMES) % 2
    off = np.full((f, b), np.nan)
    for judged in (0, 1):
        rows = np.flatnonzero(fold == judged)
        seen = centred[fold != judged]
        if left_out is not None:
            seen = np.where(np.repeat(left_out[fold != judged], 3, axis=1), 0.0, seen)
        _, sv, vt = thin_svd(seen)
        big, small = max(seen.shape[0] - 1, 3 * b), min(seen.shape[0] - 1, 3 * b)
        keep = shrinkage_factors(sv / (np.sqrt(big) * sigma), small / big) > 0.0
        v = vt[keep[: vt.shape[0]]]
        variance = np.maximum(sv[keep] ** 2 / max(seen.shape[0] - 1, 1) - sigma**2, 0.0)
        # sigma² P = I - Vᵀ diag(w) V with w = λ / (λ + sigma²) (V's rows orthonormal).
        w = variance / (variance + sigma**2)

        def scaled_precision(z: NDArray[np.float64]) -> NDArray[np.float64]:
            return np.asarray(z - ((z @ v.T) * w) @ v)  # noqa: B023 (used in this round only)

        part = centred[rows]
        y = scaled_precision(part)
        for t in np.flatnonzero(missing[rows].any(axis=1)):
            m = np.flatnonzero(missing[rows[t]])
            vm = v[:, m]
            part[t, m] = np.linalg.solve(np.eye(m.size) - (vm.T * w) @ vm, -y[t, m])
        y = scaled_precision(part).reshape(rows.size, b, 3)
        vb = v.reshape(-1, b, 3)
        own = np.eye(3)[None] - np.einsum("kbi,k,kbj->bij", vb, w, vb)  # sigma² P_bb
        off[rows] = np.linalg.norm(np.einsum("bij,fbj->fbi", np.linalg.inv(own), y), axis=2)
    off[np.isnan(x).any(axis=2)] = np.nan
    return off


def _off_the_take(deviations: NDArray[np.float64], b: int, first: int, last: int) -> bool:
    """Whether marker `b` is off the take's own motion over frames first..last
    (`_take_deviations`) as a fault puts it: its median there above `STEP_MADS` scaled MADs over
    its median in the take, and back on the take's motion either side (under half that median,
    at the frame beside the range or the one beyond it: a range read from noisy residuals can
    end a frame short, as `_leaves_track` allows). A fault leaves the motion in one frame and
    comes back in one; skin the take does not predict (a fast lip, a blink) eases out and back
    over several. A range with no sample to read is not asked (True)."""
    col = deviations[:, b]
    vals = col[np.isfinite(col)]
    inside = col[first : last + 1]
    inside = inside[np.isfinite(inside)]
    if vals.size < 3 or inside.size == 0:
        return True
    limit = _above_median(vals, STEP_MADS)
    off = float(np.median(inside))
    back = []
    for side in ((first - 1, first - 2), (last + 1, last + 2)):
        seen = [col[k] for k in side if 0 <= k < col.size and np.isfinite(col[k])]
        if seen:
            back.append(min(seen) < 0.5 * off)
    return off > limit and all(back)


def _merge(known: list[tuple[int, int]], ranges: list[tuple[int, int]]) -> None:
    """`ranges` added to a marker's `known` runs in place; a run over the same frames is the
    same event: the two become the wider one."""
    for s0, e0 in ranges:
        overlap = [(s1, e1) for s1, e1 in known if s1 <= e0 and s0 <= e1]
        for o in overlap:
            known.remove(o)
        known.append((min([s0, *(o[0] for o in overlap)]), max([e0, *(o[1] for o in overlap)])))
    known.sort()


def _deviation_runs(
    deviations: NDArray[np.float64], size: float, noise: float
) -> dict[int, list[tuple[int, int]]]:
    """Per marker, the frame ranges where it is off the take's own motion (`_take_deviations`):
    by `OUTLIER_MADS` scaled MADs over its median there, and at least `FLOOR` of the face's
    size and `NOISE_SIGMAS` sigma (as a residual must be). A range over a frame where many
    markers are off at once (more than `FACE_SHARE` of them, and 3) is the face's own motion
    (a glitch of the performance itself), not a marker's, and is left out."""
    f, b = deviations.shape
    off = np.zeros((f, b), dtype=bool)
    for k in range(b):
        col = deviations[:, k]
        vals = col[np.isfinite(col)]
        if vals.size < 3:
            continue
        limit = max(_above_median(vals, OUTLIER_MADS), FLOOR * size, NOISE_SIGMAS * noise)
        with np.errstate(invalid="ignore"):
            off[:, k] = col > limit
    together = _face_moves(off)
    out: dict[int, list[tuple[int, int]]] = {}
    for k in range(b):
        ranges = [(s, e) for s, e in _runs(off[:, k]) if not together[s : e + 1].any()]
        if ranges:
            out[k] = ranges
    return out


def diagnose(
    residuals: ArrayLike,
    missing: ArrayLike,
    names: Sequence[str],
    *,
    size: float,
    markers: ArrayLike | None = None,
    noise: float | None = None,
) -> list[Finding]:
    """The findings of a solved take: `residuals` and `missing` (F, B), the marker `names`,
    the face's `size` (its bounding-box diagonal, in the residuals' unit) and, when known, the
    take's `markers` (F, B, 3) for the swap test and the solve's marker `noise` sigma (a
    residual under `NOISE_SIGMAS` of it is no outlier). Swaps first, then the worst first."""
    r = np.where(np.asarray(missing, dtype=bool), np.nan, np.asarray(residuals, dtype=np.float64))
    limit = max(_threshold(r, size), NOISE_SIGMAS * (noise or 0.0))
    with np.errstate(invalid="ignore"):
        out = r > limit
    runs = {b: _runs(out[:, b]) for b in range(r.shape[1])}
    # With the solve's sigma known, and one a residual could count at (`FLOOR` over
    # `NOISE_SIGMAS`), its residuals say which markers it corrected and when; the tracks' jumps
    # (motion, where frames are far apart) then serve the swap test only. Under it (a
    # noise-free take's reading, round-off) the solve interpolates its markers as the exact
    # one does, and its tracks are read as an exact solve's are.
    read_noise = (noise or 0.0) >= FLOOR * size / NOISE_SIGMAS
    residual_runs = {b: list(rs) for b, rs in runs.items()} if read_noise else None
    x = None if markers is None else np.asarray(markers, dtype=np.float64)
    face_jumps: list[Finding] = []
    nearest: NDArray[np.int64] | None = None
    if x is not None:
        nearest = nearest_markers(x)
        for b, ranges in _track_ranges(x, size, nearest).items():
            if b < 0:
                face_jumps = [Finding("cut", (), k, k, float("nan")) for k, _ in ranges]
                continue
            _merge(runs[b], ranges)
    deviations: NDArray[np.float64] | None = None
    motion_only: set[tuple[int, int, int]] = set()  # ranges the take's motion alone shows
    # The take's own motion is read at the solve's sigma, where it is one a residual could
    # count at (`FLOOR` over `NOISE_SIGMAS`): under it (a noise-free take's reading,
    # round-off) the motion read takes the face's own fast motion for faults (a lip's 0.5-1
    # mm in two frames), and without a sigma (an exact solve) it has none to read at.
    if x is not None and residual_runs is not None and noise:
        deviations = _take_deviations(x, noise)
        if deviations is not None:
            # Read again without the samples found off it (`_take_deviations`).
            off = np.zeros(r.shape, dtype=bool)
            for b, ranges in _deviation_runs(deviations, size, noise).items():
                for s, e in ranges:
                    off[s : e + 1, b] = True
            deviations = _take_deviations(x, noise, off)
        # Samples off the take's own motion are runs too, whatever the solve made of them: a
        # noise-aware solve can follow a spike (a 2 cm spike left a 1 mm residual where the
        # dataset's shapes let the marker move), the take's other markers do not.
        # Over a range the residuals or the tracks already have, only where it is itself off
        # the take's motion as a fault is (`_off_the_take`): then its edges are the fault's (a
        # solve that followed a spike's first frame starts its residuals a frame late); else
        # the range keeps its own (a marker the take's motion misses for a while before a
        # spike would move them off the spike's steps).
        # Found from the motion alone only in a take long enough to show it (`MOTION_FRAMES`).
        off_runs = (
            {}
            if deviations is None or x.shape[0] < MOTION_FRAMES
            else _deviation_runs(deviations, size, noise)
        )
        for b, ranges in off_runs.items():
            assert deviations is not None
            for s, e in ranges:
                for rs in (runs[b], residual_runs[b]):
                    if not any(s <= e1 and s1 <= e for s1, e1 in rs):
                        rs.append((s, e))
                        rs.sort()
                        motion_only.add((b, s, e))
                    elif _off_the_take(deviations, b, s, e):
                        _merge(rs, [(s, e)])
    findings: list[Finding] = []
    taken: set[tuple[int, int, int]] = set()
    swapped: list[tuple[int, int, int]] = []  # (marker, first, last) of each named swap
    if x is not None:
        flat = [(b, s, e) for b, rs in runs.items() for s, e in rs]
        for i, (a, s1, e1) in enumerate(flat):
            for b, s2, e2 in flat[i + 1 :]:
                if b == a or (a, s1, e1) in taken or (b, s2, e2) in taken:
                    continue
                lo, hi = max(s1, s2), min(e1, e2)
                if hi < lo or (hi - lo + 1) < 0.5 * (max(e1, e2) - min(s1, s2) + 1):
                    continue
                first, last = min(s1, s2), max(e1, e2)
                if _swapped(x, a, b, first, last, ((s1, e1), (s2, e2))):
                    worst = _worst(r[first : last + 1][:, [a, b]])
                    pair = tuple(sorted((names[a], names[b])))
                    findings.append(Finding("swap", pair, first, last, worst))
                    taken |= {(a, s1, e1), (b, s2, e2)}
                    swapped += [(a, first, last), (b, first, last)]
    singles = []
    steps: NDArray[np.float64] | None = None  # read on first need: most takes need none
    for b, rs in (runs if residual_runs is None else residual_runs).items():
        for s, e in rs:
            if (b, s, e) in taken or any(k == b and s <= e1 and s1 <= e for k, s1, e1 in swapped):
                continue
            backed = bool(out[s : e + 1, b].any())
            if not backed and (x is None or not _is_spike(x[:, b], s, e)):
                continue  # two unrelated steps of real motion, not a marker off its track
            kind = "spike" if e - s + 1 <= SPIKE_FRAMES else "off"
            if x is not None and nearest is not None:
                if steps is None:
                    steps = relative_steps(x, nearest)
                # Off the take's motion and back at both edges, and off the solve's surface
                # (its residuals), one step off its track is enough: the other may be lost in
                # the noise (a 5 mm spike's way back at 0.5 mm). A glitch of the performance
                # itself that the solve follows keeps needing both.
                left = deviations is not None and bool(_off_the_take(deviations, b, s, e))
                if not _leaves_track(steps, b, s, e, either=left and backed, noise=noise):
                    kind = "gap"  # the marker moves with its neighbours: the dataset's, not its
                elif deviations is not None and not left:
                    kind = "gap"  # the take moves it so elsewhere: fast skin, not a fault
            if kind == "off" and (s == 0 or e == r.shape[0] - 1):
                # A fault steps off its track and back: a range longer than a spike that runs
                # from the take's first frame or to its last shows one step at most, as a blink
                # the dataset cannot follow does (an eyelid marker, from a take's frame 0).
                kind = "gap"
            if kind == "gap" and (b, s, e) in motion_only:
                continue  # the solve followed it: no gap of the dataset's either
            singles.append(Finding(kind, (names[b],), s, e, _worst(r[s : e + 1, b])))
    if x is not None and nearest is not None and not read_noise:
        if steps is None:
            steps = relative_steps(x, nearest)
        for b, s, e in _noise_free_spikes(x, nearest, steps, size, runs):
            singles.append(Finding("spike", (names[b],), s, e, _worst(r[s : e + 1, b])))
    singles.sort(key=lambda f: -f.worst)
    if x is not None:
        assert nearest is not None
        singles = _without_echoes(findings + singles, nearest, names)[len(findings) :]
    return findings + singles + face_jumps


def _noise_free_spikes(
    x: NDArray[np.float64],
    nearest: NDArray[np.int64],
    steps: NDArray[np.float64],
    size: float,
    known: dict[int, list[tuple[int, int]]],
) -> list[tuple[int, int, int]]:
    """(marker, first, last) of each spike a noise-free take shows against the marker's
    neighbours (where the solve interpolates its markers and has no residual to read): a jump
    away from them and one back (`_relative_jumps`) over at most `SPIKE_FRAMES` frames, from a
    settled track and back to it, back where it left on the skin (`_is_spike`), stepping off
    its track at both edges (`_leaves_track`), and off the take's own motion there as a fault
    is (`_off_the_take`, the motion read at the least sigma a residual counts at, `FLOOR` over
    `NOISE_SIGMAS`, without the candidates' samples): a blink or a fast lip steps as far
    against its neighbours, and the take's other markers predict it or it eases over several
    frames. Ranges over a marker's `known` runs are not asked again."""
    jumped = _relative_jumps(steps, size)
    f = jumped.shape[0]
    candidates = []
    for b in np.flatnonzero(jumped.sum(axis=0) > 1).tolist():
        jumps: list[int] = np.flatnonzero(jumped[:, b]).tolist()
        skin: NDArray[np.float64] | None = None
        for s, after in itertools.pairwise(jumps):
            e = after - 1
            # Away from a settled track and back to it: no jump into the frame before or out
            # of the frame after (a blink's lid steps two or three frames running each way).
            settled = (s < 1 or not jumped[s - 1, b]) and (e + 2 >= f or not jumped[e + 2, b])
            if (
                e - s + 1 > SPIKE_FRAMES
                or not settled
                or any(s <= e1 and s1 <= e for s1, e1 in known[b])
            ):
                continue
            if skin is None:
                skin = skin_track(x, nearest, b)
            if _is_spike(x[:, b], s, e, skin) and _leaves_track(steps, b, s, e):
                candidates.append((b, s, e))
    if not candidates:
        return []
    left_out = np.zeros(x.shape[:2], dtype=bool)
    for b, s, e in candidates:
        left_out[s : e + 1, b] = True
    deviations = _take_deviations(x, FLOOR * size / NOISE_SIGMAS, left_out)
    if deviations is None:
        return candidates
    return [(b, s, e) for b, s, e in candidates if _off_the_take(deviations, b, s, e)]


def _without_echoes(
    found: list[Finding], nearest: NDArray[np.int64], names: Sequence[str]
) -> list[Finding]:
    """`found` less the gaps that are a fault's echo: a noise-aware solve spreads a faulty
    marker's correction to its neighbours, whose residuals then rise over the fault's frames
    without any track of theirs moving. A gap of one of a fault's `2 * NEIGHBOURS` nearest
    markers (`nearest_markers`) overlapping the fault's frames is dropped."""
    faults = [f for f in found if f.fault]
    if not faults:
        return found
    index = {n: k for k, n in enumerate(names)}
    near = nearest[:, : 2 * NEIGHBOURS]

    def echo(g: Finding) -> bool:
        k = index[g.markers[0]]
        return any(
            g.first <= f.last and f.first <= g.last and any(k in near[index[n]] for n in f.markers)
            for f in faults
        )

    return [g for g in found if g.kind != "gap" or not echo(g)]


def _worst(r: NDArray[np.float64]) -> float:
    return float(np.nanmax(r)) if np.isfinite(r).any() else float("nan")


def face_size(first_frame: ArrayLike) -> float:
    """The size findings are measured against: the solved first frame's bounding-box
    diagonal (the same whether the solve is in memory or read back from its file)."""
    v0 = np.asarray(first_frame, dtype=np.float64)
    return float(np.linalg.norm(v0.max(axis=0) - v0.min(axis=0)))


def diagnose_result(r: Result) -> list[Finding]:
    """`diagnose` of a solved take (label swaps only where it keeps the take's markers)."""
    return diagnose(
        r.bundle_residuals,
        r.missing,
        r.marker_names,
        size=face_size(r.vertices[0]),
        markers=r.markers,
        noise=None if r.settings is None else r.settings.given_noise,
    )


def finding_lines(r: Result) -> list[str]:
    """`diagnose_result`'s findings as the lines `lgi report` and `lgi view` list."""
    return [f.describe(r.start, r.units) for f in diagnose_result(r)]


def summary(
    residuals: ArrayLike,
    missing: ArrayLike,
    names: Sequence[str],
    findings: Sequence[Finding],
    *,
    start: int = 0,
    units: str | None = None,
    shown: int = 4,
) -> list[str]:
    """A few lines for `lgi solve` and `lgi info`: the residuals' median and largest (marker,
    time code), then the findings (at most `shown`)."""
    r = np.where(np.asarray(missing, dtype=bool), np.nan, np.asarray(residuals, dtype=np.float64))
    u = f" {units}" if units else ""
    if not np.isfinite(r).any():
        return ["residuals: none (every sample missing)"]
    f, b = (int(k) for k in np.unravel_index(int(np.nanargmax(r)), r.shape))
    lines = [
        f"residual median {np.nanmedian(r):.3g}{u}, 95th percentile "
        f"{np.nanpercentile(r, 95):.3g}{u}, largest {r[f, b]:.3g}{u} ({names[b]} at time code "
        f"{start + f})"
    ]
    if not any(f.fault for f in findings):
        lines.append("no marker fault (outliers off their track, spikes, label swaps)")
    for item in findings[:shown]:
        lines.append(item.describe(start, units))
    if len(findings) > shown:
        lines.append(f"... and {len(findings) - shown} more (lgi report shows them all)")
    return lines
