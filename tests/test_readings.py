"""The take's readings as one stage (`lgi.plan.readings`): each left-out row and each solve of
it made once and shared by every reading, with the same numbers as each reading made alone."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import lgi
from lgi.errors import InputError
from lgi.plan.leave_out import LEFT_OUT_PER_FRAME, LOOKS
from lgi.plan.readings import TakeReadings
from test_take_prior import SIGMA, two_directions  # noqa: F401  (the fixture)


def _counting(monkeypatch: pytest.MonkeyPatch, model: Any) -> list[tuple[bytes, Any, bool]]:
    """Every row each `Model.solve_markers` (the readings' solve) solves: its markers (bytes),
    its fit and whether it had a take prior."""
    calls: list[tuple[bytes, Any, bool]] = []
    solve = type(model).solve_markers

    def counted(self: Any, frames: Any, *args: Any, **kw: Any) -> Any:
        fit, prior = kw.get("fit"), kw.get("take_prior") is not None
        calls.extend((np.asarray(f).tobytes(), fit, prior) for f in frames)
        return solve(self, frames, *args, **kw)

    monkeypatch.setattr(type(model), "solve_markers", counted)
    return calls


def test_shared_readings_give_each_readings_own_numbers(two_directions: Any) -> None:  # noqa: F811
    """The unbounded fit (with the take prior) and the take prior's reading, made on one
    `TakeReadings` one after the other, read the same distances as each made alone."""
    model, frames, _, _ = two_directions
    kw: dict[str, Any] = {"marker_noise": SIGMA, "frames_used": 2}
    alone_fit = lgi.estimate_unbounded_fit(frames, model, take_prior=True, **kw)
    alone_prior = lgi.estimate_take_prior_use(frames, model, **kw)
    shared = TakeReadings(frames, model, marker_noise=SIGMA, jaw="auto")
    fit = lgi.estimate_unbounded_fit(frames, model, take_prior=True, readings=shared, **kw)
    prior = lgi.estimate_take_prior_use(frames, model, readings=shared, **kw)
    assert fit == alone_fit
    assert (prior.use, prior.error_without, prior.error_with) == (
        alone_prior.use,
        alone_prior.error_without,
        alone_prior.error_with,
    )


def test_a_row_is_solved_once_per_variant_however_many_readings_read_it(
    two_directions: Any,  # noqa: F811
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Local fits, the unbounded fit with the take prior and the take prior's reading (twice)
    on one `TakeReadings`: no row is solved twice the same way, and the held-out priors are
    each read once."""
    model, frames, _, _ = two_directions
    kw: dict[str, Any] = {"marker_noise": SIGMA, "frames_used": 2}
    shared = TakeReadings(frames, model, marker_noise=SIGMA, jaw="auto")
    calls = _counting(monkeypatch, model)
    lgi.estimate_local_fits(frames, model, readings=shared, **kw)
    lgi.estimate_unbounded_fit(frames, model, take_prior=True, readings=shared, **kw)
    held = shared.held_out_priors(LOOKS * 2, LEFT_OUT_PER_FRAME)
    assert held is not None
    priors = dict(held._priors)
    lgi.estimate_take_prior_use(frames, model, readings=shared, **kw)
    before = len(calls)
    lgi.estimate_take_prior_use(frames, model, readings=shared, **kw)
    assert len(calls) == before > 0  # the second reading solves nothing
    assert len(set(calls)) == len(calls)  # no row solved twice the same way
    assert {fit for _, fit, _ in calls} == {None, "unbounded"}  # boxed and unbounded both read
    assert all(held._priors[k] is v for k, v in priors.items())  # no prior read again


def test_readings_made_for_another_noise_or_jaw_are_refused_in_our_words(
    two_directions: Any,  # noqa: F811
) -> None:
    model, frames, _, _ = two_directions
    shared = TakeReadings(frames, model, marker_noise=SIGMA, jaw="auto")
    with pytest.raises(InputError, match=r"readings: made for another .*noise"):
        lgi.estimate_take_prior_use(frames, model, marker_noise=2 * SIGMA, readings=shared)
    with pytest.raises(InputError, match=r"jaw None vs|jaw 'auto' vs None"):
        lgi.estimate_local_fits(frames, model, marker_noise=SIGMA, jaw=None, readings=shared)
