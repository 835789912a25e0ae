#!/usr/bin/env python3
"""Writes a C3D marker take of the ICT-FaceKit face performing a Live Link Face recording: the
recording's ARKit curves drive the ICT shapes (`lgi.lab.capture.make_capture`, real hinge jaw),
the 120 markers of `markers_120.csv` are sampled on the result with Gaussian noise and
dropouts, and the take is written through ezc3d in millimetres with the layout's labels: the
input of the CLI walkthrough in docs/cli.md.

    python scripts/ict_take.py OUT.c3d [--recording jmtechart_myslate_3] [--sigma 0.05]
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--recording", default="jmtechart_myslate_3")
    ap.add_argument("--sigma", type=float, default=0.05, help="marker noise, cm")
    ap.add_argument("--dropout", type=float, default=0.02)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    import ezc3d

    from lgi.io.livelink import read_livelinkface
    from lgi.lab import capture, ict

    folder = ict.find(os.environ.get(ict.ENV), start=ROOT)
    if folder is None:
        print(f"ICT-FaceKit data not found (set {ict.ENV})", file=sys.stderr)
        return 2
    data = ict.load_dataset(folder)
    layout = ict.load_layout(folder)
    rec = folder.parent / "livelinkface" / f"{args.recording}.csv"
    curves = read_livelinkface(rec)
    jaw = capture.HingeJaw.fit(data, ict.lower_teeth())
    take = capture.make_capture(
        data,
        curves.for_dataset(data.names),
        layout.positions,
        sigma=args.sigma,
        dropout=args.dropout,
        holdout=0.0,
        seed=args.seed,
        jaw=jaw,
    )
    frames_mm = take.frames * 10.0
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [round(curves.fps)]
    c["parameters"]["POINT"]["LABELS"]["value"] = layout.names
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    pts = np.ones((4, frames_mm.shape[1], frames_mm.shape[0]))
    pts[:3] = frames_mm.transpose(2, 1, 0)
    c["data"]["points"] = pts
    res = np.zeros((1, frames_mm.shape[1], frames_mm.shape[0]))
    res[0][np.isnan(frames_mm).any(axis=2).T] = -1.0
    c["data"]["meta_points"]["residuals"] = res
    c.write(str(args.out))
    print(f"wrote {args.out}: {frames_mm.shape[0]} frames, {frames_mm.shape[1]} markers")
    return 0


if __name__ == "__main__":
    sys.exit(main())
