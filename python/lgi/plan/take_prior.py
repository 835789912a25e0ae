"""A take's own prior on its frames' global fit (empirical Bayes).

A performance moves a dataset's face in a few directions of its many shapes. Least squares
with noisy markers spends the noise over every direction the shapes can take at the markers;
the take's frames show which directions it really moves in, and by how much. The prior is
read from the take itself:

1. Each frame's markers, in the jaw's unskinned space less the bundles' rest (the rows the
   global fit fits, `core.fit_rows`), are written in the fit matrix's own coordinates:
   `A = U S Vᵀ`, `ζ_t = Uᵀ d_t / sigma`. Noise of sigma per coordinate is then white, of
   variance 1, in `ζ`. A frame's missing rows are filled by its fit (first its ridge fit,
   then its fit under the prior read so far, `REFILL_ROUNDS` times), so that a frame short
   of a marker neither loses the directions the marker saw nor shows its noise as motion.
2. The frames' centred `ζ` (a matrix of F frames by q directions) are shrunk by the optimal
   singular-value shrinker for white noise of known level (Gavish & Donoho 2017, Frobenius
   loss): a singular value y inside the noise's bulk edge `1 + √β` goes to 0, the others to
   `η(y) = √((y² - β - 1)² - 4β) / y`. Each direction's factor `f = η(y)/y` is a Gaussian
   prior's Wiener factor `c / (c + 1)`, so the prior's variance there is `c = f / (1 - f)`.
3. Mapped back to the shapes' weights, `w = V S⁻¹ sigma ζ`: the prior's mean and covariance
   factor. The fit's own ridge is kept on top (its precision added on the prior's span,
   `with_ridge`): where a take's out-of-span motion (a performance beyond the dataset) lands
   in weakly seen directions, least squares there would follow it too far.
4. The core applies it per frame with that frame's rows (`TakePrior`), dropouts included:
   the ridge fit of `A L` to the markers less `A μ`.

A frame of a take whose motion lies in a few directions then loses the noise in the others;
noise-free markers (sigma = 0) need no prior. Whether a take gains by it is read from the take's
own markers left out (`lgi.estimate_take_prior_use`, `lgi.plan.take_prior_use`): a take that
ranges beyond the directions its frames show often (a range-of-motion session) can lose more
to the prior's pull than it saves in noise.
"""

from __future__ import annotations

from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray
from threadpoolctl import threadpool_limits

import lgi._lgi as _lgi
from lgi.errors import InputError
from lgi.plan.leave_out import (
    LeftOut,
    solved_in_chunks,
    take_frames,
)
from lgi.solve.local import UNBOUNDED
from lgi.solve.spectrum import right_singular, shrinkage_factors
from lgi.solve.take_prior import TakePrior

if TYPE_CHECKING:
    from lgi._lgi import SolveResult
    from lgi.solve.model import Model

__all__ = [
    "HeldOutPriors",
    "TakePrior",
    "TakeRows",
    "estimate_take_prior",
    "shrinkage_factors",
]

F64 = NDArray[np.float64]

#: Directions of the fit's matrix kept, relative to its largest singular value (every one the
#: markers see; numerically zero ones have no weight to put a prior on).
DIRECTION_TOLERANCE = 1e-9

#: Rounds of filling frames' missing rows by their fit under the prior and reading it again.
REFILL_ROUNDS = 3


def _shrunk(zeta: F64) -> tuple[F64, F64]:
    """The mean (q,) and covariance factor (q, k) of frames `zeta` (F, q) with white noise of
    level 1: the centred frames' singular values shrunk optimally (`shrinkage_factors`), each
    kept direction's factor `f` read as a prior's Wiener factor, variance `f / (1 - f)`."""
    n_frames, q = zeta.shape
    mean = zeta.mean(axis=0)
    m, n = sorted((q, n_frames - 1))
    centred = (zeta - mean) / np.sqrt(n)
    # The right singular vectors and values from the q x q Gram matrix (several times faster
    # than the SVD of the F x q frames; exact enough above the noise's bulk edge, all that is
    # kept: there a singular value is at least the noise's, 1).
    sv, v, order = right_singular(centred)
    f = shrinkage_factors(sv, m / n)
    used = f > 0.0
    return mean, v[:, order[used]] * np.sqrt(f[used] / (1.0 - f[used]))


def _filled(
    u: F64, left: F64, k: F64, present: NDArray[np.bool_], zeta: F64, mean: F64 | None
) -> F64:
    """`zeta` (F, q) with each frame short of a row (`present` (F, R)) filled by its fit in the
    core (`_lgi.fill_missing_rows`: products with the frame's m missing rows of `u` and an m x m
    solve, Woodbury's identity), the fit's `left` factor (R, q) and `k = left @ u.T`:

    - the frame's ridge fit (`mean` None; `left = U D⁻¹`, `D = I + ridge S⁻²`): `zeta`'s frames
      are their present rows' share `c = U_Pᵀ d_P / sigma` and become `c + U_Mᵀ x`, `x = (I -
      U_M D⁻¹ U_Mᵀ)⁻¹ U_M D⁻¹ c`: the fit `(D - U_MᵀU_M)⁻¹ c` at the missing rows;
    - the frame's fit under the prior `mean`, `Φ` (its MAP over its present rows, `left = U P`,
      `P = Φ (ΦᵀΦ + I)⁻¹ Φᵀ`): the frame's offset from the mean less its missing rows' share,
      `r`, becomes `mean + r + U_Mᵀ (I - U_M P U_Mᵀ)⁻¹ U_M P r`."""
    if present.all():
        return zeta
    c64 = np.ascontiguousarray
    return np.asarray(
        _lgi.fill_missing_rows(
            c64(u), c64(left), c64(k), c64(present), c64(zeta), None if mean is None else c64(mean)
        )
    )


class TakeRows:
    """What a take's prior is read from (module text): the fit's matrix in its own coordinates
    (`A = U S Vᵀ`, numerically zero directions dropped) and every frame's rows (the markers in
    the jaw's unskinned space less the rest, `core.fit_rows`), read once; `prior` reads the
    prior, with some markers' rows left out of every frame where asked."""

    def __init__(
        self, model: Model, frames: ArrayLike, marker_noise: float, jaw: str | None = "auto"
    ) -> None:
        sigma = float(marker_noise)
        if not (np.isfinite(sigma) and sigma > 0.0):
            raise InputError(
                f"take prior: the marker noise must be a distance > 0 (data units), got "
                f"{sigma}; noise-free markers need no prior"
            )
        if model.jaw_bins is not None:
            raise InputError(
                "take prior: the model has jaw bins (each bin fits its own re-posed shapes); "
                "build it without jaw_bins"
            )
        a, offsets, _ = model.core.fit_rows(take_frames(frames, model), jaw=jaw)
        a = np.asarray(a, dtype=np.float64)
        self.offsets = np.asarray(offsets, dtype=np.float64)
        if self.offsets.shape[0] < 2:
            raise InputError(
                f"take prior: needs a take of 2 frames or more, got {self.offsets.shape[0]}"
            )
        self.sigma = sigma
        self.ridge = _lgi.FIT_L2 * float(np.mean(np.sum(a**2, axis=0)))
        self._present = np.isfinite(self.offsets)
        u, s, vt = np.linalg.svd(a, full_matrices=False)
        # Every direction the markers see at all (the fit's ridge still weighs the weak ones).
        keep = s > s[0] * DIRECTION_TOLERANCE if s.size else s > 0
        if not keep.any():
            raise InputError("take prior: the dataset's shapes do not move the markers")
        self.u, self.s, self.vt = u[:, keep], s[keep], vt[keep]
        # Every frame's present rows in the fit's coordinates (c = U_Pᵀ d_P / sigma), once: a
        # prior without a marker takes its rows' share off.
        self._dropped = np.where(self._present, self.offsets, 0.0)
        self._c = (self._dropped @ self.u) / sigma
        # The ridge fit's U D⁻¹ and U D⁻¹ Uᵀ (D = I + ridge S⁻²), the same for every prior.
        self._ua = self.u / (1.0 + self.ridge / self.s**2)
        self._inner = self._ua @ self.u.T

    def prior(self, without: int | None = None) -> TakePrior:
        """The take's prior; `without`: marker `without`'s rows left out of every frame, as if
        the take had never had it (the left-out readings' prior for a row leaving it out)."""
        u, s, sigma, ridge = self.u, self.s, self.sigma, self.ridge
        c, present = self._c, self._present
        if without is not None:
            rows = slice(3 * without, 3 * without + 3)
            c = c - (self._dropped[:, rows] @ u[rows]) / sigma
            present = present.copy()
            present[:, rows] = False
        zeta = _filled(u, self._ua, self._inner, present, c, None)
        mean, phi = _shrunk(zeta)
        if not present.all():
            # A frame short of a marker is filled by its fit under the prior read so far, and
            # the prior read again (a few rounds: the kept directions settle in two or three).
            for _ in range(REFILL_ROUNDS):
                k = phi.shape[1]
                up = u @ (phi @ np.linalg.solve(phi.T @ phi + np.eye(k), phi.T))
                zeta = _filled(u, up, up @ u.T, present, zeta, mean)
                mean, phi = _shrunk(zeta)
        # ζ = S z / sigma and w = V z: w = V S⁻¹ sigma ζ. Mean and factor are the frames' ridge
        # fits' (each direction's share by s² / (s² + ridge)): in a weakly seen direction they
        # are mostly noise over s, which the ridge keeps from the weights as in every frame's fit.
        to_w = self.vt.T * (sigma / s * (s**2 / (s**2 + ridge)))
        return TakePrior(
            mean=np.ascontiguousarray(to_w @ mean),
            factor=np.ascontiguousarray(with_ridge(to_w @ phi, ridge / sigma**2)),
            noise=sigma,
            directions=len(s),
            frames=self.offsets.shape[0],
        )


def estimate_take_prior(
    model: Model, frames: ArrayLike, marker_noise: float, *, jaw: str | None = "auto"
) -> TakePrior:
    """The take's prior on its frames' global fit (module text), read from `frames` (F, B, 3;
    NaN: missing) with markers of noise `marker_noise` (sigma, data units, > 0) on `model` (built
    with a dataset of shapes and without jaw bins), each frame at the jaw pose `jaw` gives as
    in `Model.solve` (a pose from the fit refined against the boxed fit, as the unbounded fit
    the prior is for is made at)."""
    return TakeRows(model, frames, marker_noise, jaw).prior()


def with_ridge(factor: F64, precision: float) -> F64:
    """The factor of the prior whose precision on the span of `factor` (S, q) is the take's
    plus `precision` (the fit's ridge over sigma²): `L (I + p LᵀL)^(-1/2)`, so a direction the
    take moves in far above its noise is still held as the fit's ridge holds it."""
    ev, evec = np.linalg.eigh(factor.T @ factor * precision)
    return np.asarray(factor @ ((evec / np.sqrt(1.0 + np.clip(ev, 0.0, None))) @ evec.T))


class HeldOutPriors:
    """The priors the left-out readings solve a take's rows with: read from the frames no row
    leaves a marker out of, and without the row's left-out marker in any frame, so that what
    a left-out marker does is in no prior its row is solved with (a real marker between the
    markers is in none either; with its track in the prior, a real take's left-out markers
    favoured the prior where the surface lost by it). `None` from `of` for a take with fewer
    than 2 such frames."""

    def __init__(self, rows: TakeRows) -> None:
        self._rows = rows
        self._priors: dict[int, TakePrior] = {}

    @staticmethod
    def of(
        model: Model, arr: F64, left_out: LeftOut, marker_noise: float, jaw: str | None
    ) -> HeldOutPriors | None:
        others = np.setdiff1d(np.arange(arr.shape[0]), left_out.picked)
        if others.size < 2:
            return None
        return HeldOutPriors(TakeRows(model, arr[others], marker_noise, jaw))

    def without(self, marker: int) -> TakePrior:
        """The prior without marker `marker` (read once)."""
        if marker not in self._priors:
            self._priors[marker] = self._rows.prior(without=marker)
        return self._priors[marker]

    def read(self, markers: NDArray[np.int64]) -> None:
        """The priors without each of `markers` read (those not read before), on lgi's threads
        (`lgi.get_num_threads`), each with one BLAS thread: each prior is many small products
        that one thread cannot fill two cores with (1.6x on 2 cores)."""
        todo = [int(k) for k in np.unique(markers) if int(k) not in self._priors]
        workers = min(_lgi.get_num_threads(), len(todo))
        if workers < 2:
            for k in todo:
                self.without(k)
            return
        with threadpool_limits(1), ThreadPoolExecutor(workers) as pool:
            jobs = {k: pool.submit(self._rows.prior, without=k) for k in todo}
            try:
                for k, job in jobs.items():
                    self._priors[k] = job.result()
            except BaseException:  # Ctrl-C included: stop at once, no prior left running
                pool.shutdown(wait=False, cancel_futures=True)
                raise

    def solved(
        self,
        model: Model,
        left_out: LeftOut,
        rows: NDArray[np.int64],
        *,
        jaw: str | None,
        marker_noise: float | None,
    ) -> Iterator[tuple[NDArray[np.int64], SolveResult]]:
        """`rows` of `left_out` solved with the unbounded fit, each with the prior without its
        left-out marker: the rows of each marker together (`solved_in_chunks`)."""
        self.read(left_out.marker[rows])
        for marker in np.unique(left_out.marker[rows]):
            mine = rows[left_out.marker[rows] == marker]
            part = left_out.subset(mine)
            for at, res in solved_in_chunks(
                model,
                part,
                jaw=jaw,
                marker_noise=marker_noise,
                fit=UNBOUNDED,
                take_prior=self.without(int(marker)),
            ):
                yield mine[at], res
