"""Capture-protocol table for docs/results.md: ICT-FaceKit driven by the real Live Link Face
recordings (jaw as a true rotation about the fitted hinge), markers in several layouts with
noise and 2 % dropouts, 0 or 25 % of the shapes held out; every method on every cell.

Usage: python scripts/capture_results.py [--frames 200] [--out docs/capture-table.md]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from lgi.io.livelink import read_livelinkface
from lgi.lab import evaluate, ict
from lgi.lab import methods as lab_methods
from lgi.lab.capture import HingeJaw, make_capture, random_layout

SIGMAS = (0.0, 0.05, 0.1)
HOLDOUTS = (0.0, 0.25)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--layouts", default="120,160:7,80:11")
    ap.add_argument(
        "--seeds", default="3", help="noise and dropout seeds, comma separated (a row each)"
    )
    args = ap.parse_args()
    folder = ict.find(os.environ.get(ict.ENV))
    if folder is None:
        raise SystemExit(f"ICT-FaceKit data not found (set ${ict.ENV})")
    data = ict.load_dataset(folder)
    jaw = HingeJaw.fit(data, ict.lower_teeth())
    layouts = {}
    for spec in args.layouts.split(","):
        if spec == "120":
            layouts["markers_120"] = ict.load_markers(folder)
        else:
            n, seed = (int(x) for x in spec.split(":"))
            layouts[f"random {n} (seed {seed})"] = random_layout(
                data, n, seed, np.arange(ict.NARROW_FACE)
            )
    lines = [
        "| recording | layout | seed | sigma (cm) | held out | displacement interp. | "
        "blendshape fit | lgi (paper: exact, tets, no jaw) | **lgi (recommended)** | "
        "lgi jaw-open frames | "
        "best baseline jaw-open |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for rec in ict.livelinkface(os.environ.get(ict.ENV)):
        curves = read_livelinkface(rec)
        w = curves.for_dataset(data.names)
        w = w[:: max(1, w.shape[0] // args.frames)]
        for lname, markers in layouts.items():
            cells = [
                (seed, sigma, hold)
                for seed in (int(x) for x in args.seeds.split(","))
                for sigma in SIGMAS
                for hold in HOLDOUTS
            ]
            for seed, sigma, hold in cells:
                t0 = time.perf_counter()
                take = make_capture(
                    data, w, markers, sigma=sigma, dropout=0.02, holdout=hold, seed=seed, jaw=jaw
                )
                methods = lab_methods.capture_methods(take.dataset, markers, sigma)
                keys = dict(zip(methods, ("disp", "bsfit", "paper", "lgi"), strict=True))
                rows = {
                    keys[r["method"]]: r
                    for r in evaluate.capture(
                        methods, take.frames, take.truth, take.jaw_open, ict.skin()
                    )
                }
                best = min(rows["disp"]["mean"], rows["bsfit"]["mean"])
                best_open = min(rows["disp"]["open_mean"], rows["bsfit"]["open_mean"])
                mark = "" if rows["lgi"]["mean"] <= best else " ✗"
                lines.append(
                    f"| {rec.stem} ({take.frames.shape[0]} fr) | {lname} | {seed} | {sigma} | "
                    f"{int(hold * 100)} % | {rows['disp']['mean']:.4f} | "
                    f"{rows['bsfit']['mean']:.4f} | {rows['paper']['mean']:.4f} | "
                    f"**{rows['lgi']['mean']:.4f}**{mark} | {rows['lgi']['open_mean']:.4f} | "
                    f"{best_open:.4f} |"
                )
                print(lines[-1], f"({time.perf_counter() - t0:.0f} s)", flush=True)
    text = "\n".join(lines) + "\n"
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
