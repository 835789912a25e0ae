"""The noise estimate on sparsely sampled takes (docs/results.md, issue 34): ICT captures of
both shared Live Link recordings (the capture truth rig: ICT's shapes plus a rotating jaw),
noise-free and with 0.2 mm noise, every 20th frame; the estimate from the tracks alone, the
estimate bounded by the model's fit (`estimate_marker_noise(frames, model)`), and the
recommended solve's mean face-skin error with each (frames solved independently).

With `--scans LAYOUT ...`: the scans protocol's setting instead (120 whole-face scans picked
from the slate recording, the performances on the layout: the ROM recording, which goes beyond
the scans, and the slate), each take sampled sparsely (60 frames over the recording) and at
capture rate (200 consecutive frames), 2 % dropouts, solved with unbounded local fits at the
true sigma, at the estimate before the left-out reading (the smaller of the tracks' and the
fit's) and at the estimate.

Usage: python scripts/noise_estimate_results.py [--scans markers_120 random:160:1 ...] (from
the checkout, ../shared beside it).
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import ict_captures
import lgi
from lgi.lab import ict
from lgi.lab.capture import make_capture
from lgi.lab.scans import scan_session
from lgi.plan.noise import _track_noise, fit_noise_bound, tracks_correlation
from lgi.solve.jaw import auto_rig
from scans_results import layout

STEP = 20


def scans(layouts: list[str]) -> None:
    d, _, jaw, _ = ict_captures.setup()
    skin = ict.skin()
    rig, theta = auto_rig(d)
    rom, slate = (w for _, w in ict_captures.recordings(d))
    session = scan_session(d, slate, 120, jaw, theta, nonlinear=None)
    print(
        "| layout | performance | frames | true sigma | neighbours' correlation | tracks | "
        "fit bound | before | estimate | estimate (s) | error at: true sigma | before | "
        "estimate |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in layouts:
        positions = layout(name, d)
        m = lgi.Model.build(session.dataset, positions, jaw=rig, shape_theta=session.theta)
        for perf, w in (("alex_rom_4", rom), ("jmtechart_myslate_3", slate)):
            for rate, curves in (("sparse", w[:: w.shape[0] // 60][:60]), ("200 at rate", w[:200])):
                for sigma in (0.0, 0.02, 0.05):
                    t = make_capture(
                        d, curves, positions, sigma=sigma, dropout=0.02, holdout=0, seed=3, jaw=jaw
                    )
                    x = t.frames
                    tracks, bound = _track_noise(x), fit_noise_bound(m, x)
                    before = min(tracks or np.inf, bound or np.inf)
                    t0 = time.perf_counter()
                    est = lgi.estimate_marker_noise(x, m)
                    took = time.perf_counter() - t0
                    errors = []
                    for s in (sigma, before, est):
                        r = m.solve(x, marker_noise=s, quiet=True, local_fits="unbounded")
                        e = np.linalg.norm(r.vertices[:, skin] - t.truth[:, skin], axis=2).mean()
                        errors.append(f"{e:.4f}")
                    print(
                        f"| {name} | {perf} | {rate} | {sigma} | "
                        f"{tracks_correlation(x, m.markers_rest):.2f} | {tracks:.4f} | "
                        f"{bound:.4f} | {before:.4f} | {est:.4f} | {took:.1f} | "
                        f"{' | '.join(errors)} |",
                        flush=True,
                    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scans", nargs="+", help="layouts (markers_120, random:N:SEED)")
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    if args.scans:
        scans(args.scans)
        return
    d, positions, jaw, m = ict_captures.setup()
    skin = ict.skin()
    head = "| take | true sigma | frames | tracks | fit bound | estimate | error at: true sigma"
    print(head + " | tracks | estimate |")
    print("|---|---|---|---|---|---|---|---|---|")
    for rec, w in ict_captures.recordings(d):
        for sigma, seed in ((0.0, 1), (0.02, 1)):
            t = make_capture(
                d, w, positions, sigma=sigma, dropout=0.0, holdout=0, seed=seed, jaw=jaw
            )
            fr, truth = t.frames[::STEP], t.truth[::STEP]
            tracks = lgi.estimate_marker_noise(fr)
            both = lgi.estimate_marker_noise(fr, m)
            errors = []
            for s in (sigma, tracks, both):
                r = m.solve(fr, marker_noise=s, quiet=True, temporal=False)
                e = np.linalg.norm(r.vertices[:, skin] - truth[:, skin], axis=2).mean()
                errors.append(f"{e:.4f}")
            print(
                f"| {rec} every {STEP}th | {sigma} | {len(fr)} | {tracks:.4f} | "
                f"{fit_noise_bound(m, fr):.4f} | {both:.4f} | {' | '.join(errors)} |"
            )


if __name__ == "__main__":
    main()
