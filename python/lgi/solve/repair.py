"""Marker faults repaired before the take is solved again: a named label swap is undone over
its frames, a spike or a marker off its track is treated as missing over its frames (the solve
fills it from the markers around it); model gaps (`Finding.kind == "gap"`) and cuts are the
dataset's and the take's, never repaired. The take given is never touched: the repaired copy
is what the second solve reads, and what was repaired is recorded in the solve's settings
(`SolveSettings.repairs`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from lgi.solve.diagnose import Finding

__all__ = ["repaired"]

Repairs = tuple[tuple[str, tuple[str, ...], int, int], ...]


def repaired(
    frames: NDArray[np.float64], findings: Sequence[Finding], names: Sequence[str]
) -> tuple[NDArray[np.float64], NDArray[np.bool_], Repairs]:
    """A copy of `frames` (F, B, 3) with the faults among `findings` repaired, the (F, B)
    mask of the samples changed, and the repairs as `SolveSettings.repairs` records them."""
    x = np.array(frames, dtype=np.float64, copy=True)
    mask = np.zeros(x.shape[:2], dtype=bool)
    index = {n: k for k, n in enumerate(names)}
    done = []
    for f in findings:
        if not f.fault:
            continue
        rows = slice(f.first, f.last + 1)
        cols = [index[n] for n in f.markers]
        if f.kind == "swap":
            a, b = cols
            x[rows, [a, b]] = x[rows, [b, a]]
        else:
            x[rows, cols] = np.nan
        mask[rows, cols] = True
        done.append((f.kind, tuple(f.markers), int(f.first), int(f.last)))
    return x, mask, tuple(done)
