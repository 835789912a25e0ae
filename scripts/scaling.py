"""How the per-frame solve time grows with vertices, shapes and markers (the speed issue's
scaling table). One run, 2 threads, medians over the frames of one temporal `solve` call.

- vertices: the built-in sample at growing resolutions (its own performance, dropouts included),
- shapes: ICT-FaceKit's 57 shapes, then augmented to 300 / 1000 (`Dataset.augmented`),
  markers_120,
- markers: ICT-300 with 60 (the first 60 of markers_120) / 120 / 240 markers (120 more placed at
  seeded random points of the face skin).

Usage: python scripts/scaling.py [--frames 60]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import lgi
from lgi.dataset import sample_dataset
from lgi.sample import make_sample

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench import make_frames


def per_frame_ms(model: lgi.Model, frames: np.ndarray) -> float:
    stamps: list[float] = []
    t0 = time.perf_counter()
    model.core.solve(frames, progress=lambda _f: stamps.append(time.perf_counter()))
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
    default = Path(__file__).resolve().parents[2] / "shared" / "data" / "ict-facekit"
    ap.add_argument("--ict", type=Path, default=default)
    args = ap.parse_args()
    print("| axis | size | vertices | shapes | markers | build (s) | solve median (ms/frame) |")
    print("|---|---|---|---|---|---|---|")
    for res in (110, 220, 440):
        s = make_sample(0, resolution=res, num_frames=args.frames)
        data = sample_dataset(s)
        t = time.perf_counter()
        m = lgi.Model.build(data, s.markers_rest)
        tb = time.perf_counter() - t
        ms = per_frame_ms(m, s.performance)
        print(
            f"| vertices | res {res} | {data.num_vertices} | {data.num_shapes} | "
            f"{m.num_bundles} | {tb:.2f} | {ms:.2f} |"
        )
    ict = lgi.Dataset.from_obj(
        args.ict / "generic_neutral_mesh.obj", str(args.ict / "shapes/*.obj")
    )
    markers = np.loadtxt(args.ict / "markers_120.csv", delimiter=",", skiprows=1, usecols=(1, 2, 3))
    # The 57 ICT shapes themselves stand for "60"; augmentation adds in-betweens first.
    for n in (57, 300, 1000):
        data = ict if n == ict.num_shapes else ict.augmented(n)
        t = time.perf_counter()
        m = lgi.Model.build(data, markers)
        tb = time.perf_counter() - t
        ms = per_frame_ms(m, make_frames(m, data, args.frames))
        print(
            f"| shapes | {n} | {data.num_vertices} | {data.num_shapes} | 120 | {tb:.2f} | "
            f"{ms:.2f} |"
        )
    data = ict.augmented(300)
    for mk in (markers[:60], markers, np.concatenate([markers, extra_markers(ict, 120)])):
        t = time.perf_counter()
        m = lgi.Model.build(data, mk)
        tb = time.perf_counter() - t
        ms = per_frame_ms(m, make_frames(m, data, args.frames))
        print(
            f"| markers | {len(mk)} | {data.num_vertices} | {data.num_shapes} | {len(mk)} | "
            f"{tb:.2f} | {ms:.2f} |"
        )


if __name__ == "__main__":
    main()
