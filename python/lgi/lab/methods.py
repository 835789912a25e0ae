"""The methods the protocols compare: LGI's calls (as `lgi solve` plans them: `Recommended`,
`AsRecommended`, on denoised markers) and the peers a TD has (`lgi.lab.baselines`: the rig
solve with the jaw as a joint and its residual corrective), by name."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi._lgi import JawRig, SolveResult
from lgi.data.dataset import Dataset
from lgi.errors import InputError, LgiWarning
from lgi.lab.baselines import FitJaw, FitJawResidual, FitJawUnbounded, FitJawUnboundedResidual
from lgi.lab.scoring import Solver
from lgi.plan.choices import SolvePlan, plan_solve
from lgi.plan.denoise import denoise_take
from lgi.plan.noise import estimate_marker_noise
from lgi.solve.local import UNBOUNDED
from lgi.solve.model import Model

F64 = NDArray[np.float64]
Row = dict[str, Any]


def default_methods(dataset: Dataset, markers: ArrayLike) -> dict[str, Solver]:
    """The four compared methods (LGI and LGI-RBF share one built model)."""
    from lgi.lab.baselines import BlendshapeFit, DisplacementInterpolation, LgiRbf

    lgi_rbf = LgiRbf(dataset, markers)
    return {
        DisplacementInterpolation.label: DisplacementInterpolation(dataset, markers),
        BlendshapeFit.label: BlendshapeFit(dataset, markers),
        LgiRbf.label: lgi_rbf,
        "LGI": lgi_rbf.model,
    }


class Recommended:
    """LGI's recommended path as a compared method: `model.solve(frames, marker_noise=sigma)`
    on a model built with defaults (`sigma` None: the paper's exact mode). With `detail`
    "auto", the frames' detail weight (`lgi.estimate_detail_weight`, read from the frames
    solved, with the same sigma) is kept too, the call for a performer the dataset is not
    (`last_detail_weight` says which); with `local_fits`, the pieces are local fits
    (`lgi.plan.local`); `fit` is `Model.solve`'s (e.g. "unbounded"); with `take_prior`, the
    unbounded fit takes the prior read from the frames solved (`lgi.estimate_take_prior`); with
    `denoise`, the frames are first denoised by the take's own low-rank structure
    (`lgi.denoise_take`) and solved with the noise it leaves. The steps are `lgi.plan_solve`'s
    with these options given (as `lgi solve` takes them)."""

    def __init__(
        self,
        model: Model,
        marker_noise: float | None,
        detail: str | None = None,
        local_fits: bool | str = False,
        fit: str | None = None,
        take_prior: bool = False,
        denoise: bool = False,
    ) -> None:
        if fit not in (None, UNBOUNDED):
            raise InputError(f"fit: expected None or {UNBOUNDED!r}, got {fit!r}")
        self.model, self.marker_noise, self.detail = model, marker_noise, detail
        self.local_fits, self.fit, self.take_prior = local_fits, fit, take_prior
        self.denoise = denoise
        self.last_detail_weight: float | None = None

    def solve(
        self, frames: ArrayLike, *, temporal: bool = True, steady: bool = True, quiet: bool = True
    ) -> SolveResult:
        # The plan `lgi solve` makes with these options given (one definition of the steps).
        plan = plan_solve(
            np.asarray(frames, dtype=np.float64),
            self.model,
            marker_noise=self.marker_noise,
            denoise=self.denoise,
            local_fits=self.local_fits,
            fit=self.fit,
            take_prior=self.take_prior,
            detail_weight=self.detail,
        )
        if self.detail == "auto":
            self.last_detail_weight = plan.detail_weight
        return self.model.solve(
            plan.frames,
            temporal=temporal,
            quiet=quiet,
            options=plan.options.replace(steady=steady),
        )


#: The name of LGI with local fits (`Model.solve(local_fits=True)`) among compared methods.
LOCAL_FITS = "LGI + local fits"


#: The same with unbounded local fits (`Model.solve(local_fits="unbounded")`, which start from
#: the unbounded global fit).
LOCAL_FITS_UNBOUNDED = "LGI + local fits (unbounded)"


#: LGI's recommended call with the unbounded global fit (`Model.solve(fit="unbounded")`).
UNBOUNDED_FIT = "LGI (unbounded fit)"


#: The same with the take's prior on the unbounded fit (`lgi.estimate_take_prior`).
TAKE_PRIOR = "LGI (take prior)"


#: Unbounded local fits from the unbounded fit with the take's prior.
LOCAL_FITS_TAKE_PRIOR = "LGI + local fits (take prior)"


#: LGI's recommended call (and with local fits) on the take denoised by its own low-rank
#: structure (`lgi.denoise_take`): bounded where the protocol's LGI is (FACS shapes), with the
#: unbounded fit and unbounded local fits in the scans protocol.
DENOISED = "LGI (denoised)"


LOCAL_FITS_DENOISED = "LGI + local fits (denoised)"


#: A peer's name when it is given the same denoised markers (not a peer a TD has: it says how
#: much of a denoised method's gain is the denoising's).
DENOISED_PEER = "{} on denoised markers"


#: The peers a TD has (`lgi.lab.baselines`): the rig solve with the jaw as a joint and its residual
#: corrective, boxed and (the scans protocol's) unbounded.
PEER_NAMES = (
    FitJaw.label,
    FitJawResidual.label,
    FitJawUnbounded.label,
    FitJawUnboundedResidual.label,
)


class OnDenoised:
    """A compared method given the take denoised by `lgi.denoise_take` with `sigma`."""

    def __init__(self, method: Solver, sigma: float) -> None:
        self.method, self.sigma = method, sigma

    def solve(
        self, frames: ArrayLike, *, temporal: bool = True, steady: bool = True, quiet: bool = True
    ) -> Any:
        den = denoise_take(frames, self.sigma)
        return self.method.solve(den.frames, temporal=temporal, steady=steady, quiet=quiet)


def add_denoised(methods: dict[str, Solver], unbounded: bool) -> None:
    """`DENOISED` and `LOCAL_FITS_DENOISED` beside a protocol's noisy LGI (`unbounded`: with
    the unbounded fit and unbounded local fits, the scans' calls; else the boxed ones), and
    each of the protocol's peers (`PEER_NAMES`) on the denoised markers (`DENOISED_PEER`)."""
    lgi = methods["LGI"]
    if not isinstance(lgi, Recommended) or not lgi.marker_noise:
        return
    sigma, model = lgi.marker_noise, lgi.model
    fit = UNBOUNDED if unbounded else None
    methods[DENOISED] = Recommended(model, sigma, fit=fit, denoise=True)
    if model.jaw_bins is None:
        local: bool | str = "unbounded" if unbounded else True
        methods[LOCAL_FITS_DENOISED] = Recommended(model, sigma, local_fits=local, denoise=True)
    for name in PEER_NAMES:
        if name in methods:
            methods[DENOISED_PEER.format(name)] = OnDenoised(methods[name], sigma)


#: LGI as `lgi solve --recommended` solves a take: every choice read from the take given, its
#: marker noise included (`lgi.plan.choices.plan_solve`), not the protocol's sigma.
AS_RECOMMENDED = "LGI --recommended"


class AsRecommended:
    """`AS_RECOMMENDED` as a compared method: the plan `lgi solve --recommended` reads from the
    frames given (with `take`: from that whole take, of which the frames given are every
    `step`-th, as a TD gives a whole take and the protocol scores some of its frames), then
    `model.solve` of it. `last_plan` is the plan of the last solve."""

    def __init__(self, model: Model, take: ArrayLike | None = None, step: int = 1) -> None:
        self.model, self.step = model, step
        self.take = None if take is None else np.asarray(take, dtype=np.float64)
        self.last_plan: SolvePlan | None = None

    def solve(
        self, frames: ArrayLike, *, temporal: bool = True, steady: bool = True, quiet: bool = True
    ) -> Any:
        x = np.asarray(frames, dtype=np.float64)
        whole = x if self.take is None else self.take
        with warnings.catch_warnings():
            # Only the noise estimate's frames-too-far-apart warning is silenced (the row's
            # plan gives the noise read); anything else still shows.
            warnings.filterwarnings("ignore", message="marker noise:", category=LgiWarning)
            plan = plan_solve(whole, self.model, recommended=True)
        solved = plan.frames if self.take is None else plan.frames[:: self.step]
        if solved.shape != x.shape:
            raise InputError(
                f"as recommended: {x.shape[0]} frames given are not every {self.step}-th of "
                f"the take's {whole.shape[0]}"
            )
        self.last_plan = plan
        return self.model.solve(
            solved, temporal=temporal, quiet=quiet, options=plan.options.replace(steady=steady)
        )


def add_as_recommended(methods: dict[str, Solver]) -> None:
    """`AS_RECOMMENDED` beside a protocol's LGI (its model)."""
    lgi = methods["LGI"]
    if isinstance(lgi, Recommended):
        methods[AS_RECOMMENDED] = AsRecommended(lgi.model)


def capture_methods(
    dataset: Dataset,
    markers: ArrayLike,
    sigma: float | None,
    frames: ArrayLike | None = None,
    *,
    jaw: tuple[JawRig, ArrayLike] | None = None,
) -> dict[str, Solver]:
    """The methods of the capture protocol: the two baselines, the fit with the jaw as a joint
    (`FitJaw`, the production rig solve, where the dataset gives a jaw rig) and the same with
    its residual corrective (`FitJawResidual`), LGI in the paper's
    exact mode (no jaw rig, no fit: tets only), LGI's recommended path (defaults,
    `marker_noise` = `sigma`; None: estimated from `frames` with the model, as
    `--marker-noise auto` does) and the same with local fits (`LOCAL_FITS`,
    `lgi.plan.local`). `jaw`: the rig and each shape's pose for a dataset without
    ICT's jaw shapes (None: the rig `Model.build` finds, if any)."""
    from lgi.lab.baselines import BlendshapeFit, DisplacementInterpolation, FitJaw, FitJawResidual

    if jaw is None:
        recommended = Model.build(dataset, markers)
    else:
        recommended = Model.build(dataset, markers, jaw=jaw[0], shape_theta=jaw[1])
    if sigma is None:
        if frames is None:
            raise InputError("capture methods: sigma None needs the frames to estimate it from")
        sigma = estimate_marker_noise(frames, recommended)
    methods: dict[str, Solver] = {
        DisplacementInterpolation.label: DisplacementInterpolation(dataset, markers),
        BlendshapeFit.label: BlendshapeFit(dataset, markers),
    }
    if recommended.jaw_rig is not None:
        peer = FitJaw(recommended)
        methods[FitJaw.label] = peer
        methods[FitJawResidual.label] = FitJawResidual(peer)
    methods["LGI (paper)"] = Recommended(Model.build(dataset, markers, jaw=None), None)
    methods["LGI"] = Recommended(recommended, sigma)
    if recommended.jaw_bins is None:
        methods[LOCAL_FITS] = Recommended(recommended, sigma, local_fits=True)
    return methods


def add_unbounded(methods: dict[str, Solver]) -> None:
    """The scans protocol's unbounded methods beside the bounded ones: a scan's weight is no
    activation, so the peers' fit without its [0, 1] bound is a peer too (`FitJawUnbounded`
    and its corrective), and LGI without it: the recommended call (`UNBOUNDED_FIT`) and with
    local fits (`LOCAL_FITS_UNBOUNDED`); with noisy markers, both with the take's prior on the
    unbounded fit (`TAKE_PRIOR`, `LOCAL_FITS_TAKE_PRIOR`)."""
    from lgi.lab.baselines import FitJawUnbounded, FitJawUnboundedResidual

    lgi = methods["LGI"]
    if not isinstance(lgi, Recommended) or lgi.model.jaw_rig is None:
        return
    peer = FitJawUnbounded(lgi.model)
    methods[FitJawUnbounded.label] = peer
    methods[FitJawUnboundedResidual.label] = FitJawUnboundedResidual(peer)
    methods[UNBOUNDED_FIT] = Recommended(lgi.model, lgi.marker_noise, fit="unbounded")
    if lgi.model.jaw_bins is None:
        methods[LOCAL_FITS_UNBOUNDED] = Recommended(
            lgi.model, lgi.marker_noise, local_fits="unbounded"
        )
    if lgi.marker_noise and lgi.model.jaw_bins is None:
        # Noise-free markers need no prior (the solve would be the unbounded fit's).
        methods[TAKE_PRIOR] = Recommended(
            lgi.model, lgi.marker_noise, fit="unbounded", take_prior=True
        )
        methods[LOCAL_FITS_TAKE_PRIOR] = Recommended(
            lgi.model, lgi.marker_noise, local_fits="unbounded", take_prior=True
        )
