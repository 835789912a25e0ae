"""Whether a take gains by its own prior on the unbounded fit (`lgi.plan.take_prior`,
`--take-prior auto`), read from its own markers left out: each row solved by the unbounded fit
without the prior and with the prior read from the take's other frames, without the row's
left-out marker (`HeldOutPriors`), on the take's shared readings (`lgi.plan.readings`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi.plan.detail import DETAIL_FRAMES
from lgi.plan.leave_out import LEFT_OUT_PER_FRAME, LOOKS, Looks
from lgi.plan.readings import TakeReadings
from lgi.plan.take_prior import estimate_take_prior
from lgi.solve.local import UNBOUNDED
from lgi.solve.take_prior import TakePrior

if TYPE_CHECKING:
    from lgi.solve.model import Model

__all__ = ["TakePriorEstimate", "estimate_take_prior_use"]


@dataclass(frozen=True)
class TakePriorEstimate:
    """Whether the take's prior predicts a take's left-out markers better
    (`estimate_take_prior_use`)."""

    use: bool
    """It saved left-out distance by more than `LOOK_SIGNIFICANCE` standard errors at one of
    the looks."""
    error_without: float
    """Mean distance (data units) of the left-out markers from the solve's surface without
    them, with the unbounded fit and no prior (NaN: not read)."""
    error_with: float
    """The same with the prior (read from the take's other frames)."""
    left_out: int
    """Markers left out (one per solved frame)."""
    frames: int
    """Take frames they were left out of."""
    prior: TakePrior | None
    """The prior from the whole take where it is used, else None."""


def estimate_take_prior_use(
    frames: ArrayLike,
    model: Model,
    *,
    marker_noise: float,
    jaw: str | None = "auto",
    frames_used: int = DETAIL_FRAMES,
    readings: TakeReadings | None = None,
) -> TakePriorEstimate:
    """Whether a take (F, B, 3; NaN rows missing) is better solved by `model` with the take's
    prior on its unbounded fit, read from its own markers: on `frames_used` frames spread over
    the take (more at each of up to `LOOKS` looks), up to `LEFT_OUT_PER_FRAME` present markers
    each are left out in turn and predicted by the unbounded solve with `marker_noise` and
    `jaw`, once without the prior and once with the prior read from the take's other frames
    (none of the frames left out from, and without the row's left-out marker in any frame,
    `HeldOutPriors`, so no left-out marker informs its prior; a take with fewer than 2 such
    frames is not read). Used as the looks' rule says (`Looks.first_clearing`); then the prior
    is read from the whole take. `readings`: the take's readings to share rows and solves with
    (made for this call where not given)."""
    nan = float("nan")
    if not (np.isfinite(marker_noise) and marker_noise > 0.0):
        return TakePriorEstimate(False, nan, nan, 0, 0, None)
    r = TakeReadings.given(readings, frames, model, marker_noise=marker_noise, jaw=jaw)
    key = (LOOKS * frames_used, LEFT_OUT_PER_FRAME)
    out = r.left_out(*key, what="take prior")
    if r.held_out_priors(*key) is None:
        return TakePriorEstimate(False, nan, nan, 0, 0, None)
    looks = Looks(out)

    def read(rows: NDArray[np.int64], err: NDArray[np.float64]) -> None:
        """The left-out distances of `rows`: without the prior (column 0) and with it (1)."""
        without = r.solved(*key, rows, fit=UNBOUNDED)
        err[rows, 0] = looks.distances(rows, without.bundle_positions)
        with_it = r.solved(*key, rows, fit=UNBOUNDED, held_out_prior=True)
        err[rows, 1] = looks.distances(rows, with_it.bundle_positions)

    read_out = looks.compare(read)
    return TakePriorEstimate(
        use=read_out.use,
        error_without=read_out.base,
        error_with=read_out.option,
        left_out=read_out.left_out,
        frames=read_out.frames,
        prior=estimate_take_prior(model, r.frames, marker_noise, jaw=jaw) if read_out.use else None,
    )
