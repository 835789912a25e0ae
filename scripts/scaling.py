"""How the per-frame solve time grows with vertices, shapes and markers (the speed issue's
scaling table). One run, 2 threads, medians over the frames of the second of two identical
temporal `solve` calls into one output buffer (steady state: dropout plans cached, no fresh
pages).

- vertices: the built-in sample at growing resolutions (its own performance, dropouts included),
- shapes: ICT-FaceKit's 57 shapes, then augmented to 300 / 1000 (`Dataset.augmented`),
  markers_120,
- markers: ICT-300 with 60 (the first 60 of markers_120) / 120 / 240 markers (120 more placed at
  seeded random points of the face skin).

Usage: python scripts/scaling.py [--frames 60]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

import lgi
from lgi.lab import ict as ict_data
from lgi.lab.sample import make_sample, sample_dataset

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench import make_frames


def per_frame_ms(model: lgi.Model, frames: np.ndarray) -> float:
    """Median per-frame time of the second of two identical solves into one reused `out`
    buffer: the first builds the sewing plans of the sample's dropout sets (cached after) and
    touches the buffer's fresh memory, which would otherwise swamp the per-frame cost (at
    166k vertices a frame is 4 MB of new pages)."""
    stamps: list[float] = []
    out = np.zeros((len(frames), model.num_vertices, 3))
    for _ in range(2):
        stamps.clear()
        t0 = time.perf_counter()
        model.core.solve(frames, progress=lambda _f: stamps.append(time.perf_counter()), out=out)
    return float(np.median(np.diff([t0, *stamps])) * 1e3)


def extra_markers(data: lgi.Dataset, n: int, seed: int = 1) -> np.ndarray:
    """`n` seeded random points on the narrow face skin (triangles of vertices 0..6705)."""
    rng = np.random.default_rng(seed)
    tris = data.triangles[(data.triangles < 6706).all(axis=1)]
    pick = tris[rng.integers(0, len(tris), size=n)]
    b = rng.dirichlet(np.ones(3), size=n)
    return np.einsum("nk,nkc->nc", b, data.neutral[pick])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--frames", type=int, default=60)
    default = ict_data.find(os.environ.get(ict_data.ENV), start=Path(__file__).parent)
    ap.add_argument("--ict", type=Path, default=default)
    args = ap.parse_args()
    print("| axis | size | vertices | shapes | markers | build (s) | solve median (ms/frame) |")
    print("|---|---|---|---|---|---|---|")

    def row(axis: str, size: object, data: lgi.Dataset, markers: np.ndarray, frames=None) -> None:  # type: ignore[no-untyped-def]
        t = time.perf_counter()
        m = lgi.Model.build(data, markers, jaw=None)
        tb = time.perf_counter() - t
        fr = make_frames(m, data, args.frames) if frames is None else frames
        ms = per_frame_ms(m, fr)
        print(
            f"| {axis} | {size} | {data.num_vertices} | {data.num_shapes} | {len(markers)} | "
            f"{tb:.2f} | {ms:.2f} |"
        )

    for res in (110, 220, 440):
        s = make_sample(0, resolution=res, num_frames=args.frames)
        row("vertices", f"res {res}", sample_dataset(s), s.markers_rest, s.performance)
    ict = ict_data.load_dataset(args.ict)
    markers = ict_data.load_markers(args.ict)
    # The 57 ICT shapes themselves stand for "60"; augmentation adds in-betweens first.
    for n in (57, 300, 1000):
        row("shapes", n, ict if n == ict.num_shapes else ict.augmented(n), markers)
    ict300 = ict.augmented(300)
    for mk in (markers[:60], markers, np.concatenate([markers, extra_markers(ict, 120)])):
        row("markers", len(mk), ict300, mk)


if __name__ == "__main__":
    main()
