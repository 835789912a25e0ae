"""The take's prior on real takes (issue 34): the lomo protocol (`lgi.lab.lomo`: each shared
AnimFace take retargeted onto ICT, 8 markers left out one at a time, every method built and
solved without the one left out; the noise estimated as `--marker-noise auto` does) with
LGI's recommended call, the unbounded fit, the unbounded fit with the take prior (read from the
frames solved, without the left-out marker) and the fit + jaw + residual peer. Each line: the
take and every method's mean distance (mm) from the left-out markers; then both takes
(docs/results.md).

Usage: python scripts/take_prior_lomo.py (from the checkout, ../shared beside it)
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from lgi.lab.evaluate import Recommended, capture_methods

sys.path.insert(0, str(Path(__file__).resolve().parent))
import ict_captures


def methods_for(dataset: Any, rest: np.ndarray, frames: np.ndarray) -> dict[str, Any]:
    ms = capture_methods(dataset, rest, None, frames)
    lgi = ms["LGI"]
    return {
        "LGI": lgi,
        "unbounded fit": Recommended(lgi.model, lgi.marker_noise, fit="unbounded"),
        "take prior": Recommended(lgi.model, lgi.marker_noise, fit="unbounded", take_prior=True),
        "fit + jaw + residual": ms["fit + jaw + residual"],
    }


def main() -> None:
    warnings.filterwarnings("ignore")
    ict_captures.print_lomo(methods_for)


if __name__ == "__main__":
    main()
