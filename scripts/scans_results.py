"""The whole-face-scans protocol (`lgi.lab.evaluate.scans_protocol`, issue 34): for each shared
Live Link recording as the performance, K scans picked farthest-first from the other
recording's curves and made by the capture truth rig are the dataset; each method solves the
performance (200 frames, 2 % dropouts) at several noise levels, on markers_120 and on random
layouts of the narrow face; mean face-skin error in cm and, for LGI, the share of bundles that
took the global fit (docs/results.md). `--truth nonlinear`: scans and performance from
`lgi.lab.capture.NonlinearTruth` (with how far the performance is from the linear rig).

Usage: python scripts/scans_results.py [--scans K ...] [--sigma S ...] [--layouts ...]
[--truth linear|nonlinear]
(from the checkout, ../shared beside it). A layout is `markers_120` or `random:N:SEED`.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from lgi.lab import evaluate, ict
from lgi.lab.capture import random_layout
from lgi.lab.methods import (
    DENOISED,
    DENOISED_PEER,
    LOCAL_FITS,
    LOCAL_FITS_DENOISED,
    LOCAL_FITS_TAKE_PRIOR,
    LOCAL_FITS_UNBOUNDED,
    TAKE_PRIOR,
    UNBOUNDED_FIT,
)

sys.path.insert(0, str(Path(__file__).resolve().parent))
import ict_captures

ICT = "../shared/data/ict-facekit"
RECORDINGS = [f"../shared/data/livelinkface/{r}.csv" for r in ("alex_rom_4", "jmtechart_myslate_3")]
METHODS = (
    "blendshape fit",
    *ict_captures.PEERS,
    "LGI (paper)",
    "LGI",
    UNBOUNDED_FIT,
    LOCAL_FITS,
    LOCAL_FITS_UNBOUNDED,
    TAKE_PRIOR,
    LOCAL_FITS_TAKE_PRIOR,
    DENOISED,
    LOCAL_FITS_DENOISED,
)
#: The peers given the same denoised markers (noisy takes only): how much of the denoised
#: calls' gain is the denoising's.
DENOISED_PEERS = tuple(DENOISED_PEER.format(p) for p in ict_captures.PEERS)


def layout(name: str, dataset: object) -> np.ndarray:
    if name == "markers_120":
        return ict.load_layout(ICT).positions
    _, count, seed = name.split(":")
    return random_layout(dataset, int(count), int(seed), np.arange(ict.NARROW_FACE))  # type: ignore[arg-type]


def ratio(m: dict[str, float], method: str) -> str:
    """`method`'s ratio to the best peer, "—" where it was not run (noise-free takes, or left
    out by `--denoised-only`)."""
    return f"{ict_captures.peer_ratio(m, method):.3f}" if method in m else "—"


def denoised_ratio(m: dict[str, float], method: str) -> str:
    """`method`'s ratio to the best peer given the denoised markers, "—" where not run."""
    peers = [m[p] for p in DENOISED_PEERS if p in m]
    return f"{m[method] / min(peers):.3f}" if method in m and peers else "—"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scans", type=int, nargs="+", default=[120])
    ap.add_argument("--sigma", type=float, nargs="+", default=[0.0, 0.02, 0.05])
    ap.add_argument("--layouts", nargs="+", default=["markers_120", "random:160:1"])
    ap.add_argument("--truth", choices=["linear", "nonlinear"], default="linear")
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument(
        "--denoised-only",
        action="store_true",
        help="the peers, LGI, its unbounded calls and the denoised calls only (the rest: as the "
        "tables before)",
    )
    args = ap.parse_args()
    only = None
    if args.denoised_only:
        only = {*ict_captures.PEERS, *DENOISED_PEERS, "LGI", UNBOUNDED_FIT, LOCAL_FITS_UNBOUNDED}
        only |= {DENOISED, LOCAL_FITS_DENOISED}
    warnings.filterwarnings("ignore")
    d = ict.load_dataset(ICT)
    print("| performance | layout | K | sigma (cm) | " + " | ".join(METHODS), end="")
    print(" | LGI bundles on the fit | LGI / best peer | local fits / best peer", end="")
    print(" | unbounded fit / best peer | unbounded local fits / best peer", end="")
    print(" | take prior / best peer | take prior + local fits / best peer", end="")
    print(" | denoised / best peer | denoised + local fits / best peer", end="")
    print(" | best peer on denoised markers | denoised + local fits / that", end="")
    print(" | truth from linear | seconds |")
    print("|---" * (len(METHODS) + 17) + "|")
    for name in args.layouts:
        markers = layout(name, d)
        for k in args.scans:
            for sigma in args.sigma:
                t0 = time.perf_counter()
                rows = evaluate.scans_protocol(
                    d,
                    markers,
                    RECORDINGS,
                    scans=k,
                    sigma=sigma,
                    jaw_rigid=ict.lower_teeth(),
                    region=ict.skin(),
                    frames=args.frames,
                    nonlinear=args.truth == "nonlinear",
                    only=None if only is None else sorted(only),
                )
                took = time.perf_counter() - t0
                for rec, got in ict_captures.by_recording(rows).items():
                    m = {x: r["mean"] for x, r in got.items()}
                    # Noise-free takes have no take-prior rows (no prior is read): "—".
                    cells = " | ".join(f"{m[x]:.4f}" if x in m else "—" for x in METHODS)
                    lgi_row = got["LGI"]
                    denoised_peer = min((m[p] for p in DENOISED_PEERS if p in m), default=np.nan)
                    print(
                        f"| {rec} | {name} | {k} | {sigma} | {cells} "
                        f"| {lgi_row['bundles_fit']:.0%} | {ict_captures.peer_ratio(m):.3f} "
                        f"| {ratio(m, LOCAL_FITS)} "
                        f"| {ratio(m, UNBOUNDED_FIT)} "
                        f"| {ratio(m, LOCAL_FITS_UNBOUNDED)} "
                        f"| {ratio(m, TAKE_PRIOR)} | {ratio(m, LOCAL_FITS_TAKE_PRIOR)} "
                        f"| {ratio(m, DENOISED)} | {ratio(m, LOCAL_FITS_DENOISED)} "
                        f"| {denoised_peer:.4f} "
                        f"| {denoised_ratio(m, LOCAL_FITS_DENOISED)} "
                        f"| {lgi_row['truth_departure']:.4f} | {took:.0f} |",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
