"""Continuity of the solve (docs/results.md, issue 34): every marker of a take moved by 1 µm
(1e-4 cm, a random direction per marker and frame, seeded), frames solved independently, and
how far the surface moves: the largest vertex displacement per frame, as a multiple of the
markers' move. The paper's mode (`fit=False`, every marker interpolated by its tets) against
the recommended call (`marker_noise`), and for the paper's mode whether the frames that jump
are those where a bundle's choice changed.

Usage: python scripts/perturbation_results.py [--frames 200] (from the checkout, ../shared
beside it).
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

import ict_captures
from lgi.lab.capture import make_capture

MOVE = 1e-4  # cm: 1 micrometre


def perturbed(frames: np.ndarray, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    d = rng.normal(size=frames.shape)
    d /= np.linalg.norm(d, axis=2, keepdims=True)
    return frames + MOVE * d


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200)
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    d, positions, jaw, m = ict_captures.setup()
    head = "| take | mode | frames | median gain | max gain | frames with gain > 100"
    print(head + " | of those, a choice changed |")
    print("|---|---|---|---|---|---|---|")
    for rec, w in ict_captures.recordings(d):
        step = max(1, len(w) // args.frames)
        t = make_capture(
            d,
            w[::step][: args.frames],
            positions,
            sigma=0.02,
            dropout=0.0,
            holdout=0,
            seed=0,
            jaw=jaw,
        )
        moved = perturbed(t.frames, 1)
        for mode, opts in (
            ("paper (fit=False)", {"fit": False}),
            ("recommended (marker_noise=0.02)", {"marker_noise": 0.02}),
        ):
            a = m.solve(t.frames, temporal=False, quiet=True, **opts)
            b = m.solve(moved, temporal=False, quiet=True, **opts)
            gain = np.linalg.norm(a.vertices - b.vertices, axis=2).max(axis=1) / MOVE
            jump = gain > 100
            changed = (np.asarray(a.choices.shapes) != np.asarray(b.choices.shapes)).any(
                axis=(1, 2)
            )
            print(
                f"| {rec} | {mode} | {len(gain)} | {np.median(gain):.2f} | {gain.max():.3g} | "
                f"{int(jump.sum())} | {int((jump & changed).sum())} |"
            )


if __name__ == "__main__":
    main()
