"""A take's spectrum: the thin SVD of a frames-by-coordinates matrix through the Gram matrix of
its smaller side, and the optimal singular-value shrinker for white noise of known level
(Gavish & Donoho 2017, Frobenius loss), which says which directions of a take are motion
and which are noise. Read by the take prior and the denoiser (`lgi.plan`) and by the fault
finder (`lgi.solve.diagnose`: a marker off the take's own motion)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

__all__ = ["right_singular", "shrinkage_factors", "thin_svd"]

F64 = NDArray[np.float64]


def shrinkage_factors(singular_values: F64, beta: float) -> F64:
    """Each singular value's optimal factor η(y)/y for white noise of level 1 (Gavish & Donoho
    2017, Frobenius loss) in a matrix of aspect ratio `beta` ≤ 1: 0 inside the noise's bulk
    edge 1 + √β, else √((y² - β - 1)² - 4β) / y²."""
    y = np.asarray(singular_values, dtype=np.float64)
    out = np.zeros_like(y)
    above = y > 1.0 + np.sqrt(beta)
    ya = y[above]
    out[above] = np.sqrt(np.maximum((ya**2 - beta - 1.0) ** 2 - 4.0 * beta, 0.0)) / ya**2
    return out


def thin_svd(a: F64, leading: Callable[[F64], int] | None = None) -> tuple[F64, F64, F64]:
    """The thin SVD of `a` (F, p) through the Gram matrix of its smaller side: several times
    faster than the full SVD, and exact enough above the noise's bulk edge (all that is kept).
    `leading`: how many of the singular values (descending) need their vectors, read from them
    (the rest are not made: their side's product is most of the cost); None: all."""
    f, p = a.shape
    if f < p:
        v, sv, ut = thin_svd(a.T, leading)
        return ut.T, sv, v.T
    sv, v, order = right_singular(a)
    k = sv.size if leading is None else leading(sv)
    v = v[:, order[:k]]
    u = (a @ v) / np.where(sv[:k] > 0.0, sv[:k], 1.0)
    return u, sv, v.T


def right_singular(a: F64) -> tuple[F64, F64, NDArray[np.intp]]:
    """The singular values of `a` (F, p), descending, from the eigendecomposition of the p x p
    Gram matrix `aᵀa`: what `thin_svd` reads for a matrix taller than wide, without the left
    vectors. With them its right singular vectors (p, p) as the eigendecomposition gives them
    and the `order` that pairs them with the values (column `order[i]` is `sv[i]`'s): a caller
    gathers only the columns it keeps."""
    evals, v = np.linalg.eigh(a.T @ a)
    order = np.argsort(evals)[::-1]
    return np.sqrt(np.maximum(evals[order], 0.0)), v, order
