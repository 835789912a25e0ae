"""Bit-identity check for refactors: solves the 300-frame ICT-300 temporal take (bench.py's
workload and frames) and prints SHA-256 digests of the vertices, choices and residuals, so two
builds can be compared by their output. Also hashes the same take with a fresh random 10 % of
the markers missing on every frame (seeded: a new sewing plan per frame), the take solved
noise-aware (`marker_noise`, with the fit candidate), and a sample solve (with jaw and
dropouts) so the check says something where the ICT data is absent. The jaw paths: the
recommended call (a model built with `jaw="auto"` on the workload's base shapes, solved with
`marker_noise`: each frame's pose from its fit, refined in the core) and the tracked pose
(`jaw="track"`), on ICT-57 and on the sample, and the recommended call and the default
`solve(frames)` on the workload (clean and with 10 % dropouts); `--save DIR` also writes the
tracked poses and the recommended vertices (npz) so two builds that differ can be compared by
how much.

Usage: python scripts/identity_check.py [--frames 300] [--out digests.json] [--save DIR]
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
        **({} if result.jaw_theta is None else {"jaw_theta": digest(result.jaw_theta)}),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--save", type=Path, help="folder for the jaw paths' arrays (npz)")
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

    from lgi.lab.sample import make_sample, sample_dataset

    s = make_sample(0)
    sdata = sample_dataset(s)
    smodel = lgi.Model.build(sdata, s.markers_rest, jaw=None)
    out["sample"] = digests(smodel.solve(s.performance, quiet=True, fit=False))

    # The jaw paths: the recommended call and the tracked pose, on a dataset with jawOpen.
    saved: dict[str, np.ndarray] = {}
    base = bench.load_base_dataset() or sdata
    jmodel = lgi.Model.build(base, markers if base is not sdata else s.markers_rest)
    jframes = (
        bench.make_frames(jmodel, base, min(args.frames, 100))
        if base is not sdata
        else s.performance
    )
    for key, m, fr in (("jaw", jmodel, jframes), ("sample_jaw", None, s.performance)):
        m = m or lgi.Model.build(sdata, s.markers_rest)
        rec = m.solve(fr, quiet=True, marker_noise=bench.NOISE)
        track = m.solve(fr, quiet=True, jaw="track", fit=False)
        out[f"{key}_recommended"] = digests(rec)
        out[f"{key}_track"] = digests(track)
        saved[f"{key}_recommended_vertices"] = rec.vertices
        saved[f"{key}_recommended_theta"] = np.asarray(rec.jaw_theta)
        saved[f"{key}_track_theta"] = np.asarray(track.jaw_theta)
        saved[f"{key}_track_vertices"] = track.vertices
    # The recommended path and the default `solve(frames)` on the workload itself (ICT-300's
    # augmented shapes take the fit's low-rank path), clean and with 10 % dropouts.
    if base is not sdata:
        rmodel = lgi.Model.build(data, markers)
        rframes = frames[: min(args.frames, 100)]
        for key, fr in (("clean", rframes), ("dropouts", messy[: len(rframes)])):
            for mode, noise in (("recommended", bench.NOISE), ("default", None)):
                res = rmodel.solve(fr, quiet=True, marker_noise=noise)
                out[f"workload_{mode}_{key}"] = digests(res)
                saved[f"workload_{mode}_{key}_vertices"] = res.vertices
                saved[f"workload_{mode}_{key}_theta"] = np.asarray(res.jaw_theta)
    if args.save:
        args.save.mkdir(parents=True, exist_ok=True)
        np.savez(args.save / "jaw_paths.npz", **saved)
    text = json.dumps(out, indent=1)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
