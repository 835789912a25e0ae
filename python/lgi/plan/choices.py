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

from lgi.denoise import DenoisedTake, denoise_take
from lgi.detail import estimate_detail_weight
from lgi.errors import InputError
from lgi.io.settings import SolveSettings
from lgi.local import UNBOUNDED, estimate_local_fits
from lgi.model import Model
from lgi.noise import estimate_marker_noise
from lgi.take_prior import TakePrior, estimate_take_prior, estimate_take_prior_use
from lgi.unbounded import estimate_unbounded_fit

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


def check_local_fits_noise(spec: bool | str, sigma: float | str | None) -> None:
    """`--local-fits` (on or 'auto') without `--marker-noise`: an InputError saying why."""
    if spec and sigma is None:
        raise InputError(
            "--local-fits needs --marker-noise (SIGMA or auto; 0 for clean markers): the local "
            "fits fit the noise-aware targets"
        )


def fits_choice(
    local: bool | str,
    unbounded: bool | str,
    frames: np.ndarray,
    model: Model,
    sigma: float | None,
    jaw: str | None,
    say: Say,
    prior: bool | str = False,
) -> tuple[bool | str, bool]:
    """`--local-fits` and `--unbounded-fit` as given or read from the take (`local_fits_choice`,
    `unbounded_fit_choice`): `local_fits` and whether the global fit is unbounded. When both
    are 'auto', the local fits are read first, on the boxed solve (bounded, then unbounded ones
    with the unbounded fit they start from): unbounded ones chosen bring the unbounded fit,
    bounded ones keep the box, and with neither the unbounded fit is read on its own
    (docs/concepts.md). Otherwise the fit is decided first and the local fits read on it.
    With `prior` (`--take-prior`, given or 'auto') the unbounded fit is read as it would be
    solved, with the take's prior."""
    if local == "auto" and unbounded == "auto":
        chosen = local_fits_choice(local, frames, model, sigma, jaw, say)
        if chosen:
            return chosen, chosen == UNBOUNDED
        return False, unbounded_fit_choice(unbounded, frames, model, sigma, jaw, say, prior)
    free = unbounded_fit_choice(unbounded, frames, model, sigma, jaw, say, prior)
    chosen = local_fits_choice(local, frames, model, sigma, jaw, say, UNBOUNDED if free else None)
    # Unbounded local fits start from the unbounded fit whatever was asked of the fit.
    return chosen, free or chosen == UNBOUNDED


def unbounded_fit_choice(
    spec: bool | str,
    frames: np.ndarray,
    model: Model,
    sigma: float | None,
    jaw: str | None,
    say: Say,
    prior: bool | str = False,
) -> bool:
    """`--unbounded-fit`: True, False or 'auto' (read from the take's own markers left out,
    `lgi.estimate_unbounded_fit`, and said with its numbers; with `prior`, the unbounded fit
    with the take's prior, as it would be solved)."""
    if spec is True or spec is False:
        return spec
    if spec != "auto":
        raise InputError(f"--unbounded-fit {spec!r}: expected no value or 'auto'")
    with_prior = bool(prior) and sigma is not None and sigma > 0.0
    est = estimate_unbounded_fit(frames, model, marker_noise=sigma, jaw=jaw, take_prior=with_prior)
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
    spec: bool | str,
    frames: np.ndarray,
    model: Model,
    sigma: float | None,
    jaw: str | None,
    say: Say,
    unbounded: bool,
) -> TakePrior | None:
    """`--take-prior`: True, False or 'auto' (read from the take's own markers left out,
    `lgi.estimate_take_prior_use`, and said with its numbers), on the unbounded fit
    (`unbounded`, as chosen) and with the markers' noise `sigma`: the prior to solve with, or
    None."""
    if spec is False:
        return None
    if spec is not True and spec != "auto":
        raise InputError(f"--take-prior {spec!r}: expected no value or 'auto'")
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
    est = estimate_take_prior_use(frames, model, marker_noise=sigma, jaw=jaw)
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
) -> bool | str:
    """`--local-fits`: True, False, 'unbounded' or 'auto' (read from the take's own markers
    left out, `lgi.estimate_local_fits` with `fit`, and said with its numbers)."""
    check_local_fits_noise(spec, sigma)
    if spec is True or spec is False or spec == UNBOUNDED:
        return spec
    if spec != "auto":
        raise InputError(f"--local-fits {spec!r}: expected no value, 'unbounded' or 'auto'")
    assert sigma is not None  # checked above
    est = estimate_local_fits(frames, model, marker_noise=sigma, jaw=jaw, fit=fit)
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
    spec: str | float | None,
    frames: np.ndarray,
    model: Model,
    sigma: float | None,
    jaw: str | None,
    fit: str | None = None,
) -> float | None:
    """`--detail-weight`: a weight in [0, 1], 'auto' (read from `frames` solved with `sigma`,
    `jaw` and `fit`, `lgi.estimate_detail_weight`) or 'none'/None (all of the dataset's
    detail)."""
    if spec is None or spec == "none":
        return None
    if spec == "auto":
        return estimate_detail_weight(frames, model, marker_noise=sigma, jaw=jaw, fit=fit)
    try:
        w = float(spec)
    except ValueError:
        raise InputError(
            f"--detail-weight {spec!r}: expected a number in [0, 1], 'auto' or 'none'"
        ) from None
    if not 0.0 <= w <= 1.0:
        raise InputError(f"--detail-weight {spec}: must be a number in [0, 1]")
    return w


def marker_noise(spec: str | float | None, frames: np.ndarray, model: Model | None) -> float | None:
    """`--marker-noise`: a sigma >= 0 (model units), 'auto' (estimated from `frames`, bounded
    by what `model`'s fit leaves at the markers) or 'none'/None (exact interpolation)."""
    if spec is None or spec == "none":
        return None
    if spec == "auto":
        return estimate_marker_noise(frames, model)
    try:
        sigma = float(spec)
    except ValueError:
        raise InputError(
            f"--marker-noise {spec!r}: expected a number (data units), 'auto' or 'none'"
        ) from None
    if not np.isfinite(sigma) or sigma < 0:
        raise InputError(f"--marker-noise {spec}: must be a finite number >= 0")
    return sigma


def take_denoised(
    asked: bool | str, frames: np.ndarray, sigma: float | None, say: Say
) -> DenoisedTake | None:
    """`--denoise`: the take denoised by its own low-rank structure (`lgi.denoise_take`) with
    the marker noise `sigma`, said in one line; None when not asked. An InputError without a
    marker noise above 0 (there is nothing to remove); with `asked` 'auto' (`--recommended`)
    such a take is solved as given, and said so."""
    if asked is False:
        return None
    if asked not in (True, "auto"):
        raise InputError(f"--denoise {asked!r}: expected no value or 'auto'")
    if sigma is None or sigma <= 0.0:
        if asked == "auto":
            why = "no marker noise" if sigma is None else "the markers' noise is 0"
            say(f"not denoised: {why} (nothing to remove)")
            return None
        raise InputError(
            "--denoise needs the markers' noise above 0: pass --marker-noise SIGMA or auto"
        )
    den = denoise_take(frames, sigma)
    say(
        f"denoised the take: {den.rank} of {den.directions} directions of motion kept, "
        f"marker noise {sigma:.4g} -> {den.marker_noise:.4g}"
    )
    return den


@dataclass(frozen=True)
class SolvePlan:
    """What a take is solved as (`plan_solve`): `frames` (the given markers, or the take
    denoised), the noise `given_noise` of the given markers and `marker_noise` of those
    solved, and the solve's options as given or read from the take. The solve is
    `model.solve(plan.frames, **plan.solve_options())`."""

    frames: np.ndarray
    given_noise: float | None
    denoised: DenoisedTake | None
    marker_noise: float | None
    local_fits: bool | str
    unbounded_fit: bool
    take_prior: TakePrior | None
    detail_weight: float | None
    jaw: str | None = "auto"

    @property
    def fit(self) -> str | None:
        """`Model.solve`'s `fit`: "unbounded" or None (the default, boxed fit)."""
        return UNBOUNDED if self.unbounded_fit else None

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

    def solve_options(self) -> dict[str, Any]:
        """`Model.solve`'s keywords for this plan (with `frames`: the solve)."""
        return {
            "jaw": self.jaw,
            "marker_noise": self.marker_noise,
            "detail_weight": self.detail_weight,
            "local_fits": self.local_fits,
            "fit": self.fit,
            "take_prior": self.take_prior,
        }

    def settings(self, *, has_jaw_rig: bool, jaw: str | None) -> SolveSettings:
        """The settings a solve of this plan records in its output."""
        return SolveSettings.of(
            has_jaw_rig=has_jaw_rig,
            jaw=jaw,
            marker_noise=self.marker_noise,
            detail_weight=self.detail_weight,
            local_fits=self.local_fits,
            unbounded_fit=self.unbounded_fit,
            take_prior=self.take_prior is not None,
            denoised=self.denoised,
        )


def plan_solve(
    frames: np.ndarray,
    model: Model,
    *,
    noise: str | float | None = None,
    denoise: bool | str = False,
    local_fits: bool | str = False,
    unbounded_fit: bool | str = False,
    take_prior: bool | str = False,
    detail: str | float | None = None,
    jaw: str | None = "auto",
    recommended: bool = False,
    say: Say = _silent,
) -> SolvePlan:
    """The plan of a solve of `frames` (F, B, 3) with `model`: `noise` (`marker_noise`), then
    `denoise` (`take_denoised`; 'auto': where that noise is above 0), then the fit and local
    fits (`fits_choice`), the take prior (`take_prior_choice`) and the detail weight
    (`detail_weight`), each read on what is solved. `jaw` is `Model.solve`'s jaw mode.

    `recommended` (`--recommended`) reads every option left at its default from the take:
    the noise, denoising, the fit, local fits and the take prior ('auto' each), and the detail
    weight where no local fits are used (local fits chosen say the dataset suits the take
    around each marker; the detail weight is for a dataset that does not: docs/concepts.md).
    Options given keep their values; local fits are not read for a model with jaw bins."""
    if recommended:
        say(RECOMMENDED)
        noise = "auto" if noise is None else noise
        denoise = "auto" if denoise is False else denoise
        if local_fits is False and model.jaw_bins is None:
            local_fits = "auto"
        unbounded_fit = "auto" if unbounded_fit is False else unbounded_fit
        take_prior = "auto" if take_prior is False else take_prior
    given_noise = marker_noise(noise, frames, model)
    if recommended and noise == "auto":
        say(f"marker noise read from the take: {given_noise:.4g}")
    den = take_denoised(denoise, frames, given_noise, say)
    x, sigma = (frames, given_noise) if den is None else (den.frames, den.marker_noise)
    if recommended and sigma is None and local_fits == "auto":
        say("local fits not read: no marker noise (every marker interpolated as given)")
        local_fits = False
    check_local_fits_noise(local_fits, sigma)
    if local_fits and model.jaw_bins is not None:
        raise InputError("--local-fits: the model has jaw bins; build it without them")
    chosen, free = fits_choice(local_fits, unbounded_fit, x, model, sigma, jaw, say, take_prior)
    prior = take_prior_choice(take_prior, x, model, sigma, jaw, say, free or chosen == UNBOUNDED)
    fit = UNBOUNDED if free else None
    if recommended and detail is None:
        if chosen:
            say("detail weight not read: local fits are used (the dataset suits the take)")
            weight = None
        else:
            weight = detail_weight("auto", x, model, sigma, jaw, fit)
            say(f"detail weight read from the take: {weight:.3f}")
    else:
        weight = detail_weight(detail, x, model, sigma, jaw, fit)
    return SolvePlan(
        frames=x,
        given_noise=given_noise,
        denoised=den,
        marker_noise=sigma,
        local_fits=chosen,
        unbounded_fit=free,
        take_prior=prior,
        detail_weight=weight,
        jaw=jaw,
    )
