"""`lgi solve --recommended` (every choice read from the take, its marker noise included)
against the strongest peer a TD has, cell by cell, in issue 34's protocols: the scans protocol
(K = 120 whole-face scans, 200 frames, 2 % dropouts, seed 3; linear or nonlinear truth) on
several layouts and noise levels, and the capture protocol with a quarter of ICT's shapes held
out. Prints one Markdown row per cell: the best peer, LGI's recommended call at the protocol's
sigma, `--recommended` and its ratio to the best peer, and the plan it read (docs/results.md).

Usage: python scripts/recommended_results.py [--protocol scans|heldout]
[--sigma S ...] [--layouts ...] [--truth linear|nonlinear]
(from the checkout, ../shared beside it). A layout is `markers_120` or `random:N:SEED`.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path
from typing import Any

from lgi.lab import evaluate, ict
from lgi.lab.methods import AS_RECOMMENDED

sys.path.insert(0, str(Path(__file__).resolve().parent))
import ict_captures
import scans_results


def cells(args: argparse.Namespace, d: Any) -> Any:
    """(layout, sigma, rows) per protocol run."""
    for name in args.layouts:
        markers = scans_results.layout(name, d)
        for sigma in args.sigma:
            common: dict[str, Any] = {
                "jaw_rigid": ict.lower_teeth(),
                "region": ict.skin(),
                "frames": 200,
                "nonlinear": args.truth == "nonlinear",
                "only": [*ict_captures.PEERS, "LGI", AS_RECOMMENDED],
            }
            if args.protocol == "scans":
                rows = evaluate.scans_protocol(
                    d, markers, scans_results.RECORDINGS, scans=120, sigma=sigma, **common
                )
            else:
                rows = evaluate.capture_protocol(
                    d, markers, scans_results.RECORDINGS, sigma=sigma, holdout=0.25, **common
                )
            yield name, sigma, rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--protocol", choices=["scans", "heldout"], default="scans")
    ap.add_argument("--sigma", type=float, nargs="+", default=[0.0, 0.02, 0.05])
    ap.add_argument("--layouts", nargs="+", default=["markers_120"])
    ap.add_argument("--truth", choices=["linear", "nonlinear"], default="linear")
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    d = ict.load_dataset(scans_results.ICT)
    print(
        "| layout | performance | sigma (cm) | best peer | its error | LGI | --recommended "
        "| --recommended / best peer | seconds | plan read |"
    )
    print("|---" * 10 + "|")
    for name, sigma, rows in cells(args, d):
        for rec, got in ict_captures.by_recording(rows).items():
            m = {k: r["mean"] for k, r in got.items()}
            best = min((p for p in ict_captures.PEERS if p in m), key=lambda p: m[p])
            row = got[AS_RECOMMENDED]
            seconds = row["ms_per_frame"] * row["frames"] / 1000.0
            print(
                f"| {name} | {rec} | {sigma} | {best} | {m[best]:.5f} | {m['LGI']:.5f} "
                f"| {m[AS_RECOMMENDED]:.5f} | {ict_captures.peer_ratio(m, AS_RECOMMENDED):.3f} "
                f"| {seconds:.0f} | {row['plan']} |",
                flush=True,
            )
    print(f"# finished {time.strftime('%Y-%m-%d %H:%M')}")


if __name__ == "__main__":
    main()
