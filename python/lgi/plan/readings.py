"""A take's left-out readings as one stage: the take's markers left out one at a time and every
solve of those rows that a choice reads, each made once and shared.

`--recommended` reads several choices from the same left-out rows (`lgi.plan.local`,
`lgi.plan.unbounded`, `lgi.plan.take_prior`): the boxed solve is the local fits' base and the
unbounded fit's first column, the unbounded solve is the unbounded local fits' start and the
take prior's base, and the held-out priors (one per left-out marker, each read from the whole
take) serve both the unbounded fit's and the take prior's reading. `TakeReadings` holds the
take, its rows and each solve variant's rows as far as they have been read; a reading asks for
rows and only those not yet solved are solved, all of them together. A row is solved alone
(`temporal=False`), so a row shared is the same bits as a row solved again."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi.errors import InputError
from lgi.plan.leave_out import LeftOut, leave_markers_out, solved_in_chunks, take_frames
from lgi.plan.take_prior import HeldOutPriors

if TYPE_CHECKING:
    from lgi.solve.model import Model

F64 = NDArray[np.float64]

__all__ = ["Solved", "TakeReadings"]


@dataclass(frozen=True)
class Solved:
    """What the readings keep of each row's solve: the fields of its `SolveResult` they read
    (`lgi.solve.local.LocalPieces.at_bundles` reads all four), one row each."""

    bundle_positions: F64
    """(n, B, 3): the markers' positions on the solved surface."""
    missing: NDArray[np.bool_]
    """(n, B): the row's missing markers (its left-out one among them)."""
    fit_weights: F64 | None
    """(n, S): each row's global fit (None: a solve without one)."""
    jaw_theta: F64 | None
    """(n, 3): each row's jaw pose (None: no jaw rig)."""


class _Variant:
    """One way of solving a `LeftOut`'s rows, filled in as rows are read."""

    def __init__(self, rows: int, bundles: int) -> None:
        self.done = np.zeros(rows, dtype=bool)
        self.positions = np.full((rows, bundles, 3), np.nan)
        self.missing = np.zeros((rows, bundles), dtype=bool)
        self.weights: F64 | None = None
        self.theta: F64 | None = None

    def keep(self, rows: NDArray[np.int64], res: Any) -> None:
        """`res` (a `SolveResult` of `rows`, in order) kept."""
        self.positions[rows] = np.asarray(res.bundle_positions)
        self.missing[rows] = np.asarray(res.missing)
        if res.fit_weights is not None:
            w = np.asarray(res.fit_weights, dtype=np.float64)
            if self.weights is None:
                self.weights = np.full((self.done.size, w.shape[1]), np.nan)
            self.weights[rows] = w
        if res.jaw_theta is not None:
            t = np.asarray(res.jaw_theta, dtype=np.float64)
            if self.theta is None:
                self.theta = np.full((self.done.size, 3), np.nan)
            self.theta[rows] = t
        self.done[rows] = True

    def of(self, rows: NDArray[np.int64]) -> Solved:
        return Solved(
            bundle_positions=self.positions[rows],
            missing=self.missing[rows],
            fit_weights=None if self.weights is None else self.weights[rows],
            jaw_theta=None if self.theta is None else self.theta[rows],
        )


class TakeReadings:
    """A take's left-out readings (module text): the take as float64 (F, B, 3), the marker
    noise and jaw it is solved with, its `LeftOut` rows per (frames, markers per frame) asked
    for, the held-out priors per rows, and each solve variant's rows as far as read."""

    def __init__(
        self, frames: ArrayLike, model: Model, *, marker_noise: float | None, jaw: str | None
    ) -> None:
        self.model = model
        self.frames = take_frames(frames, model)
        self.marker_noise = None if marker_noise is None else float(marker_noise)
        self.jaw = jaw
        self._left_out: dict[tuple[int, int | None], LeftOut] = {}
        self._variants: dict[tuple[int, int | None, str | None, bool], _Variant] = {}
        self._held: dict[tuple[int, int | None], HeldOutPriors | None] = {}

    @classmethod
    def given(
        cls,
        readings: TakeReadings | None,
        frames: ArrayLike,
        model: Model,
        *,
        marker_noise: float | None,
        jaw: str | None,
    ) -> TakeReadings:
        """`readings` where given (an InputError unless made for `model`, `marker_noise` and
        `jaw`: a reading reads them as they were made, and `frames` is theirs), else new ones
        of `frames`."""
        if readings is None:
            return cls(frames, model, marker_noise=marker_noise, jaw=jaw)
        noise = None if marker_noise is None else float(marker_noise)
        if model is not readings.model or noise != readings.marker_noise or jaw != readings.jaw:
            raise InputError(
                "readings: made for another model, marker noise or jaw than this reading's "
                f"(noise {readings.marker_noise} vs {noise}, jaw {readings.jaw!r} vs {jaw!r})"
            )
        return readings

    def left_out(self, frames_used: int, per_frame: int | None, what: str) -> LeftOut:
        """The take's markers left out one at a time on `frames_used` frames, at most
        `per_frame` a frame (`leave_markers_out`; made once per pair)."""
        key = (frames_used, per_frame)
        made = self._left_out.get(key)
        if made is None:
            made = leave_markers_out(self.frames, frames_used, per_frame, what=what)
            self._left_out[key] = made
        return made

    def held_out_priors(self, frames_used: int, per_frame: int | None) -> HeldOutPriors | None:
        """The take priors the rows of `left_out(frames_used, per_frame)` are solved with
        (`lgi.plan.take_prior.HeldOutPriors`, each read once), or None (a take with fewer than
        2 frames no row leaves a marker out of, or no marker noise above 0)."""
        key = (frames_used, per_frame)
        if key not in self._held:
            sigma = self.marker_noise
            held = None
            if sigma:
                out = self._left_out[key]
                held = HeldOutPriors.of(self.model, self.frames, out, sigma, self.jaw)
            self._held[key] = held
        return self._held[key]

    def solved(
        self,
        frames_used: int,
        per_frame: int | None,
        rows: NDArray[np.int64],
        *,
        fit: str | None = None,
        held_out_prior: bool = False,
    ) -> Solved:
        """`rows` of `left_out(frames_used, per_frame)` solved as the take would be (its noise
        and jaw), with `fit` (None: boxed; `UNBOUNDED`) and, with `held_out_prior`, each row
        with the take prior read without its left-out marker (`held_out_priors`: needs one).
        Rows not solved before in this variant are solved now, together."""
        out = self._left_out[(frames_used, per_frame)]
        key = (frames_used, per_frame, fit, held_out_prior)
        variant = self._variants.get(key)
        if variant is None:
            variant = _Variant(out.marker.size, self.frames.shape[1])
            self._variants[key] = variant
        todo = rows[~variant.done[rows]]
        if todo.size:
            if held_out_prior:
                held = self.held_out_priors(frames_used, per_frame)
                if held is None:
                    raise InputError("readings: no held-out take prior for these rows")
                for mine, res in held.solved(
                    self.model, out, todo, jaw=self.jaw, marker_noise=self.marker_noise
                ):
                    variant.keep(mine, res)
            else:
                for at, res in solved_in_chunks(
                    self.model,
                    out.subset(todo),
                    jaw=self.jaw,
                    marker_noise=self.marker_noise,
                    fit=fit,
                ):
                    variant.keep(todo[at], res)
        return variant.of(rows)
