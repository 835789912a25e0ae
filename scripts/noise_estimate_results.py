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

import lgi
from lgi.io.livelink import read_livelinkface
from lgi.lab import ict
from lgi.lab.capture import HingeJaw, make_capture
from lgi.model import fit_noise_bound

STEP = 20
D = "../shared/data/ict-facekit"


def main() -> None:
    warnings.filterwarnings("ignore")
    d = ict.load_dataset(D)
    lay = ict.load_layout(D)
    jaw = HingeJaw.fit(d, ict.lower_teeth())
    skin = ict.skin()
    m = lgi.Model.build(d, lay.positions)
    head = "| take | true sigma | frames | tracks | fit bound | estimate | error at: true sigma"
    print(head + " | tracks | estimate |")
    print("|---|---|---|---|---|---|---|---|---|")
    for rec in ["alex_rom_4", "jmtechart_myslate_3"]:
        w = read_livelinkface(f"../shared/data/livelinkface/{rec}.csv").for_dataset(d.names)
        for sigma, seed in ((0.0, 1), (0.02, 1)):
            t = make_capture(
                d, w, lay.positions, sigma=sigma, dropout=0.0, holdout=0, seed=seed, jaw=jaw
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
