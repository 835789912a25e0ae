"""Bit-identity check for refactors: solves the 300-frame ICT-300 temporal take (bench.py's
workload and frames) and prints SHA-256 digests of the vertices, choices and residuals, so two
builds can be compared by their output. Also hashes the same take with a fresh random 10 % of
the markers missing on every frame (seeded: a new sewing plan per frame), the take solved
noise-aware (`marker_noise`, with the fit candidate), and a sample solve (with jaw and
dropouts) so the check says something where the ICT data is absent.

Usage: python scripts/identity_check.py [--frames 300] [--out digests.json]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench
import lgi


def digest(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()[:16]


def digests(result: lgi.SolveResult) -> dict[str, str]:
    c = result.choices
    return {
        "vertices": digest(result.vertices),
        "residuals": digest(result.bundle_residuals),
        "choice_shapes": digest(c.shapes),
        "choice_weights": digest(c.weights),
        "choice_tets": digest(c.tets),
        "choice_projected": digest(c.projected),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    out: dict[str, dict[str, str]] = {}

    name, data, markers = bench.load_workload()
    model = lgi.Model.build(data, markers, jaw=None)
    frames = bench.make_frames(model, data, args.frames)
    out["workload"] = {"name": name}
    out["temporal"] = digests(model.solve(frames, quiet=True, fit=False))
    rng = np.random.default_rng(bench.SEED + 2)
    messy = bench.with_dropouts(frames, round(0.1 * frames.shape[1]), rng)
    out["dropouts_10pct"] = digests(model.solve(messy, quiet=True, fit=False))
    out["noise_aware"] = digests(model.solve(frames, quiet=True, marker_noise=bench.NOISE))

    from lgi.dataset import sample_dataset
    from lgi.sample import make_sample

    s = make_sample(0)
    sdata = sample_dataset(s)
    smodel = lgi.Model.build(sdata, s.markers_rest, jaw=None)
    out["sample"] = digests(smodel.solve(s.performance, quiet=True, fit=False))
    text = json.dumps(out, indent=1)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
