"""Whether a take is better solved with the unbounded global fit (`Model.solve(fit="unbounded")`,
`--unbounded-fit auto`), read from its own markers.

The box on the fit's weights is a FACS rig's prior; a dataset of whole-face scans has none, and
a TD does not always know which a dataset is (a set of scans with FACS names, an actor rig built
from scans). The take's markers, left out one at a time, say it the way they say whether local
fits pay (`lgi.estimate_local_fits`, the same rows and looks): the solve with the boxed fit and
the solve with the unbounded one each predict every left-out marker, and the unbounded fit is
used when the distance it saves, averaged per frame, clears `LOOK_SIGNIFICANCE` standard
errors. docs/concepts.md explains it; docs/results.md says what it chose on the protocols'
takes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi.plan.detail import DETAIL_FRAMES
from lgi.plan.leave_out import LEFT_OUT_PER_FRAME, LOOKS, Looks
from lgi.plan.readings import TakeReadings
from lgi.solve.local import UNBOUNDED

if TYPE_CHECKING:
    from lgi.solve.model import Model

__all__ = ["UnboundedFitEstimate", "estimate_unbounded_fit"]


@dataclass(frozen=True)
class UnboundedFitEstimate:
    """Whether the unbounded global fit predicts a take's left-out markers better
    (`estimate_unbounded_fit`)."""

    use: bool
    """It saved left-out distance by more than `LOOK_SIGNIFICANCE` standard errors at one of
    the looks."""
    error_boxed: float
    """Mean distance (data units) of the left-out markers from the solve's surface without
    them, the fit held to [0, 1]."""
    error_unbounded: float
    """The same with the unbounded fit."""
    left_out: int
    """Markers left out (one per solved frame)."""
    frames: int
    """Take frames they were left out of (`frames_used` a look)."""

    @property
    def fit(self) -> str | None:
        """What to pass as `Model.solve(fit=...)`: `UNBOUNDED` or None (the default)."""
        return UNBOUNDED if self.use else None


def estimate_unbounded_fit(
    frames: ArrayLike,
    model: Model,
    *,
    marker_noise: float | None,
    jaw: str | None = "auto",
    frames_used: int = DETAIL_FRAMES,
    take_prior: bool = False,
    readings: TakeReadings | None = None,
) -> UnboundedFitEstimate:
    """Whether a take (F, B, 3; NaN rows missing) is better solved by `model` with the unbounded
    global fit, read from its own markers: on `frames_used` frames spread over the take, up to
    `LEFT_OUT_PER_FRAME` present markers each are left out in turn and predicted by the solve
    with `marker_noise` and `jaw` without them, once with the fit held to [0, 1] and once
    unbounded. The unbounded fit is used when the left-out distance it saves, averaged per
    frame, exceeds `LOOK_SIGNIFICANCE` standard errors of that mean over the frames read; when
    it does not and the saving is positive, `frames_used` more frames are read, up to `LOOKS`
    looks. Each look solves about `frames_used` x 30 frames twice. With `take_prior` (and a
    `marker_noise` > 0) the unbounded fit is read as it would be solved with the take's prior
    (`lgi.plan.take_prior`), each row's prior read without its left-out marker from the take's
    frames none of the markers is left out of (`lgi.plan.take_prior.HeldOutPriors`).
    `readings`: the take's readings to share rows and solves with (made for this call where
    not given)."""
    r = TakeReadings.given(readings, frames, model, marker_noise=marker_noise, jaw=jaw)
    key = (LOOKS * frames_used, LEFT_OUT_PER_FRAME)
    out = r.left_out(*key, what="unbounded fit")
    held = take_prior and bool(marker_noise) and r.held_out_priors(*key) is not None
    looks = Looks(out)

    def read(rows: NDArray[np.int64], err: NDArray[np.float64]) -> None:
        """The left-out distances of `rows`, solved boxed (column 0) and unbounded (1)."""
        err[rows, 0] = looks.distances(rows, r.solved(*key, rows).bundle_positions)
        unbounded = r.solved(*key, rows, fit=UNBOUNDED, held_out_prior=held)
        err[rows, 1] = looks.distances(rows, unbounded.bundle_positions)

    read_out = looks.compare(read)
    return UnboundedFitEstimate(
        use=read_out.use,
        error_boxed=read_out.base,
        error_unbounded=read_out.option,
        left_out=read_out.left_out,
        frames=read_out.frames,
    )
