"""Cost against the number of whole-face scans K (issue 34): build, per-frame solve and peak
memory of the scans protocol's model (`lgi.lab.scans`: K scans picked from the ROM recording
alex_rom_4, ICT's jaw rig), solving 100 frames of the other recording with the recommended call
(`marker_noise=0.02`), the paper's exact mode on the same build (`fit=False`, jaw from the
fit), and the stages: the global fit with its jaw pose alone (`fit_residuals`);
recommended_first_extra_s is what the model's first recommended call takes beyond the best one
(done once: the fit's shape basis); unbounded_ms: the recommended call with the unbounded
global fit (`fit="unbounded"`, its first call's extra as for the recommended one);
take_prior_s: reading the take's prior (`lgi.estimate_take_prior`, the whole take) and
take_prior_ms: the unbounded call with it; then the
recommended call with local fits (`local_fits=True`: local_build_s, once per model, and
local_ms per frame, the whole call), and estimate_s: what `lgi.estimate_local_fits`
(`--local-fits auto`) takes to read the take (estimate_frames: the frames it read, 8 a look).
Each K runs in its own process so its peak RSS (the process's, its own arrays included) is its
own.

Usage: python scripts/scans_cost.py [--scans 120 400 1000 2000] [--frames 100]
(from the checkout, ../shared beside it; RAYON_NUM_THREADS sets the threads, default 2)
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
import warnings

ICT = "../shared/data/ict-facekit"
LIVELINK = "../shared/data/livelinkface"


def one(k: int, frames: int) -> dict[str, float]:
    import lgi
    from lgi.io.livelink import read_livelinkface
    from lgi.lab import ict
    from lgi.lab.capture import HingeJaw, make_capture
    from lgi.lab.scans import scan_session
    from lgi.solve.jaw import auto_rig

    warnings.filterwarnings("ignore")
    d = ict.load_dataset(ICT)
    markers = ict.load_markers(ICT)
    hinge = HingeJaw.fit(d, ict.lower_teeth())
    rig, theta = auto_rig(d)
    rom = read_livelinkface(f"{LIVELINK}/alex_rom_4.csv").for_dataset(d.names)
    perf = read_livelinkface(f"{LIVELINK}/jmtechart_myslate_3.csv").for_dataset(d.names)
    t0 = time.perf_counter()
    session = scan_session(d, rom, k, hinge, theta)
    t_scans = time.perf_counter() - t0
    take = make_capture(
        d, perf[:frames], markers, sigma=0.02, dropout=0.0, holdout=0.0, seed=3, jaw=hinge
    )
    t0 = time.perf_counter()
    model = lgi.Model.build(session.dataset, markers, jaw=rig, shape_theta=session.theta)
    t_build = time.perf_counter() - t0
    out: dict[str, float] = {"K": k, "scans_s": t_scans, "build_s": t_build}
    t0 = time.perf_counter()
    prior = lgi.estimate_take_prior(model, take.frames, 0.02)
    out["take_prior_s"] = time.perf_counter() - t0
    calls = {
        "recommended_ms": lambda: model.solve(take.frames, marker_noise=0.02, quiet=True),
        "unbounded_ms": lambda: model.solve(
            take.frames, marker_noise=0.02, quiet=True, fit="unbounded"
        ),
        "take_prior_ms": lambda: model.solve(
            take.frames, marker_noise=0.02, quiet=True, fit="unbounded", take_prior=prior
        ),
        "paper_ms": lambda: model.solve(take.frames, jaw="fit", fit=False, quiet=True),
        "fit_ms": lambda: model.core.fit_residuals(take.frames, jaw="fit"),
    }
    for name, call in calls.items():
        times = []
        for _ in range(2):
            t0 = time.perf_counter()
            call()
            times.append(time.perf_counter() - t0)
        out[name] = 1e3 * min(times) / len(take.frames)
        if name in ("recommended_ms", "unbounded_ms"):
            # What the model's first solve does once (the fit's shape basis per jaw bin; the
            # unbounded fit's solver).
            out[name.replace("_ms", "_first_extra_s")] = times[0] - min(times)
    from lgi.solve.local import local_pieces

    t0 = time.perf_counter()
    local_pieces(model)
    out["local_build_s"] = time.perf_counter() - t0
    times = []
    for _ in range(2):
        t0 = time.perf_counter()
        model.solve(take.frames, marker_noise=0.02, quiet=True, local_fits=True)
        times.append(time.perf_counter() - t0)
    out["local_ms"] = 1e3 * min(times) / len(take.frames)
    # `--local-fits auto`'s reading of the take (240 left-out rows a look, up to three looks).
    t0 = time.perf_counter()
    est = lgi.estimate_local_fits(take.frames, model, marker_noise=0.02)
    out["estimate_s"] = time.perf_counter() - t0
    out["estimate_frames"] = est.frames
    out["peak_rss_gib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scans", type=int, nargs="+", default=[120, 400, 1000, 2000])
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--one", type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one is not None:
        print(json.dumps(one(args.one, args.frames)))
        return
    env = {**os.environ, "RAYON_NUM_THREADS": os.environ.get("RAYON_NUM_THREADS", "2")}
    cols = [
        "K",
        "scans_s",
        "build_s",
        "recommended_first_extra_s",
        "recommended_ms",
        "unbounded_first_extra_s",
        "unbounded_ms",
        "take_prior_s",
        "take_prior_ms",
        "paper_ms",
        "fit_ms",
        "local_build_s",
        "local_ms",
        "estimate_s",
        "estimate_frames",
        "peak_rss_gib",
    ]
    print("| " + " | ".join(cols) + " |")
    print("|---" * len(cols) + "|")
    for k in args.scans:
        cmd = [sys.executable, __file__, "--one", str(k), "--frames", str(args.frames)]
        got = json.loads(subprocess.run(cmd, env=env, check=True, capture_output=True).stdout)
        print("| " + " | ".join(f"{got[c]:.4g}" for c in cols) + " |", flush=True)


if __name__ == "__main__":
    main()
