"""The take denoised by its own low-rank structure on real takes (issue 34): the lomo protocol
(`lgi.lab.lomo`: each shared AnimFace take retargeted onto ICT, 8 markers left out one at a
time, every method built and solved without the one left out; the noise estimated as
`--marker-noise auto` does) with LGI's recommended call with and without `lgi.denoise_take`
first, and the displacement interpolation and the fit + jaw + residual peer, each also given the
same denoised markers. Each line: the take, its estimated noise, and every method's mean
distance (mm) from the left-out markers; then both takes (docs/results.md).

Usage: python scripts/denoise_lomo.py (from the checkout, ../shared beside it)
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from lgi.lab.evaluate import (
    DENOISED,
    DENOISED_PEER,
    OnDenoised,
    Recommended,
    capture_methods,
)

sys.path.insert(0, str(Path(__file__).resolve().parent))
import ict_captures

OTHERS = ("displacement interpolation", "fit + jaw + residual")
#: Each solve's estimated noise (cm), for the line of its take.
NOISE: list[float] = []


def methods_for(dataset: Any, rest: np.ndarray, frames: np.ndarray) -> dict[str, Any]:
    ms = capture_methods(dataset, rest, None, frames)
    lgi = ms["LGI"]
    NOISE.append(float(lgi.marker_noise))
    out: dict[str, Any] = {
        "LGI": lgi,
        DENOISED: Recommended(lgi.model, lgi.marker_noise, denoise=True),
    }
    for name in OTHERS:
        out[name] = ms[name]
        out[DENOISED_PEER.format(name)] = OnDenoised(ms[name], lgi.marker_noise)
    return out


def main() -> None:
    warnings.filterwarnings("ignore")

    def label(stem: str) -> str:
        """The take's stem and the noise its solves estimated (then read afresh)."""
        noise = f"noise {min(NOISE):.5f}-{max(NOISE):.5f} cm"
        NOISE.clear()
        return f"{stem} {noise}"

    ict_captures.print_lomo(methods_for, label)


if __name__ == "__main__":
    main()
