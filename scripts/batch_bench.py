"""Throughput of `lgi.app.batch.solve_shots` (docs/scale.md): the same shots solved by a plain
loop in this process, then on a LocalCluster of 1 and of 2 worker processes, all in one run.
Each shot is a C3D take of the built-in sample's held-out performance (its own noise seed; with
`--ict`, ICT-FaceKit performing a Live Link Face recording, `scripts/ict_take.py`) solved on
the recommended path (`marker_noise="auto"`, the default jaw) into a solved `.npz`.
Prints shots/min and frames/s for each, the cluster's start-up time, the engine's overhead per
shot against the loop, and the workers' peak memory.

    python scripts/batch_bench.py [--shots 8] [--repeat 2] [--ict] [--out /tmp/lgi-batch-bench]
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

import lgi
from lgi.app import batch
from lgi.app.write import write_output
from lgi.io.topology import topology
from lgi.lab.sample import make_sample, sample_dataset

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from pipeline_files import write_c3d  # the tests' ezc3d writer

FPS = 30.0


def make_takes(folder: Path, shots: int) -> tuple[lgi.Model, dict[str, Path], int]:
    sample = make_sample(0)
    model = lgi.Model.build(
        sample_dataset(sample), sample.markers_rest, marker_names=sample.marker_names, units="cm"
    )
    perf = np.asarray(sample.performance, dtype=np.float64)
    takes = {}
    for k in range(shots):
        noise = np.random.default_rng(k).normal(scale=0.005, size=perf.shape)
        takes[f"sh{k:03d}"] = folder / f"sh{k:03d}.c3d"
        write_c3d(takes[f"sh{k:03d}"], perf + noise, list(sample.marker_names), FPS, "cm")
    return model, takes, int(perf.shape[0])


def make_ict_takes(folder: Path, shots: int) -> tuple[lgi.Model, dict[str, Path], int]:
    """ICT-FaceKit (`../shared/data`): the model `lgi build` makes (120 named markers, cm) and
    `scripts/ict_take.py`'s take (a Live Link Face recording, in mm), once per shot with its
    own extra 0.005 cm of noise."""
    import subprocess

    from lgi.app import pipeline
    from lgi.lab import ict

    data = ict.find(os.environ.get(ict.ENV), start=Path(__file__).resolve().parents[1])
    if data is None:
        raise SystemExit(f"ICT-FaceKit data not found (set {ict.ENV})")
    model_path = folder / "ict.lgi"
    pipeline.build_file(
        data / "generic_neutral_mesh.obj",
        os.fspath(data / "shapes"),
        data / "markers_120.csv",
        model_path,
        units="cm",
    )
    model = lgi.Model.load(model_path)
    base = folder / "base.c3d"
    script = Path(__file__).resolve().parent / "ict_take.py"
    subprocess.run([sys.executable, os.fspath(script), os.fspath(base)], check=True)
    raw = lgi.io.takes.read_raw(base)
    takes = {}
    for k in range(shots):
        noise = np.random.default_rng(k).normal(scale=0.05, size=raw.points.shape)  # mm
        takes[f"sh{k:03d}"] = folder / f"sh{k:03d}.c3d"
        fps = raw.fps if raw.fps is not None else FPS
        write_c3d(takes[f"sh{k:03d}"], raw.points + noise, raw.labels, fps, raw.units or "mm")
    return model, takes, int(raw.points.shape[0])


def plain_loop(model: lgi.Model, takes: dict[str, Path], out: Path) -> float:
    """What one process does without an engine: read, solve, write, shot after shot."""
    lgi.set_num_threads(os.cpu_count() or 1)
    t0 = time.perf_counter()
    topo = topology(model.dataset)
    for name, path in takes.items():
        t = lgi.io.takes.read(path, model.marker_names, units=model.units)
        res = model.solve(t.frames, quiet=True, marker_noise=lgi.estimate_marker_noise(t.frames))
        write_output(
            "npz",
            out / f"{name}.npz",
            topo,
            res.vertices,
            residuals=res.bundle_residuals,
            missing=res.missing,
            names=model.marker_names,
            fps=t.fps,
            start=t.first_frame,
            units=model.units,
            jaw_theta=res.jaw_theta,
            quiet=True,
        )
    lgi.set_num_threads(None)
    return time.perf_counter() - t0


def on_cluster(
    model: lgi.Model, takes: dict[str, Path], out: Path, workers: int
) -> tuple[float, float, float, list[int]]:
    """Start-up seconds, batch seconds, the tasks' own seconds (summed), and each worker's
    peak resident memory."""
    t0 = time.perf_counter()
    # The cluster `solve_shots` would start itself, started here so its start-up is timed apart.
    with batch._connect(None, workers, None, shots=workers) as (client, threads):
        client.wait_for_workers(workers)
        started = time.perf_counter() - t0
        t1 = time.perf_counter()
        result = batch.solve_shots(
            model, takes, out, client=client, threads=threads, quiet=True, marker_noise="auto"
        )
        took = time.perf_counter() - t1
        if result.failed:
            raise SystemExit(f"shots failed: {result.failed}")
        tasks = sum(s.seconds or 0.0 for s in result.shots.values())

        def rss() -> int:
            """The worker process's peak resident memory: Linux's VmHWM of its own address
            space (ru_maxrss would carry the spawning process's peak across exec)."""
            with open("/proc/self/status", encoding="ascii") as f:
                line = next(x for x in f if x.startswith("VmHWM:"))
            return int(line.split()[1]) * 1024

        memory = sorted(client.run(rss).values())
    return started, took, tasks, memory


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shots", type=int, default=8)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--ict", action="store_true", help="ICT-FaceKit shots instead of the sample")
    ap.add_argument("--out", default="/tmp/lgi-batch-bench")
    args = ap.parse_args()
    root = Path(args.out)
    shutil.rmtree(root, ignore_errors=True)
    (root / "takes").mkdir(parents=True)
    make = make_ict_takes if args.ict else make_takes
    model, takes, frames = make(root / "takes", args.shots)
    n, total = len(takes), len(takes) * frames
    print(
        f"{n} shots of {frames} frames; model: {model.num_vertices} vertices, "
        f"{model.num_bundles} markers, {len(model.to_bytes()) / 1e6:.1f} MB as bytes; "
        f"{os.cpu_count()} cores"
    )
    cores = os.cpu_count() or 1
    loops, runs = [], {1: [], 2: []}
    for r in range(args.repeat):  # interleaved, so a busy spell hits every configuration
        (root / f"loop{r}").mkdir()
        loops.append(plain_loop(model, takes, root / f"loop{r}"))
        for workers in (1, 2):
            runs[workers].append(on_cluster(model, takes, root / f"w{workers}-{r}", workers))
    loop = min(loops)
    print(f"best of {args.repeat} interleaved runs")
    print("| run | wall s | shots/min | frames/s | cluster start-up s | worker peak RSS MB |")
    print("|---|---|---|---|---|---|")
    print(
        f"| plain loop, 1 process x {cores} threads | {loop:.2f} | {60 * n / loop:.1f} | "
        f"{total / loop:.0f} | - | - |"
    )
    best = {}
    for workers, results in runs.items():
        started, took, tasks, memory = min(results, key=lambda x: x[1])
        best[workers] = (took, tasks)
        print(
            f"| LocalCluster, {workers} worker(s) x {max(1, cores // workers)} thread(s) | "
            f"{took:.2f} | {60 * n / took:.1f} | {total / took:.0f} | {started:.2f} | "
            f"{', '.join(str(round(m / 1e6)) for m in memory)} |"
        )
    took, tasks = best[1]
    print(
        f"engine overhead per shot, 1 worker: {(took - loop) / n * 1000:.0f} ms against the "
        f"loop; {(took - tasks) / n * 1000:.0f} ms outside the tasks (scheduling, the model's "
        "first transfer, the manifest)"
    )


if __name__ == "__main__":
    main()
