"""What a take is solved as: each solve option as given or read from the take itself (the
markers' noise, denoising, the global fit's box, local fits, the take's prior, the detail
weight), said in one line each, and `--recommended`, which reads every one of them. `lgi
solve` and `lgi batch` both plan a solve here (`plan_solve`); error messages name the CLI's
options, which the parameters mirror. docs/concepts.md explains each reading and
docs/results.md measures the recommended plan against the strongest peers."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from lgi.errors import InputError
from lgi.io.settings import SolveSettings
from lgi.plan.denoise import DenoisedTake, denoise_take
from lgi.plan.detail import estimate_detail_weight
from lgi.plan.local import estimate_local_fits
from lgi.plan.noise import estimate_marker_noise
from lgi.plan.readings import TakeReadings
from lgi.plan.take_prior import estimate_take_prior
from lgi.plan.take_prior_use import estimate_take_prior_use
from lgi.plan.unbounded import estimate_unbounded_fit
from lgi.solve.model import Model
from lgi.solve.options import AUTO, NONE, UNBOUNDED, SolveOptions
from lgi.solve.take_prior import TakePrior

__all__ = [
    "RECOMMENDED",
    "SolvePlan",
    "detail_weight",
    "marker_noise",
    "plan_solve",
]

Say = Callable[[str], None]

RECOMMENDED = (
    "--recommended: every choice read from the take (marker noise, denoising, the fit's box, "
    "local fits, the take prior, the detail weight)"
)
"""What `--recommended` says before its readings."""


def _silent(_message: str) -> None:
    """A `say` that says nothing."""


def fits_choice(
    local: bool | str,
    unbounded: bool | str,
    frames: np.ndarray,
    model: Model,
    sigma: float | None,
    jaw: str | None,
    say: Say,
    prior: TakePrior | bool | str = False,
    readings: TakeReadings | None = None,
) -> tuple[bool | str, bool]:
    """`--local-fits` and `--unbounded-fit` as given or read from the take (`local_fits_choice`,
    `unbounded_fit_choice`): `local_fits` and whether the global fit is unbounded. When both
    are 'auto', the local fits are read first, on the boxed solve (bounded, then unbounded ones
    with the unbounded fit they start from): unbounded ones chosen bring the unbounded fit,
    bounded ones keep the box, and with neither the unbounded fit is read on its own
    (docs/concepts.md). Otherwise the fit is decided first and the local fits read on it.
    With `prior` (`--take-prior`, given or 'auto') the unbounded fit is read as it would be
    solved, with the take's prior. `readings`: the take's left-out readings, shared by every
    reading (`lgi.plan.readings`)."""
    if local == "auto" and unbounded == "auto":
        chosen = local_fits_choice(local, frames, model, sigma, jaw, say, readings=readings)
        if chosen:
            return chosen, chosen == UNBOUNDED
        free = unbounded_fit_choice(unbounded, frames, model, sigma, jaw, say, prior, readings)
        return False, free
    free = unbounded_fit_choice(unbounded, frames, model, sigma, jaw, say, prior, readings)
    fit = UNBOUNDED if free else None
    chosen = local_fits_choice(local, frames, model, sigma, jaw, say, fit, readings)
    # Unbounded local fits start from the unbounded fit whatever was asked of the fit.
    return chosen, free or chosen == UNBOUNDED


def unbounded_fit_choice(
    spec: bool | str,
    frames: np.ndarray,
    model: Model,
    sigma: float | None,
    jaw: str | None,
    say: Say,
    prior: TakePrior | bool | str = False,
    readings: TakeReadings | None = None,
) -> bool:
    """`--unbounded-fit`: True, False or 'auto' (read from the take's own markers left out,
    `lgi.estimate_unbounded_fit`, and said with its numbers; with `prior`, the unbounded fit
    with the take's prior, as it would be solved)."""
    if spec is True or spec is False:
        return spec
    with_prior = bool(prior) and sigma is not None and sigma > 0.0
    est = estimate_unbounded_fit(
        frames, model, marker_noise=sigma, jaw=jaw, take_prior=with_prior, readings=readings
    )
    which = " (with the take prior)" if with_prior else ""
    say(
        _reading(
            f"unbounded fit{which} {'used' if est.use else 'not used'}",
            est.left_out,
            est.frames,
            f"{est.error_unbounded:.4g}",
            model,
            "it",
            f"{est.error_boxed:.4g} with the fit held to [0, 1]",
        )
    )
    return est.use


def _reading(
    what: str, left_out: int, frames: int, near: str, model: Model, them: str, other: str
) -> str:
    """The line a left-out reading says: `what` (the choice), how many markers were left out on
    how many frames, their distance `near` from the surface with `them` (the option read) in
    the model's units, and `other`, the distance without it."""
    unit = model.units or "model units"
    return (
        f"{what}: {left_out} markers left out one at a time on {frames} frames are {near} "
        f"{unit} from the surface with {them}, {other}"
    )


def take_prior_choice(
    spec: TakePrior | bool | str,
    frames: np.ndarray,
    model: Model,
    sigma: float | None,
    jaw: str | None,
    say: Say,
    unbounded: bool,
    readings: TakeReadings | None = None,
) -> TakePrior | None:
    """`--take-prior`: a `TakePrior` (used as it is), True, False or 'auto' (read from the take's
    own markers left out, `lgi.estimate_take_prior_use`, and said with its numbers), on the
    unbounded fit (`unbounded`, as chosen) and with the markers' noise `sigma`: the prior to solve
    with, or None."""
    if spec is False:
        return None
    if isinstance(spec, TakePrior):
        return spec
    noisy = sigma is not None and sigma > 0.0
    if spec is True:
        if not unbounded:
            raise InputError(
                "--take-prior is a prior on the unbounded global fit: add --unbounded-fit (or "
                "--local-fits unbounded)"
            )
        if not noisy:
            raise InputError(
                "--take-prior needs the markers' noise: --marker-noise with a distance > 0 "
                "or auto (noise-free markers need no prior)"
            )
        assert sigma is not None
        prior = estimate_take_prior(model, frames, sigma, jaw=jaw)
        say(f"take prior: {prior.kept} of {prior.directions} directions move above the noise")
        return prior
    if not unbounded or not noisy:
        if not unbounded:
            why = "the fit is held to [0, 1]"
        elif sigma is None:
            why = "no --marker-noise (every marker interpolated as given)"
        else:
            why = "the markers are noise-free"
        say(f"take prior not read: {why}")
        return None
    assert sigma is not None
    est = estimate_take_prior_use(frames, model, marker_noise=sigma, jaw=jaw, readings=readings)
    if est.left_out == 0:
        say("take prior not used: the take is too short to read it on frames of its own")
        return None
    kept = "" if est.prior is None else f" ({est.prior.kept} of {est.prior.directions} directions)"
    say(
        _reading(
            f"take prior {'used' if est.use else 'not used'}{kept}",
            est.left_out,
            est.frames,
            f"{est.error_with:.4g}",
            model,
            "it",
            f"{est.error_without:.4g} without",
        )
    )
    return est.prior


def local_fits_choice(
    spec: bool | str,
    frames: np.ndarray,
    model: Model,
    sigma: float | None,
    jaw: str | None,
    say: Say,
    fit: str | None = None,
    readings: TakeReadings | None = None,
) -> bool | str:
    """`--local-fits`: True, False, 'unbounded' or 'auto' (read from the take's own markers
    left out, `lgi.estimate_local_fits` with `fit`, and said with its numbers). Needs the
    markers' noise `sigma` (`SolveOptions` and `plan_solve` see to it)."""
    if spec is True or spec is False or spec == UNBOUNDED:
        return spec
    assert sigma is not None
    est = estimate_local_fits(
        frames, model, marker_noise=sigma, jaw=jaw, fit=fit, readings=readings
    )
    chosen = {False: "not used", True: "used", UNBOUNDED: "used, unbounded"}[est.local_fits]
    read = [
        f"{x:.4g}{kind}"
        for x, kind in ((est.error_with, " (bounded)"), (est.error_unbounded, " (unbounded)"))
        if np.isfinite(x)
    ]
    say(
        _reading(
            f"local fits {chosen}",
            est.left_out,
            est.frames,
            " and ".join(read),
            model,
            "them",
            f"{est.error_without:.4g} without",
        )
    )
    return est.local_fits


def detail_weight(
    spec: float | str | None,
    frames: np.ndarray,
    model: Model,
    sigma: float | None,
    jaw: str | None,
    fit: str | None = None,
) -> float | None:
    """`--detail-weight` as checked (`SolveOptions`): a weight in [0, 1], 'auto' (read from
    `frames` solved with `sigma`, `jaw` and `fit`, `lgi.estimate_detail_weight`) or None/'none'
    (all of the dataset's detail)."""
    if spec is None or spec == NONE:
        return None
    if spec == AUTO:
        return estimate_detail_weight(frames, model, marker_noise=sigma, jaw=jaw, fit=fit)
    return float(spec)


def marker_noise(spec: float | str | None, frames: np.ndarray, model: Model | None) -> float | None:
    """`--marker-noise` as checked (`SolveOptions`): a sigma >= 0 (model units), 'auto'
    (estimated from `frames`, bounded by what `model`'s fit leaves at the markers) or
    None/'none' (exact interpolation)."""
    if spec is None or spec == NONE:
        return None
    if spec == AUTO:
        return estimate_marker_noise(frames, model)
    return float(spec)


def take_denoised(
    asked: bool | str, frames: np.ndarray, sigma: float | None, say: Say
) -> DenoisedTake | None:
    """`--denoise`: the take denoised by its own low-rank structure (`lgi.denoise_take`) with
    the marker noise `sigma`, said in one line; None when not asked. An InputError without a
    marker noise above 0 (there is nothing to remove); with `asked` 'auto' (`--recommended`)
    such a take is solved as given, and said so."""
    if asked is False:
        return None
    if sigma is None or sigma <= 0.0:
        if asked == AUTO:
            why = "no marker noise" if sigma is None else "the markers' noise is 0"
            say(f"not denoised: {why} (nothing to remove)")
            return None
        why = "no marker noise is given" if sigma is None else "the markers read as noise-free"
        raise InputError(f"--denoise: {why}, so there is nothing to remove; solve without it")
    den = denoise_take(frames, sigma)
    say(
        f"denoised the take: {den.rank} of {den.directions} directions of motion kept, "
        f"marker noise {sigma:.4g} -> {den.marker_noise:.4g}"
    )
    return den


@dataclass(frozen=True)
class SolvePlan:
    """What a take is solved as (`plan_solve`): `frames` (the given markers, or the take
    denoised), the noise `given_noise` of the given markers, the take `denoised` (or None) and
    the solve's `options`, resolved: each as given or read from the take. The solve is
    `model.solve(plan.frames, options=plan.options)`."""

    frames: np.ndarray
    given_noise: float | None
    denoised: DenoisedTake | None
    options: SolveOptions

    @property
    def marker_noise(self) -> float | None:
        """The noise of the markers solved (what denoising left, where the take was)."""
        sigma = self.options.marker_noise
        return None if sigma is None else float(sigma)

    @property
    def local_fits(self) -> bool | str:
        return self.options.local_fits

    @property
    def unbounded_fit(self) -> bool:
        return self.options.fit == UNBOUNDED

    @property
    def fit(self) -> str | None:
        """The global fit as the readings solved it: 'unbounded' or None (boxed)."""
        return UNBOUNDED if self.unbounded_fit else None

    @property
    def take_prior(self) -> TakePrior | None:
        prior = self.options.take_prior
        return prior if isinstance(prior, TakePrior) else None

    @property
    def detail_weight(self) -> float | None:
        w = self.options.detail_weight
        return None if w is None else float(w)

    @property
    def jaw(self) -> str | None:
        return self.options.jaw

    def summary(self) -> str:
        """The plan in one line: the noise (and what denoising left), the fit, the local fits,
        the take prior and the detail weight."""
        noise = "none" if self.given_noise is None else f"{self.given_noise:.4g}"
        if self.denoised is not None:
            noise += f" -> {self.marker_noise:.4g} (denoised, {self.denoised.rank} directions)"
        local = {False: "none", True: "bounded", UNBOUNDED: "unbounded"}[self.local_fits]
        return (
            f"noise {noise}; fit {'unbounded' if self.unbounded_fit else 'boxed'}; local fits "
            f"{local}; take prior {'yes' if self.take_prior is not None else 'no'}; detail "
            f"weight {'-' if self.detail_weight is None else f'{self.detail_weight:.3f}'}"
        )

    def settings(self, *, has_jaw_rig: bool) -> SolveSettings:
        """The settings a solve of this plan records in its output."""
        return SolveSettings.of(
            has_jaw_rig=has_jaw_rig,
            jaw=self.jaw,
            marker_noise=self.marker_noise,
            detail_weight=self.detail_weight,
            local_fits=self.local_fits,
            unbounded_fit=self.unbounded_fit,
            take_prior=self.take_prior is not None,
            denoised=self.denoised,
            steady=self.options.steady,
        )


def plan_solve(
    frames: np.ndarray,
    model: Model,
    options: SolveOptions | None = None,
    *,
    say: Say = _silent,
    **given: Any,
) -> SolvePlan:
    """The plan of a solve of `frames` (F, B, 3) with `model` and `options` (a `SolveOptions`,
    or its fields as keywords `given`): the markers' noise (`marker_noise`), then denoising
    (`take_denoised`; 'auto': where that noise is above 0), then the fit and local fits
    (`fits_choice`), the take prior (`take_prior_choice`) and the detail weight
    (`detail_weight`), each read on what is solved.

    `recommended` reads every option left at its default from the take: the noise, denoising,
    the fit, local fits and the take prior ('auto' each), and the detail weight where no local
    fits are used (local fits chosen say the dataset suits the take around each marker; the
    detail weight is for a dataset that does not: docs/concepts.md). Options given keep their
    values ('none' included); local fits are not read for a model with jaw bins."""
    options = SolveOptions.given(options, given, "plan_solve")
    options.check_model(model.jaw_bins is not None)
    o = options
    noise, denoise, local_fits, take_prior, detail = (
        o.marker_noise,
        o.denoise,
        o.local_fits,
        o.take_prior,
        o.detail_weight,
    )
    unbounded_fit: bool | str = AUTO if o.fit == AUTO else o.fit == UNBOUNDED
    if o.recommended:
        say(RECOMMENDED)
        noise = AUTO if noise is None else noise
        denoise = AUTO if denoise is False else denoise
        if local_fits is False and model.jaw_bins is None:
            local_fits = AUTO
        unbounded_fit = AUTO if unbounded_fit is False else unbounded_fit
        take_prior = AUTO if take_prior is False else take_prior
    given_noise = marker_noise(noise, frames, model)
    if o.recommended and noise == AUTO:
        say(f"marker noise read from the take: {given_noise:.4g}")
    den = take_denoised(denoise, frames, given_noise, say)
    x, sigma = (frames, given_noise) if den is None else (den.frames, den.marker_noise)
    if o.recommended and sigma is None and local_fits == AUTO:
        say("local fits not read: no marker noise (every marker interpolated as given)")
        local_fits = False
    if local_fits and sigma is None:
        raise o.local_fits_without_noise()
    # One stage of left-out readings for every choice read from the take (each row and solve
    # made once, lgi.plan.readings).
    readings = None
    if AUTO in (local_fits, unbounded_fit, take_prior) and sigma is not None:
        readings = TakeReadings(x, model, marker_noise=sigma, jaw=o.jaw)
    chosen, free = fits_choice(
        local_fits, unbounded_fit, x, model, sigma, o.jaw, say, take_prior, readings
    )
    unbounded = free or chosen == UNBOUNDED
    prior = take_prior_choice(take_prior, x, model, sigma, o.jaw, say, unbounded, readings)
    fit = UNBOUNDED if free else None
    if o.recommended and detail is None:
        if chosen:
            say("detail weight not read: local fits are used (the dataset suits the take)")
            weight = None
        else:
            weight = detail_weight(AUTO, x, model, sigma, o.jaw, fit)
            say(f"detail weight read from the take: {weight:.3f}")
    else:
        weight = detail_weight(detail, x, model, sigma, o.jaw, fit)
    # `fit` True or False (offered, or none) as given where the fit is not unbounded.
    solved_fit = UNBOUNDED if free else (None if o.fit in (AUTO, UNBOUNDED) else o.fit)
    return SolvePlan(
        frames=x,
        given_noise=given_noise,
        denoised=den,
        options=SolveOptions(
            marker_noise=sigma,
            fit=solved_fit,
            local_fits=chosen,
            take_prior=False if prior is None else prior,
            detail_weight=weight,
            jaw=o.jaw,
            steady=o.steady,
            repair=o.repair,
            # A denoised take's faults are read at its given noise, as `lgi solve` reads them.
            fault_noise=given_noise if den is not None else None,
        ),
    )
