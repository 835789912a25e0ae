"""A take's prior on its frames' global fit, as a solve applies it: `w = mean + factor @ v`,
`v ~ N(0, I)`, per frame with that frame's rows (dropouts included). How it is read from a take
(empirical Bayes) is `lgi.plan.take_prior`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["TakePrior"]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class TakePrior:
    """The prior on a take's global-fit weights: `w = mean + factor @ v`, `v ~ N(0, I)`.

    `mean` (S,) and `factor` (S, q) are in the dataset's shape weights; `noise` the markers' sigma
    (data units, per coordinate) it was read with; `directions` the fit's directions at the
    markers (q's ceiling), `kept` the directions the take moves in above its noise (q), and
    `frames` the frames it was read from."""

    mean: F64
    factor: F64
    noise: float
    directions: int
    frames: int

    @property
    def kept(self) -> int:
        return int(self.factor.shape[1])

    def as_core(self) -> tuple[F64, F64, float]:
        """The core's `take_prior` argument: (mean, factor, noise variance)."""
        return self.mean, self.factor, self.noise**2
