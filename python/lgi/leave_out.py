"""Markers left out one at a time on a few frames of a take: what the take-driven estimates
(`lgi.estimate_detail_weight`, `lgi.estimate_local_fits`) compare their predictions on."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

import lgi._lgi as _lgi
from lgi.errors import InputError

if TYPE_CHECKING:
    from lgi._lgi import SolveResult
    from lgi.model import Model

__all__ = ["SOLVE_ROWS", "LeftOut", "leave_markers_out", "solved_in_chunks"]

SOLVE_ROWS = 32
"""Left-out rows solved at a time (`solved_in_chunks`): their meshes are dropped between
(960 rows of ICT's mesh would take 615 MB)."""


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
) -> Iterator[tuple[slice, SolveResult]]:
    """`rows`' frames solved as independent frames (`temporal=False`, as the take would be
    with `jaw`, `marker_noise` and `fit`), `SOLVE_ROWS` at a time: each chunk's rows and
    result."""
    for a in range(0, rows.marker.size, SOLVE_ROWS):
        part = slice(a, a + SOLVE_ROWS)
        yield (
            part,
            model.solve(
                rows.frames[part],
                temporal=False,
                jaw=jaw,
                marker_noise=marker_noise,
                fit=fit,
                quiet=True,
            ),
        )
