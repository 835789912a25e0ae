"""Is a take the size of the model? A wrong unit label (millimetres labelled `cm`, an empty
`POINT:UNITS`) solves a head 10 times too big without any other error, so before solving, the
take's present markers are compared with the model's rest layout: the median, over the first
frames, of the median ratio of pairwise marker distances (take / rest). Pairwise distances do
not change under the head's rotation and translation, a median ignores a few mislabelled or
spiking markers and the pairs an expression stretches. A factor outside `[1/SCALE_TOLERANCE,
SCALE_TOLERANCE]` is refused, naming the factor and the unit the numbers look like."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi.errors import InputError
from lgi.io.units import METERS_PER_UNIT, unit_scale

F64 = NDArray[np.float64]

__all__ = ["SCALE_TOLERANCE", "ScaleFit", "check_scale", "describe_scale", "take_scale"]

SCALE_TOLERANCE = 1.6
"""Largest accepted size ratio between a take and the model (either way). The nearest unit
mistake is inches for centimetres (2.54x); real takes measured against their models are within
a few per cent (docs/reliability.md), an actor's face against a generic model within 20 %."""

FRAMES_LOOKED_AT = 30
"""The first frames with enough markers that the factor is measured over."""

MIN_MARKERS = 4
"""Fewest present markers a frame needs to count (pairs of 4 points fix a similarity)."""


@dataclass(frozen=True)
class ScaleFit:
    """A take's size against the model's layout."""

    factor: float
    """Median ratio of pairwise distances, take / rest (1.0: the same size)."""
    frames: int
    """Frames the factor was measured over."""
    spread: float
    """Ratio of the 90th to the 10th percentile of the per-frame factors (1.0: steady)."""


def take_scale(frames: ArrayLike, rest: ArrayLike) -> ScaleFit | None:
    """The size factor of `frames` (F, B, 3; NaN rows missing) against `rest` (B, 3), or None
    when no frame among the first has `MIN_MARKERS` present."""
    x = np.asarray(frames, dtype=np.float64)
    r = np.asarray(rest, dtype=np.float64)
    if x.ndim != 3 or r.shape != x.shape[1:]:
        raise InputError(f"frames {x.shape} do not match the layout {r.shape}")
    i, j = np.triu_indices(r.shape[0], k=1)
    rest_d = np.linalg.norm(r[i] - r[j], axis=1)
    # Pairs closer than a tenth of the layout are noise-dominated: leave them out.
    far = rest_d > 0.1 * float(rest_d.max(initial=0.0))
    factors = []
    for f in range(x.shape[0]):
        present = ~np.isnan(x[f]).any(axis=1)
        if present.sum() < MIN_MARKERS:
            continue
        use = far & present[i] & present[j]
        if not use.any():
            continue
        d = np.linalg.norm(x[f, i[use]] - x[f, j[use]], axis=1)
        ratio = float(np.median(d / rest_d[use]))
        if np.isfinite(ratio):
            factors.append(ratio)
        if len(factors) == FRAMES_LOOKED_AT:
            break
    if not factors:
        return None
    fs = np.asarray(factors)
    lo, hi = np.percentile(fs, [10, 90])
    return ScaleFit(float(np.median(fs)), len(factors), float(hi / lo) if lo > 0 else np.inf)


def _likely_unit(factor: float, declared: str) -> str | None:
    """The unit that, read instead of `declared`, brings `factor` nearest 1 (within the
    tolerance), or None."""
    if not (np.isfinite(factor) and factor > 0):
        return None
    best, best_err = None, np.log(SCALE_TOLERANCE)
    for u in METERS_PER_UNIT:
        if u == declared:
            continue
        err = abs(np.log(factor * unit_scale(u, declared)))
        if err < best_err:
            best, best_err = u, err
    return best


def describe_scale(fit: ScaleFit | None) -> str:
    """One line for `lgi info TAKE --model MODEL`."""
    if fit is None:
        return f"  size: not measured (no frame has {MIN_MARKERS} markers present)"
    ok = 1 / SCALE_TOLERANCE <= fit.factor <= SCALE_TOLERANCE
    return f"  size: {fit.factor:.3g} x the model's layout (median over {fit.frames} frames); " + (
        "matches" if ok else f"outside 1/{SCALE_TOLERANCE:g}..{SCALE_TOLERANCE:g}: refused"
    )


def check_scale(
    frames: ArrayLike,
    rest: ArrayLike,
    *,
    path: str,
    file_units: str | None,
    model_units: str | None,
    stated: bool = False,
) -> ScaleFit | None:
    """Refuses a take whose size is off the model's by more than `SCALE_TOLERANCE`, naming
    the factor and the unit its numbers look like. `file_units`: the unit the take was read
    in (the file's, or `--take-units` when `stated`); `model_units`: the model's."""
    fit = take_scale(frames, rest)
    if fit is None or 1 / SCALE_TOLERANCE <= fit.factor <= SCALE_TOLERANCE:
        return fit
    declared = file_units or model_units
    where = "--take-units" if stated else "The file"
    head = (
        f"{path}: the markers are {fit.factor:.3g} x the size of the model's layout (median "
        f"pair-distance ratio over the first {fit.frames} frames; at most "
        f"{SCALE_TOLERANCE:g} x either way is accepted)"
    )
    if declared is None:
        raise InputError(
            f"{head}. Neither the take nor the model gives a unit: build the model with "
            "--units and give the take's with --take-units"
        )
    unit = _likely_unit(fit.factor, declared)
    said = (
        f"{where} says {declared}"
        if file_units
        else f"The file gives no unit, so it was read in the model's ({declared})"
    )
    if unit is not None:
        hint = f"{said}, but its numbers look like {unit}: pass --take-units {unit}" + (
            "" if stated else " if the file's unit is wrong"
        )
    else:
        hint = f"{said}; no length unit explains the factor: is this the right take and model?"
    raise InputError(f"{head}. {hint}")
