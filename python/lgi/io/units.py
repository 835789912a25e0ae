"""Length units: the one table of the units lgi understands (`METERS_PER_UNIT`, in meters) and
the conversions between them. Takes declare units, models keep one (`lgi build --units`), USD
writes `metersPerUnit` from it; all of them read this table."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from lgi.errors import InputError

F64 = NDArray[np.float64]

__all__ = ["METERS_PER_UNIT", "convert_units", "normalize_unit", "unit_scale"]


METERS_PER_UNIT = {"mm": 1e-3, "cm": 1e-2, "dm": 1e-1, "m": 1.0, "in": 0.0254, "ft": 0.3048}
"""Length units understood (takes' declared units, `lgi build --units`), in meters: the one
table of unit conversions and of USD's `metersPerUnit`."""

_UNIT_ALIASES = {
    "millimeter": "mm",
    "millimetre": "mm",
    "centimeter": "cm",
    "centimetre": "cm",
    "decimeter": "dm",
    "decimetre": "dm",
    "meter": "m",
    "metre": "m",
    "inch": "in",
    "inches": "in",
    "foot": "ft",
    "feet": "ft",
}


def normalize_unit(unit: str, where: str) -> str:
    """`unit` as a key of `METERS_PER_UNIT` (`Millimeters` -> `mm`); `InputError` naming
    `where` when unknown."""
    u = unit.strip().lower()
    singular = u[:-1] if u.endswith("s") and u[:-1] in _UNIT_ALIASES else u  # millimeters
    u = _UNIT_ALIASES.get(singular, u)
    if u not in METERS_PER_UNIT:
        raise InputError(
            f"{where}: unknown length unit {unit!r} (known: {', '.join(METERS_PER_UNIT)})"
        )
    return u


def unit_scale(source: str, target: str) -> float:
    """The factor taking coordinates in `source` units to `target` units."""
    return (
        METERS_PER_UNIT[normalize_unit(source, "unit")]
        / METERS_PER_UNIT[normalize_unit(target, "unit")]
    )


def convert_units(x: F64, source: str, target: str) -> F64:
    """`x` in `source` units converted to `target` units. To a unit a whole number of times
    larger (mm -> cm), coordinates are divided by that number, so the result is the correctly
    rounded quotient a user computes (x / 10), not x * 0.1 (which differs in the last bit)."""
    up = 1.0 / unit_scale(source, target)
    if up > 1 and up == round(up):
        return x / round(up)
    return x * unit_scale(source, target)
