"""How a take is solved: one `SolveOptions`, built and checked once where a solve is asked for
(`lgi solve` and `lgi batch` on the command line, `lgi.app.batch.solve_shots`, `lgi.plan_solve`
and `Model.solve` from Python) and trusted by every layer below it; the core keeps its own
invariant checks on what crosses into Rust.

An option may be 'auto': read from the take by `lgi.plan_solve`, which returns the options
resolved (`SolvePlan.options`: no 'auto' left) that `Model.solve` applies. `recommended` reads
every option left at its default. Errors name an option as its caller spells it: `--marker-noise`
on the command line, `marker_noise` from Python."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lgi.errors import InputError
from lgi.solve.take_prior import TakePrior

__all__ = ["AUTO", "JAW_MODES", "NONE", "UNBOUNDED", "SolveOptions", "local_bounds"]

AUTO = "auto"
"""An option's value that asks `lgi.plan_solve` to read it from the take."""

NONE = "none"
"""`marker_noise` or `detail_weight` given as none: with `recommended`, kept as given (no noise,
all of the detail) where an option left at None is read from the take; otherwise None."""

UNBOUNDED = "unbounded"
"""`fit=UNBOUNDED`, `local_fits=UNBOUNDED`: weights not held to [0, 1]. The box is a FACS rig's
prior (a weight is an activation); a scan's weight is no activation: a face, or a window of it,
is matched by differences of scans as well as by sums (docs/concepts.md)."""

JAW_MODES = ("auto", "fit", "track")
"""How each frame's jaw pose is found (`Model.solve`); None: the rest pose."""

# The command line's spelling of each option, for its error messages.
_FLAGS = {
    "marker_noise": "--marker-noise",
    "denoise": "--denoise",
    "fit": "--unbounded-fit",
    "local_fits": "--local-fits",
    "take_prior": "--take-prior",
    "detail_weight": "--detail-weight",
    "jaw": "--jaw",
    "recommended": "--recommended",
    "steady": "--no-steady",
    "repair": "--no-repair",
}


def local_bounds(spec: bool | str) -> bool | None:
    """What a checked `local_fits` asks for: None (no local fits), True (weights held to [0, 1]
    by the fit's penalty) or False (`UNBOUNDED`)."""
    if spec is True:
        return True
    return False if spec == UNBOUNDED else None


@dataclass(frozen=True)
class SolveOptions:
    """How a take is solved. Each field as `Model.solve` names it:

    - `marker_noise`: the markers' noise sigma >= 0 (model units), 'auto' (estimated from the
      take) or None (every marker interpolated exactly);
    - `denoise`: denoise the take by its own low-rank motion first (`lgi.denoise_take`); True,
      False or 'auto' (where its noise is above 0);
    - `fit`: the frame's global fit: None (the default), True (offered), False (none),
      'unbounded' (weights not held to [0, 1]) or 'auto' (unbounded where the take says so);
    - `local_fits`: False, True, 'unbounded' or 'auto' (`lgi.solve.local`);
    - `take_prior`: a `TakePrior`, True (read from the take), 'auto' (read, and used where the
      take says so) or False;
    - `detail_weight`: a weight in [0, 1], 'auto' or None (all of the dataset's detail);
    - `jaw`: one of `JAW_MODES`, or None for the rest pose;
    - `recommended`: read every option left at its default from the take;
    - `steady`: in a temporal solve, dropouts filled from the take and the detail averaged over
      neighbouring frames (`lgi.solve.gaps`, `lgi.solve.steady`); False solves each frame from
      its own markers alone (frames that are not a take's consecutive frames);
    - `repair`: in a steady solve, the marker faults it shows repaired and the take solved
      again (`lgi.solve.repair`); False keeps the markers as given;
    - `fault_noise`: the noise sigma of the markers as the take gave them, which a repair
      reads faults at (None: `marker_noise`). A plan of a denoised take sets it to the noise
      before denoising, as `lgi solve` reads the given markers: a denoised take's own small
      sigma made a blink the dataset cannot follow (1 mm on an eyelid) a fault.

    Built from the command line with `from_cli` (strings as typed); `cli` only changes how
    errors name the options."""

    marker_noise: float | str | None = None
    denoise: bool | str = False
    fit: bool | str | None = None
    local_fits: bool | str = False
    take_prior: TakePrior | bool | str = False
    detail_weight: float | str | None = None
    jaw: str | None = "auto"
    recommended: bool = False
    steady: bool = True
    repair: bool = True
    fault_noise: float | None = None
    cli: bool = field(default=False, compare=False, repr=False)

    def __post_init__(self) -> None:
        put = object.__setattr__
        put(self, "recommended", self._flag("recommended", self.recommended))
        put(self, "steady", self._flag("steady", self.steady))
        put(self, "repair", self._flag("repair", self.repair))
        put(self, "marker_noise", self._noise(self.marker_noise))
        put(self, "fault_noise", self._fault_noise(self.fault_noise))
        put(self, "detail_weight", self._weight(self.detail_weight))
        put(self, "denoise", self._flag_or_auto("denoise", self.denoise))
        put(self, "fit", self._fit(self.fit))
        put(self, "local_fits", self._local_fits(self.local_fits))
        put(self, "take_prior", self._prior(self.take_prior))
        if self.jaw is not None and self.jaw not in JAW_MODES:
            modes = ", ".join(repr(m) for m in JAW_MODES)
            raise InputError(f"{self._name('jaw')} must be {modes} or None, got {self.jaw!r}")
        self._check_together()

    # --- building --------------------------------------------------------------------------

    @classmethod
    def from_cli(cls, args: Any) -> SolveOptions:
        """The options of `lgi solve` / `lgi batch` from their parsed arguments (`--jaw rest`
        is None; `--unbounded-fit` is `fit`)."""
        fit: bool | str | None = None
        if args.unbounded_fit:
            fit = AUTO if args.unbounded_fit == AUTO else UNBOUNDED
        return cls(
            marker_noise=args.marker_noise,
            denoise=args.denoise,
            fit=fit,
            local_fits=args.local_fits,
            take_prior=args.take_prior,
            detail_weight=args.detail_weight,
            jaw=None if args.jaw == "rest" else args.jaw,
            recommended=args.recommended,
            steady=args.steady,
            repair=args.repair,
            cli=True,
        )

    @classmethod
    def given(
        cls, options: SolveOptions | None, keywords: dict[str, Any], where: str
    ) -> SolveOptions:
        """The options a call was given, as `options` or as keywords (not both), built once;
        an unknown keyword is an InputError naming `where` and the options there are."""
        if options is not None:
            if keywords:
                raise InputError(f"{where}: give the solve options as options= or as keywords")
            if not isinstance(options, SolveOptions):
                raise InputError(
                    f"{where}: options must be an lgi.SolveOptions, got {type(options).__name__}"
                )
            return options
        known = {f.name for f in dataclasses.fields(cls)} - {"cli"}
        unknown = sorted(set(keywords) - known)
        if unknown:
            raise InputError(
                f"{where}: unknown solve options {unknown} (it takes {', '.join(sorted(known))})"
            )
        return cls(**keywords)

    def replace(self, **changes: Any) -> SolveOptions:
        """These options with `changes` (checked again)."""
        return dataclasses.replace(self, **changes)

    # --- what they ask for -----------------------------------------------------------------

    @property
    def solve_noise(self) -> float | None:
        """The marker noise sigma the solve applies: `marker_noise` as a number (None: the
        exact interpolation, or not yet read from the take)."""
        sigma = self.marker_noise
        return float(sigma) if isinstance(sigma, (int, float)) else None

    @property
    def given_noise(self) -> float | None:
        """The markers' noise sigma as the take gave them, which faults are read and dropouts
        filled at: `fault_noise`, else `marker_noise` (None: no number for it)."""
        if self.fault_noise is not None:
            return self.fault_noise
        return self.solve_noise

    @property
    def resolved(self) -> bool:
        """Nothing left to read from a take: what `Model.solve` applies."""
        read = (self.marker_noise, self.fit, self.local_fits, self.take_prior, self.detail_weight)
        return (
            not self.recommended
            and self.denoise is False
            and self.take_prior is not True
            and AUTO not in read
        )

    def check_resolved(self) -> None:
        """An InputError where an option is still to be read from a take (`lgi.plan_solve`)."""
        if self.resolved:
            return
        raise InputError(
            "Model.solve applies options as they are: 'auto', recommended, denoise and "
            "take_prior=True are read from a take by lgi.plan_solve (solve its plan: "
            "model.solve(plan.frames, options=plan.options))"
        )

    def local_fits_without_noise(self) -> InputError:
        """The error of local fits asked without a marker noise (given, or with `recommended`
        none read): they fit the noise-aware targets."""
        if self.cli:
            return InputError(
                "--local-fits needs --marker-noise (SIGMA or auto; 0 for clean markers): the "
                "local fits fit the noise-aware targets"
            )
        return InputError(
            "local_fits needs marker_noise (the noise-aware solve's targets and global fits; "
            "marker_noise=0 for clean markers)"
        )

    def check_model(self, jaw_bins: bool) -> None:
        """An InputError where local fits are asked of a model with jaw bins."""
        if jaw_bins and self.local_fits is not False:
            raise InputError(
                f"{self._name('local_fits')}: the model has jaw bins (each bin fits its own "
                "re-posed shapes); build it without jaw_bins"
            )

    def record(self) -> dict[str, Any]:
        """The options given, as plain values (a batch manifest hashes them): every field that
        is not its default, by its `Model.solve` name."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            if f.name == "cli":
                continue
            value = getattr(self, f.name)
            if value != f.default:
                out[f.name] = value
        return out

    # --- checks ----------------------------------------------------------------------------

    def _name(self, option: str) -> str:
        # An option the command line does not take (`fault_noise`) is named as Python names it.
        return _FLAGS.get(option, option) if self.cli else option

    def _given_none(self, value: Any) -> bool:
        return isinstance(value, str) and value == NONE

    def _noise(self, value: Any) -> float | str | None:
        if value is None:
            return None
        if self._given_none(value):
            return NONE if self.recommended else None
        if value == AUTO:
            return AUTO
        what = "a number (data units), 'auto' or 'none'"
        sigma = self._number("marker_noise", value, what)
        if not math.isfinite(sigma) or sigma < 0:
            if self.cli:
                raise InputError(f"--marker-noise {value}: must be a finite number >= 0")
            raise InputError(
                f"marker_noise must be a finite distance >= 0 (data units), got {value}"
            )
        return sigma

    def _fault_noise(self, value: Any) -> float | None:
        if value is None:
            return None
        sigma = self._number("fault_noise", value, "a number (data units) or None")
        if not math.isfinite(sigma) or sigma < 0:
            raise InputError(
                f"fault_noise must be a finite distance >= 0 (data units), got {value}"
            )
        return sigma

    def _weight(self, value: Any) -> float | str | None:
        if value is None:
            return None
        if self._given_none(value):
            return NONE if self.recommended else None
        if value == AUTO:
            return AUTO
        what = "a number in [0, 1], 'auto' or 'none'"
        w = self._number("detail_weight", value, what)
        if not 0.0 <= w <= 1.0:
            if self.cli:
                raise InputError(f"--detail-weight {value}: must be a number in [0, 1]")
            raise InputError(f"detail_weight: expected a number in [0, 1], got {value}")
        return w

    def _number(self, option: str, value: Any, what: str) -> float:
        try:
            if isinstance(value, (bool, np.bool_)):
                raise TypeError
            return float(value)
        except (TypeError, ValueError):
            if self.cli:
                raise InputError(f"{self._name(option)} {value!r}: expected {what}") from None
            if option == "marker_noise":
                raise InputError(f"marker_noise must be {what}, got {value!r}") from None
            raise InputError(f"{option}: expected {what}, got {value!r}") from None

    def _flag(self, option: str, value: Any) -> bool:
        if not isinstance(value, (bool, np.bool_)):
            raise InputError(f"{self._name(option)} must be True or False, got {value!r}")
        return bool(value)

    def _flag_or_auto(self, option: str, value: Any) -> bool | str:
        if value == AUTO and not isinstance(value, (bool, np.bool_)):
            return AUTO
        if not isinstance(value, (bool, np.bool_)):
            raise InputError(
                f"{self._name(option)} must be True or False (or 'auto'), got {value!r}"
            )
        return bool(value)

    def _fit(self, value: Any) -> bool | str | None:
        if value is None or isinstance(value, (bool, np.bool_)):
            return None if value is None else bool(value)
        if value in (UNBOUNDED, AUTO):
            return str(value)
        raise InputError(
            f"fit must be True, False, None, {UNBOUNDED!r} or 'auto' (read from the take), got "
            f"{value!r}"
        )

    def _local_fits(self, value: Any) -> bool | str:
        if isinstance(value, (bool, np.bool_)):
            return bool(value)
        if value in (UNBOUNDED, AUTO):
            return str(value)
        raise InputError(
            f"{self._name('local_fits')} must be True, False, {UNBOUNDED!r} or 'auto' (read from "
            f"the take), got {value!r}"
        )

    def _prior(self, value: Any) -> TakePrior | bool | str:
        if value is None:
            return False
        if isinstance(value, TakePrior):
            return value
        return self._flag_or_auto_prior(value)

    def _flag_or_auto_prior(self, value: Any) -> bool | str:
        if isinstance(value, (bool, np.bool_)):
            return bool(value)
        if value == AUTO:
            return AUTO
        raise InputError(
            f"take_prior must be True, False or 'auto' (or an lgi.TakePrior, "
            f"lgi.estimate_take_prior), got {value!r}"
        )

    def _check_together(self) -> None:
        """What no take can change: options that cannot be given together."""
        local = self.local_fits
        if local and self.marker_noise is None and not self.recommended:
            raise self.local_fits_without_noise()
        if local and self.fit is False:
            raise InputError("local_fits needs the global fit: do not pass fit=False")
        noise = self.marker_noise
        if self.denoise is True and not self.recommended and noise in (None, 0.0):
            if self.cli:
                raise InputError(
                    "--denoise needs the markers' noise above 0: pass --marker-noise SIGMA or auto"
                )
            raise InputError(
                "denoise needs marker_noise above 0 (a number or 'auto'): there is nothing to "
                "remove"
            )
        if isinstance(self.take_prior, TakePrior) and UNBOUNDED not in (self.fit, local):
            raise InputError(
                "take_prior is a prior on the unbounded global fit: solve with fit='unbounded' or "
                "local_fits='unbounded'"
            )
