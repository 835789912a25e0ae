"""The noise estimate on sparsely sampled takes (docs/results.md, issue 34): ICT captures of
both shared Live Link recordings (the capture truth rig: ICT's shapes plus a rotating jaw),
noise-free and with 0.2 mm noise, every 20th frame; the estimate from the tracks alone, the
estimate bounded by the model's fit (`estimate_marker_noise(frames, model)`), and the
recommended solve's mean face-skin error with each (frames solved independently).

Usage: python scripts/noise_estimate_results.py (from the checkout, ../shared beside it).
"""

from __future__ import annotations

import warnings

import numpy as np

import ict_captures
import lgi
from lgi.lab import ict
from lgi.lab.capture import make_capture
from lgi.noise import fit_noise_bound

STEP = 20


def main() -> None:
    warnings.filterwarnings("ignore")
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
