"""LGI's recommended call against the strongest peer a TD has, the fit with the jaw as a joint
(`lgi.lab.baselines.FitJaw`) and the same with its residual corrective (`FitJawResidual`), in the
capture protocol (`lgi.lab.evaluate.capture_protocol`: both
shared Live Link recordings driving ICT with a rotating jaw, 200 frames each, 2 % dropouts,
markers_120), at two noise levels and with a quarter of the shapes held out or none; mean
face-skin error in cm (docs/results.md, issue 34).

`--truth nonlinear`: the performance from `lgi.lab.capture.NonlinearTruth` (the shapes'
rotations and stretches blended per triangle) instead of the linear rig with a hinged jaw.

The denoised calls (`lgi.denoise_take` first, `LGI (denoised)` and with local fits) and the peers
given the same denoised markers are in the last columns.

Usage: python scripts/peer_results.py [--truth linear|nonlinear] [--sigma S ...]
[--holdout H ...]
(from the checkout, ../shared beside it).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

from lgi.lab import evaluate, ict
from lgi.lab.methods import DENOISED, DENOISED_PEER, LOCAL_FITS, LOCAL_FITS_DENOISED

sys.path.insert(0, str(Path(__file__).resolve().parent))
import ict_captures

ICT = "../shared/data/ict-facekit"
RECORDINGS = [f"../shared/data/livelinkface/{r}.csv" for r in ("alex_rom_4", "jmtechart_myslate_3")]
METHODS = ("blendshape fit", "fit + jaw", "fit + jaw + residual", "LGI (paper)", "LGI", LOCAL_FITS)
DENOISED_PEERS = tuple(DENOISED_PEER.format(p) for p in ("fit + jaw", "fit + jaw + residual"))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--truth", choices=["linear", "nonlinear"], default="linear")
    ap.add_argument("--sigma", type=float, nargs="+", default=[0.02, 0.05])
    ap.add_argument("--holdout", type=float, nargs="+", default=[0.0, 0.25])
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    d = ict.load_dataset(ICT)
    markers = ict.load_layout(ICT).positions
    head = "| recording | sigma (cm) | held out | " + " | ".join(METHODS)
    print(head + " | LGI / best peer | local fits / best peer | truth from linear", end="")
    print(" | denoised / best peer | denoised + local fits / best peer", end="")
    print(" | best peer on denoised markers | denoised / that | denoised + local fits / that |")
    print("|---" * (len(METHODS) + 11) + "|")
    for sigma in args.sigma:
        for holdout in args.holdout:
            rows = evaluate.capture_protocol(
                d,
                markers,
                RECORDINGS,
                sigma=sigma,
                holdout=holdout,
                jaw_rigid=ict.lower_teeth(),
                region=ict.skin(),
                frames=200,
                nonlinear=args.truth == "nonlinear",
            )
            for rec, got in ict_captures.by_recording(rows).items():
                m = {k: r["mean"] for k, r in got.items()}
                cells = " | ".join(f"{m[k]:.4f}" for k in METHODS)
                dpeer = min(m[p] for p in DENOISED_PEERS)
                print(
                    f"| {rec} | {sigma} | {holdout:.0%} | {cells} "
                    f"| {ict_captures.peer_ratio(m):.3f} "
                    f"| {ict_captures.peer_ratio(m, LOCAL_FITS):.3f} "
                    f"| {got['LGI']['truth_departure']:.4f} "
                    f"| {ict_captures.peer_ratio(m, DENOISED):.3f} "
                    f"| {ict_captures.peer_ratio(m, LOCAL_FITS_DENOISED):.3f} "
                    f"| {dpeer:.4f} | {m[DENOISED] / dpeer:.3f} "
                    f"| {m[LOCAL_FITS_DENOISED] / dpeer:.3f} |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
