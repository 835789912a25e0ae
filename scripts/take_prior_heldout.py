"""The take's prior (`lgi.estimate_take_prior`, issue 34) on the capture protocol with a quarter
of ICT's FACS shapes held out: both Live Link recordings drive ICT with a rotating jaw (200
frames, 2 % dropouts, markers_120, seed 3, as `scripts/peer_results.py`), and the peers, LGI's
boxed call and its local fits, the unbounded fit alone and with unbounded local fits, and the
unbounded fit with the take prior alone and with unbounded local fits solve it. Each line: the
recording, sigma (cm), the best peer's mean face-skin error (cm) and every method's ratio to it
(docs/results.md).

Usage: python scripts/take_prior_heldout.py [--frames 200] (from the checkout, ../shared
beside it)
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

from lgi.io.livelink import read_livelinkface
from lgi.lab import ict
from lgi.lab.capture import HingeJaw
from lgi.lab.evaluate import (
    LOCAL_FITS,
    LOCAL_FITS_TAKE_PRIOR,
    LOCAL_FITS_UNBOUNDED,
    TAKE_PRIOR,
    UNBOUNDED_FIT,
    _add_unbounded,
    _performance,
    capture,
    capture_methods,
)

ICT = "../shared/data/ict-facekit"
RECORDINGS = [f"../shared/data/livelinkface/{r}.csv" for r in ("alex_rom_4", "jmtechart_myslate_3")]
PEERS = ("fit + jaw", "fit + jaw + residual")
METHODS = (
    *PEERS,
    "LGI",
    LOCAL_FITS,
    UNBOUNDED_FIT,
    LOCAL_FITS_UNBOUNDED,
    TAKE_PRIOR,
    LOCAL_FITS_TAKE_PRIOR,
)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=200)
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    d = ict.load_dataset(ICT)
    markers = ict.load_layout(ICT).positions
    hinge = HingeJaw.fit(d, ict.lower_teeth())
    print("| recording | sigma (cm) | best peer (cm) | " + " | ".join(METHODS) + " | seconds |")
    print("|---" * (len(METHODS) + 4) + "|")
    for rec in RECORDINGS:
        curves = read_livelinkface(rec).for_dataset(d.names)
        for sigma in (0.02, 0.05):
            take, _ = _performance(
                d, curves, markers, frames=args.frames, sigma=sigma, dropout=0.02,
                holdout=0.25, seed=3, hinge=hinge, truth=None, region=ict.skin(),
            )  # fmt: skip
            methods = capture_methods(take.dataset, markers, sigma)
            _add_unbounded(methods)
            t0 = time.perf_counter()
            rows = capture(
                {k: methods[k] for k in METHODS},
                take.frames,
                take.truth,
                take.jaw_open,
                ict.skin(),
            )
            m = {r["method"]: r["mean"] for r in rows}
            best = min(m[p] for p in PEERS)
            cells = " | ".join(f"{m[k] / best:.3f}" for k in METHODS)
            print(
                f"| {Path(rec).stem} | {sigma} | {best:.4f} | {cells} "
                f"| {time.perf_counter() - t0:.0f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
