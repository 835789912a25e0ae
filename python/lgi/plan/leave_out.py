"""Markers left out one at a time on a few frames of a take: what the take-driven estimates
(`lgi.estimate_detail_weight`, `lgi.estimate_local_fits`, `lgi.estimate_unbounded_fit`,
`lgi.estimate_take_prior_use`) compare
their predictions on, and the looks the last two read them in."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

import lgi._lgi as _lgi
from lgi.errors import InputError

if TYPE_CHECKING:
    from lgi._lgi import SolveResult
    from lgi.solve.model import Model
    from lgi.solve.take_prior import TakePrior

__all__ = [
    "LEFT_OUT_PER_FRAME",
    "LOOKS",
    "LOOK_SIGNIFICANCE",
    "SOLVE_ROWS",
    "Comparison",
    "LeftOut",
    "Looks",
    "leave_markers_out",
    "solved_in_chunks",
    "take_frames",
]

SOLVE_ROWS = 32
"""Left-out rows solved at a time (`solved_in_chunks`). The core reports rows solved each
alone only when all are done, so Ctrl-C is seen between calls: 32 rows of ICT's markers are
~0.07 s (only their triangles sewn; whole meshes were ~0.13 s, and 400 a call held Ctrl-C
for 1.7 s)."""


LEFT_OUT_PER_FRAME = 30
"""Markers the looked-at estimates leave out, one at a time, on each frame they read (spread
over the face; every present one where a frame has fewer)."""

LOOKS = 3
"""Looks the looked-at estimates take at most, each at `frames_used` more frames (interleaved
with the others', so each look spans the take): they stop at the first whose saving is
significant (`LOOK_SIGNIFICANCE`) or negative."""

LOOK_SIGNIFICANCE = 2.33
"""The standard errors a look's mean saving must exceed: with no saving, one of `LOOKS` looks
at the cumulative frames crosses it as often as one look crosses `lgi.plan.detail.SIGNIFICANCE`
(2.3 % one-sided; Pocock's boundary for three looks, 1977; simulated in
tests/test_local_fits.py)."""


def take_frames(frames: ArrayLike, model: Model) -> NDArray[np.float64]:
    """A take's frames for `model` as float64 (F, B, 3) with F >= 1; an InputError saying the
    shape otherwise (what every take-driven estimate reads)."""
    arr = np.asarray(frames, dtype=np.float64)
    b = model.num_bundles
    if arr.ndim != 3 or arr.shape[0] == 0 or arr.shape[1:] != (b, 3):
        raise InputError(f"frames: expected shape (F, {b}, 3) with F >= 1, got {arr.shape}")
    return arr


@dataclass(frozen=True)
class LeftOut:
    """Rows of frames, each a take frame with one of its present markers left out (NaN)."""

    frames: NDArray[np.float64]
    """(R, B, 3): row r is take frame `frame[r]` without marker `marker[r]`."""
    frame: NDArray[np.int64]
    """(R,): the take frame of each row."""
    marker: NDArray[np.int64]
    """(R,): the marker left out of each row."""
    picked: NDArray[np.int64]
    """The take frames used, in order."""
    given: NDArray[np.float64]
    """(R, 3): each row's left-out marker as the take gives it."""

    def subset(self, rows: NDArray[np.int64]) -> LeftOut:
        """These rows only (their frames kept in `picked`, in order)."""
        return LeftOut(
            frames=self.frames[rows],
            frame=self.frame[rows],
            marker=self.marker[rows],
            picked=self.picked[np.isin(self.picked, self.frame[rows])],
            given=self.given[rows],
        )


@dataclass(frozen=True)
class Comparison:
    """Two solves of the same left-out rows read look by look (`Looks.compare`)."""

    use: bool
    """The option saved left-out distance significantly at one of the looks."""
    base: float
    """Mean distance of the rows read from the surface without the option."""
    option: float
    """The same with it."""
    left_out: int
    """Rows read (markers left out, one per solved frame)."""
    frames: int
    """Take frames they were left out of."""


class Looks:
    """`LOOKS` looks at the rows of a `LeftOut`: look k reads every `LOOKS`-th of its picked
    frames from the k-th, so every look spans the take."""

    def __init__(self, rows: LeftOut) -> None:
        self.left_out = rows
        self._look_of_frame = np.arange(rows.picked.size) % LOOKS
        self._look_of_row = self._look_of_frame[np.searchsorted(rows.picked, rows.frame)]

    def rows(self, look: int, *, through: bool = False) -> NDArray[np.int64]:
        """The rows look `look` reads (`through`: and every look before it)."""
        on = self._look_of_row <= look if through else self._look_of_row == look
        return np.flatnonzero(on)

    def saving(
        self, before: NDArray[np.float64], after: NDArray[np.float64], look: int
    ) -> tuple[float, float, int]:
        """The mean over the frames read through `look` of each frame's mean saving
        `before - after` (per row: NaN where not read), its standard error (NaN for one frame)
        and how many frames. Distances, as the results report errors: squared ones let a few
        markers (the lips', whose left-out errors are the largest) decide the choice."""
        seen = self.left_out.picked[self._look_of_frame <= look]
        saved = np.array([(before - after)[self.left_out.frame == f].mean() for f in seen])
        if saved.size < 2:
            return float(saved.mean()), float("nan"), int(saved.size)
        return (
            float(saved.mean()),
            float(saved.std(ddof=1) / np.sqrt(saved.size)),
            int(saved.size),
        )

    def first_clearing(
        self,
        read: Callable[[NDArray[np.int64]], None],
        before: NDArray[np.float64],
        after: NDArray[np.float64],
    ) -> int | None:
        """Reads the looks in turn (`read(rows)` fills `before` and `after` at those rows)
        until the mean per-frame saving `before - after` clears `LOOK_SIGNIFICANCE` standard
        errors (that look is returned) or is negative, or the looks run out (None)."""
        for look in range(LOOKS):
            rows = self.rows(look)
            if rows.size == 0:
                break
            read(rows)
            mean, spread, seen = self.saving(before, after, look)
            if seen < 2:
                continue
            if mean > LOOK_SIGNIFICANCE * spread:
                return look
            if mean < 0:
                break
        return None

    def compare(self, read: Callable[[NDArray[np.int64], NDArray[np.float64]], None]) -> Comparison:
        """Reads the looks (`first_clearing`) with `read(rows, err)` filling the left-out
        distances of `rows` in `err` (R, 2): column 0 without the option, column 1 with it;
        then their means over the rows read."""
        err = np.full((self.left_out.marker.size, 2), np.nan)
        look = self.first_clearing(lambda rows: read(rows, err), err[:, 0], err[:, 1])
        done = np.isfinite(err[:, 0])
        return Comparison(
            use=look is not None,
            base=float(err[done, 0].mean()),
            option=float(err[done, 1].mean()),
            left_out=int(done.sum()),
            frames=int(np.unique(self.left_out.frame[done]).size),
        )

    def distances(self, rows: NDArray[np.int64], positions: ArrayLike) -> NDArray[np.float64]:
        """Each of `rows`' left-out marker's distance from its position in `positions` (the
        rows' marker positions on a surface, (len(rows), B, 3))."""
        at = np.asarray(positions)[np.arange(rows.size), self.left_out.marker[rows]]
        return np.asarray(np.linalg.norm(at - self.left_out.given[rows], axis=1))


def leave_markers_out(
    arr: NDArray[np.float64], frames_used: int, per_frame: int | None = None, what: str = ""
) -> LeftOut:
    """Up to `frames_used` frames of `arr` (F, B, 3) spread evenly over those with at least one
    more marker present than a solve needs, and in each every present marker left out in turn
    (`per_frame`: at most that many, spread over the frame's present markers and shifted from
    frame to frame so that the frames together leave out different ones). `what` names the
    estimate in the InputError raised when no frame can spare a marker."""
    if frames_used < 1:
        raise InputError(f"frames_used must be >= 1, got {frames_used}")
    present: NDArray[np.bool_] = np.asarray(np.isfinite(arr).all(axis=2))
    usable = np.flatnonzero(present.sum(axis=1) > _lgi.MIN_PRESENT_MARKERS)
    if usable.size == 0:
        raise InputError(
            f"{what}: no frame has more than {_lgi.MIN_PRESENT_MARKERS} markers present, so "
            "none can be left out"
        )
    at = np.unique(np.linspace(0, usable.size - 1, frames_used).round().astype(int))
    picked = usable[at]
    rows: list[tuple[int, int]] = []
    for ordinal, f in enumerate(picked):
        markers = np.flatnonzero(present[f])
        n = markers.size
        if per_frame is not None and per_frame < n:
            step = n / per_frame
            shift = int(ordinal * step / len(picked))
            markers = markers[(np.floor(np.arange(per_frame) * step).astype(int) + shift) % n]
        rows += [(int(f), int(i)) for i in markers]
    frame = np.array([f for f, _ in rows], dtype=np.int64)
    marker = np.array([i for _, i in rows], dtype=np.int64)
    batch = arr[frame].copy()
    batch[np.arange(len(rows)), marker] = np.nan
    return LeftOut(
        frames=batch, frame=frame, marker=marker, picked=picked, given=arr[frame, marker]
    )


def solved_in_chunks(
    model: Model,
    rows: LeftOut,
    *,
    jaw: str | None,
    marker_noise: float | None,
    fit: bool | str | None = None,
    take_prior: TakePrior | None = None,
) -> Iterator[tuple[slice, SolveResult]]:
    """`rows`' frames solved for their markers (`Model.solve_markers`: as independent frames,
    as the take would be with `jaw`, `marker_noise`, `fit` and `take_prior`, only the
    markers' triangles sewn), `SOLVE_ROWS` at a time (threads across rows in the core): each
    chunk's rows and result."""
    for a in range(0, rows.marker.size, SOLVE_ROWS):
        part = slice(a, a + SOLVE_ROWS)
        yield (
            part,
            model.solve_markers(
                rows.frames[part],
                jaw=jaw,
                marker_noise=marker_noise,
                fit=fit,
                take_prior=take_prior,
            ),
        )
