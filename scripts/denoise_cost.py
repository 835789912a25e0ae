"""What `lgi.denoise_take` costs (docs/performance.md): synthetic takes of 120 markers moving in
20 directions with noise of 0.05 per coordinate, 200 to 3,809 frames (the ROM recording's
length), complete and with 2 % of the samples missing (filled by hard impute until settled);
the median of 3 runs each, seconds, with the rounds the fill took and the directions kept.

Usage: python scripts/denoise_cost.py
"""

from __future__ import annotations

import time

import numpy as np

import lgi


def main() -> None:
    rng = np.random.default_rng(0)
    print("| frames | complete (s) | 2 % missing (s) | directions kept |")
    print("|---|---|---|---|")
    for frames in (200, 1000, 3809):
        motion = rng.normal(size=(frames, 20)) @ rng.normal(size=(20, 360)) * 0.3
        take = motion.reshape(frames, 120, 3) + rng.normal(0.0, 0.05, (frames, 120, 3))
        gaps = take.copy()
        gaps[rng.random((frames, 120)) < 0.02] = np.nan
        times = []
        for x in (take, gaps):
            runs = []
            for _ in range(3):
                t0 = time.perf_counter()
                den = lgi.denoise_take(x, 0.05)
                runs.append(time.perf_counter() - t0)
            times.append(float(np.median(runs)))
        print(f"| {frames} | {times[0]:.2f} | {times[1]:.2f} | {den.rank} |", flush=True)


if __name__ == "__main__":
    main()
