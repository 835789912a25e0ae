#!/usr/bin/env python3
"""End-to-end benchmark of lgi through its Python API: build, per-frame solve at 1 and 2 rayon
threads (one subprocess each: rayon reads RAYON_NUM_THREADS once), peak RSS, model save size and
load time, a dense-numpy reference of the sewing step, and the cost of writing results (a
1,000-frame USD point cache and OBJ frames with the neutral's polygons). Prints a markdown
table.

Workload: ICT-300 (ICT-FaceKit neutral + 57 shapes augmented to 300, markers_120) when the data
is found ($LGI_SHARED_DATA, else ../shared/data beside the checkout); else the shipped sample.
Frames: bundle positions of seeded random convex combinations of 1-4 dataset shapes plus
Gaussian marker noise (0.05 data units), so some targets fall outside every tet.

    python scripts/bench.py [--frames N] [--quick] [--shapes 57] [--streamed 20000]
                            [--out docs/performance.md]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
ICT_SHAPES = 300
DROPOUT_FRAMES = 500
NOISE = 0.05
SEED = 1


def load_workload(shapes: int = ICT_SHAPES) -> tuple[str, Any, np.ndarray]:
    from lgi.lab import ict

    folder = ict.find(os.environ.get(ict.ENV), start=ROOT)
    if folder is not None:
        base = ict.load_dataset(folder)
        data = base.augmented(shapes) if shapes > base.num_shapes else base
        markers = ict.load_markers(folder)
        name = (
            f"ICT-{data.num_shapes}: ICT-FaceKit neutral ({data.num_vertices} vertices) + "
            f"{base.num_shapes} shapes augmented to {data.num_shapes}, {len(markers)} markers"
        )
        return name, data, markers
    from lgi.lab.sample import make_sample, sample_dataset

    s = make_sample(0)
    data = sample_dataset(s)
    name = (
        f"sample (ICT data not found): synthetic face ({data.num_vertices} vertices), "
        f"{data.num_shapes} shapes, {len(s.markers_rest)} markers"
    )
    return name, data, np.asarray(s.markers_rest)


def load_base_dataset() -> Any | None:
    """ICT-FaceKit's own shapes (57, with jawOpen), or None where the data is absent."""
    from lgi.lab import ict

    folder = ict.find(os.environ.get(ict.ENV), start=ROOT)
    return None if folder is None else ict.load_dataset(folder)


def make_frames(model: Any, data: Any, n: int, seed: int = SEED) -> np.ndarray:
    """Bundle positions of random convex combinations of 1-4 shapes, plus marker noise."""
    rng = np.random.default_rng(seed)
    x0 = data.neutral
    shapes = data.shapes
    out = []
    chunk = 25
    for start in range(0, n, chunk):
        m = min(chunk, n - start)
        meshes = np.repeat(x0[None], m, axis=0)
        for f in range(m):
            k = rng.integers(1, 5)
            ids = rng.integers(0, data.num_shapes, size=k)
            w = rng.random(k) + 1e-3
            w /= w.sum()
            for i, wi in zip(ids, w, strict=True):
                meshes[f] += wi * shapes[i]
        out.append(model.bundle_positions(meshes))
    frames = np.concatenate(out)
    return frames + rng.normal(0.0, NOISE, size=frames.shape)


def with_dropouts(frames: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """`frames` (F, B, 3) with a fresh random set of `k` markers missing (NaN) on every frame."""
    out = frames.copy()
    for f in range(len(out)):
        out[f, rng.choice(out.shape[1], k, replace=False)] = np.nan
    return out


def numpy_sew(
    x0: np.ndarray,
    shapes0: np.ndarray,
    csr: dict[str, np.ndarray],
    ch_s: np.ndarray,
    ch_w: np.ndarray,
) -> np.ndarray:
    """Dense numpy sewing: x0 + sum_i W_vi sum_j a_ij s_k(v), with shapes0[0] = 0 (neutral)."""
    indptr, cols, vals = csr["indptr"], csr["indices"], csr["data"]
    rows = csr["rows"]
    k = ch_s[cols]  # (nnz, 4) shape ids, 0 = neutral
    f = vals[:, None] * ch_w[cols]  # (nnz, 4)
    contrib = np.einsum("nj,njc->nc", f, shapes0[k, rows[:, None]])
    d = np.zeros_like(x0)
    # Rows are contiguous in CSR: a segmented sum (empty rows keep 0).
    nonempty = indptr[:-1] < indptr[1:]
    d[nonempty] = np.add.reduceat(contrib, indptr[:-1][nonempty], axis=0)
    return x0 + d


def memcpy_bandwidth(mb: int = 256, reps: int = 5) -> float:
    """Read + write bytes per second of np.copyto on large arrays (best of reps)."""
    src = np.ones(mb * (1 << 20) // 8)
    dst = np.empty_like(src)
    best = float("inf")
    for _ in range(reps):
        t = time.perf_counter()
        np.copyto(dst, src)
        best = min(best, time.perf_counter() - t)
    return 2 * src.nbytes / best


def per_frame_ms(solve: Any, frames: np.ndarray, **options: Any) -> tuple[np.ndarray, Any]:
    """Milliseconds each frame of `solve(frames, progress=..., **options)` took, and what it
    returned."""
    stamps: list[float] = []
    t0 = time.perf_counter()
    res = solve(frames, progress=lambda _f: stamps.append(time.perf_counter()), **options)
    return np.diff(np.array([t0, *stamps])) * 1e3, res


PATH_PASSES = 3


def whole_call_ms(
    solve: Any, frames: np.ndarray, passes: int = PATH_PASSES, **options: Any
) -> float:
    """Milliseconds per frame of the fastest of `passes` whole `solve(frames, **options)` calls
    (the jaw poses and fits run before the first frame is sewn, so a per-frame median
    between progress callbacks would miss them; contention only adds time)."""
    best = np.inf
    for _ in range(passes):
        t = time.perf_counter()
        solve(frames, **options)
        best = min(best, time.perf_counter() - t)
    return float(best / len(frames) * 1e3)


def path_rows(data: Any, markers: np.ndarray, frames: np.ndarray, exact: Any) -> dict[str, Any]:
    """The solve paths users run, side by side in this process (ICT's default build: a jaw
    rig from jawOpen): the exact mode (the paper's, no rig), the default `solve(frames)` (jaw
    pose from the frame's fit, refined) and the recommended `solve(frames,
    marker_noise=NOISE)`, clean and with a fresh random 10 % of the markers missing on every
    frame (a new set each pass), beside the dense evaluation of every shape. The stages of
    the recommended path come from the same build solved with less: at the rest pose, with
    the poses it found given (the jaw's unskinning and the sewing's jaw map), with those
    poses and the noise (the fit, noise-aware targets and the fit candidate); the pose is
    what remains."""
    import lgi

    out: dict[str, Any] = {}
    rec = lgi.Model.build(data, markers)
    out["paths_jaw"] = rec.jaw_rig is not None
    buf = np.empty((len(frames), data.num_vertices, 3))
    core = rec.core
    first = core.solve(frames, jaw="fit", marker_noise=NOISE, out=buf)
    theta = np.asarray(first.jaw_theta) if first.jaw_theta is not None else None
    out["paths_exact_ms"] = whole_call_ms(exact.core.solve, frames, out=buf)
    out["paths_default_ms"] = whole_call_ms(core.solve, frames, jaw="fit", out=buf)
    out["paths_recommended_ms"] = whole_call_ms(
        core.solve, frames, jaw="fit", marker_noise=NOISE, out=buf
    )
    out["paths_rest_ms"] = whole_call_ms(core.solve, frames, jaw=None, out=buf)
    if theta is not None:
        out["paths_given_ms"] = whole_call_ms(core.solve, frames, jaw=theta, out=buf)
        out["paths_given_noise_ms"] = whole_call_ms(
            core.solve, frames, jaw=theta, marker_noise=NOISE, out=buf
        )
    rng = np.random.default_rng(SEED + 3)
    k = max(1, round(0.1 * frames.shape[1]))
    takes = [with_dropouts(frames, k, rng) for _ in range(PATH_PASSES)]

    def messy(solve: Any, **options: Any) -> float:
        return min(whole_call_ms(solve, t, passes=1, **options) for t in takes)

    out["paths_dropout_markers"] = k
    out["paths_exact_dropout_ms"] = messy(exact.core.solve, out=buf)
    out["paths_default_dropout_ms"] = messy(core.solve, jaw="fit", out=buf)
    out["paths_recommended_dropout_ms"] = messy(core.solve, jaw="fit", marker_noise=NOISE, out=buf)
    flat = data.shapes.reshape(data.shapes.shape[0], -1)
    weights = rng.uniform(0, 1, (len(frames), flat.shape[0])).astype(np.float32)
    x0 = data.neutral.astype(np.float32).reshape(-1)

    def dense(w: np.ndarray, **_: Any) -> None:
        for row in w:
            x0 + row @ flat

    out["paths_dense_ms"] = whole_call_ms(dense, weights)
    out["paths_frames"] = len(frames)
    out["paths_shapes"] = int(data.num_shapes)
    return out


def paths_worker(args: argparse.Namespace) -> dict[str, Any]:
    import lgi

    out: dict[str, Any] = {"threads": os.environ.get("RAYON_NUM_THREADS")}
    name, data, markers = load_workload(args.shapes)
    out["workload"] = name
    exact = lgi.Model.build(data, markers, jaw=None)
    frames = make_frames(exact, data, args.frames)
    out.update(path_rows(data, markers, frames, exact))
    return out


def worker(args: argparse.Namespace) -> dict[str, Any]:
    import lgi

    out: dict[str, Any] = {"threads": os.environ.get("RAYON_NUM_THREADS")}
    name, data, markers = load_workload(args.shapes)
    out["workload"] = name
    t = time.perf_counter()
    # The paper's model (no jaw rig): the rows below time the core's solve modes on it.
    model = lgi.Model.build(data, markers, jaw=None)
    out["build_s"] = time.perf_counter() - t
    frames = make_frames(model, data, args.frames)
    per, res = per_frame_ms(model.core.solve, frames, temporal=True)
    total = per.sum() / 1e3
    out["solve_ms_median"] = float(np.median(per))
    out["solve_ms_p95"] = float(np.percentile(per, 95))
    out["solve_ms_mean"] = float(per.mean())
    out["fps"] = len(frames) / total
    # Again into the now-warm result array (`out=`): what a pipeline solving chunk after chunk
    # into one buffer sees, without the first touch of fresh pages.
    warm = np.asarray(res.vertices)
    per_warm, _ = per_frame_ms(model.core.solve, frames, temporal=True, out=warm)
    out["solve_out_ms_median"] = float(np.median(per_warm))
    out["solve_out_ms_p95"] = float(np.percentile(per_warm, 95))
    out["frames"] = len(frames)
    out["projected_fraction"] = float(np.asarray(res.choices.projected).mean())
    out["peak_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    # Messy capture, after the RSS reading (its result would add to the peak): 2 % and 10 %
    # of the markers missing, a fresh set on every one of DROPOUT_FRAMES frames (the take's
    # frames repeated; seeded), the worst case for the sewing plans: no set repeats, so every
    # frame makes its plan from the rows the model keeps without one missing bundle or a
    # pair. Those are made as the take goes on (every bundle's at the first missing marker):
    # the first 20 frames show that; the median over the rest is a frame's cost while pairs
    # are still being kept; the take solved again, once they are.
    rng = np.random.default_rng(SEED + 1)
    for pct in (2, 10):
        k = max(1, round(pct / 100 * frames.shape[1]))
        drop = with_dropouts(np.resize(frames, (DROPOUT_FRAMES, *frames.shape[1:])), k, rng)
        per_drop, _ = per_frame_ms(model.core.solve, drop, temporal=True)
        out[f"dropout{pct}_ms_median"] = float(np.median(per_drop[20:]))
        out[f"dropout{pct}_ms_first20"] = float(per_drop[:20].mean())
        out[f"dropout{pct}_markers"] = k
        # The same take again: every set's rows are kept by now (a long take's later frames),
        # though its plans are not (the plan cache holds 64 sets).
        again, _ = per_frame_ms(model.core.solve, drop, temporal=True)
        out[f"dropout{pct}_ms_again"] = float(np.median(again))
    out["dropout_frames"] = DROPOUT_FRAMES
    # What a blendshape solver spends at least to output a mesh: the dense evaluation
    # x0 + sum_k w_k s_k of every shape (float32, numpy/BLAS at this thread count).
    flat = data.shapes.reshape(data.shapes.shape[0], -1)
    weights = rng.uniform(0, 1, (20, flat.shape[0])).astype(np.float32)
    x0 = data.neutral.astype(np.float32).reshape(-1)
    dense = []
    for w in weights:
        t = time.perf_counter()
        mesh = x0 + w @ flat
        dense.append(time.perf_counter() - t)
    del mesh
    out["dense_eval_ms_median"] = float(np.median(dense) * 1e3)
    # Noise-aware solving (the recommended path's core: the fit candidate, the noise-aware
    # targets) on the same frames, at their noise, beside the exact solve above.
    per_noise, _ = per_frame_ms(model.core.solve, frames, temporal=True, marker_noise=NOISE)
    out["noise_ms_median"] = float(np.median(per_noise))
    out["noise_ms_p95"] = float(np.percentile(per_noise, 95))
    # Both again into the warm result array: a fresh result's first touch costs the
    # noise-aware solve more (its ratio above swung 1.97-2.48 x between runs of one build).
    per_noise_out, _ = per_frame_ms(
        model.core.solve, frames, temporal=True, marker_noise=NOISE, out=warm
    )
    out["noise_out_ms_median"] = float(np.median(per_noise_out))
    # The paths users run (the default build with its jaw rig), beside the exact mode.
    out.update(path_rows(data, markers, frames, model))
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "model.lgi"
        t = time.perf_counter()
        model.save(p)
        out["save_s"] = time.perf_counter() - t
        out["save_mib"] = p.stat().st_size / (1 << 20)
        # Best of three: the first read may come from disk rather than the page cache.
        loads = []
        for _ in range(3):
            t = time.perf_counter()
            lgi.Model.load(p)
            loads.append(time.perf_counter() - t)
        out["load_s"] = min(loads)
        out["load_s_max"] = max(loads)
    if not args.reference:
        return out

    # Numpy reference of the sewing step on the frames just solved.
    w = model.core.sew_weights()
    indptr = np.asarray(w["indptr"], dtype=np.int64)
    csr = {
        "indptr": indptr,
        "indices": np.asarray(w["indices"], dtype=np.int64),
        "data": np.asarray(w["data"], dtype=np.float64),
        "rows": np.repeat(np.arange(len(indptr) - 1), np.diff(indptr)),
    }
    x0 = data.neutral
    shapes0 = np.concatenate([np.zeros((1, *x0.shape), np.float32), data.shapes])
    ch_s = np.asarray(res.choices.shapes, dtype=np.int64)
    ch_w = np.asarray(res.choices.weights, dtype=np.float64)
    nref = min(len(frames), 20 if args.quick else 50)
    times = []
    touched = []
    for f in range(nref):
        t = time.perf_counter()
        numpy_sew(x0, shapes0, csr, ch_s[f], ch_w[f])
        times.append(time.perf_counter() - t)
        active = ((ch_w[f] != 0) & (ch_s[f] != 0)).sum(axis=1)  # shapes read per bundle
        touched.append(int(active[csr["indices"]].sum()))
    out["numpy_sew_ms_median"] = float(np.median(times) * 1e3)
    out["sew_nnz"] = len(csr["indices"])
    v = x0.shape[0]
    out["vertices"] = v
    out["sew_bytes_per_frame"] = float(v * 24 + np.mean(touched) * 12 + v * 24)
    out["memcpy_gbps"] = memcpy_bandwidth() / 1e9
    out.update(writing(data, np.asarray(res.vertices)))
    out.update(baselines(data, markers, frames, 20 if args.quick else 50))
    return out


USD_FRAMES = 1000


def streamed(args: argparse.Namespace) -> dict[str, Any]:
    """Peak RSS and time of a long take solved chunk by chunk from a memmap on disk
    (`Model.solve_iter`, the recommended build and exact targets), the results dropped as
    they come: the memory a streamed take needs beyond the model."""
    import lgi

    name, data, markers = load_workload(args.streamed_shapes)
    model = lgi.Model.build(data, markers)
    base = make_frames(model, data, 500)
    with tempfile.TemporaryDirectory() as d:
        frames = np.lib.format.open_memmap(
            Path(d) / "take.npy",
            mode="w+",
            dtype=np.float64,
            shape=(args.streamed, *base.shape[1:]),
        )
        for a in range(0, args.streamed, len(base)):
            n = min(len(base), args.streamed - a)
            frames[a : a + n] = base[:n] + 1e-4 * (a // len(base))
        frames.flush()
        del frames
        take = np.load(Path(d) / "take.npy", mmap_mode="r")
        before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        t = time.perf_counter()
        out = np.empty((256, data.neutral.shape[0], 3))
        for _ in model.solve_iter(take, chunk=256, out=out, quiet=True):
            pass
        seconds = time.perf_counter() - t
        del take
    return {
        "streamed_workload": name,
        "streamed_frames": args.streamed,
        "streamed_s": seconds,
        "streamed_rss_before_mib": before,
        "streamed_peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "threads": os.environ.get("RAYON_NUM_THREADS"),
    }


def writing(data: Any, vertices: np.ndarray) -> dict[str, Any]:
    """Time to write a `USD_FRAMES`-frame USD point cache chunk by chunk as `lgi solve` does
    (100 frames a chunk, file included); and OBJ frames of the same mesh."""
    from lgi.io.obj import write_obj_sequence
    from lgi.io.topology import topology
    from lgi.io.usd import UsdCache

    topo = topology(data)
    out: dict[str, Any] = {"usd_frames": USD_FRAMES, "faces": topo.num_faces}
    with tempfile.TemporaryDirectory() as d:
        t = time.perf_counter()
        cache = UsdCache(Path(d) / "take.usd", topo, fps=60.0, units="cm")
        for a in range(0, USD_FRAMES, 100):
            f = np.arange(a, min(USD_FRAMES, a + 100))
            # Distinct frames (the solved ones, cycled and offset): USD's crate files store
            # an array once however often it repeats, which would flatter the cycle.
            cache.add(vertices[f % len(vertices)] + 1e-3 * f[:, None, None])
        path = cache.close()
        out["usd_s"] = time.perf_counter() - t
        out["usd_mib"] = path.stat().st_size / (1 << 20)
        n_obj = 10
        t = time.perf_counter()
        write_obj_sequence(Path(d) / "obj", topo, vertices[:n_obj])
        out["obj_ms"] = (time.perf_counter() - t) / n_obj * 1e3
    return out


def baselines(data: Any, markers: np.ndarray, frames: np.ndarray, n: int) -> dict[str, Any]:
    """Setup time and per-frame solve time of every baseline on the first `n` frames (one call
    over all n frames, as a pipeline would; per frame = total / n)."""
    from lgi.lab.baselines import BlendshapeFit, DisplacementInterpolation, LgiRbf

    out: dict[str, Any] = {}
    for key, make in [
        ("displacement", lambda: DisplacementInterpolation(data, markers)),
        ("blendshape", lambda: BlendshapeFit(data, markers)),
        ("lgi_rbf", lambda: LgiRbf(data, markers)),
    ]:
        t = time.perf_counter()
        method = make()
        out[f"{key}_setup_s"] = time.perf_counter() - t
        t = time.perf_counter()
        method.solve(frames[:n], quiet=True)
        out[f"{key}_ms"] = (time.perf_counter() - t) / n * 1e3
    return out


def run_threads(
    threads: int, args: argparse.Namespace, reference: bool, stream: bool = False
) -> dict[str, Any]:
    # numpy's BLAS gets the same thread count, so the baselines compare like for like.
    env = dict(
        os.environ,
        RAYON_NUM_THREADS=str(threads),
        OPENBLAS_NUM_THREADS=str(threads),
        OMP_NUM_THREADS=str(threads),
    )
    cmd = [sys.executable, __file__, "--worker", "--frames", str(args.frames)]
    cmd += ["--shapes", str(args.shapes), "--streamed", str(args.streamed)]
    cmd += ["--streamed-shapes", str(args.streamed_shapes)]
    if args.quick:
        cmd.append("--quick")
    if args.paths:
        cmd.append("--paths")
    if reference:
        cmd.append("--reference")
    if stream:
        cmd.append("--stream-worker")
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if p.returncode != 0:
        sys.stderr.write(p.stderr)
        raise SystemExit(f"worker with {threads} thread(s) failed ({p.returncode})")
    return json.loads(p.stdout.strip().splitlines()[-1])


def machine() -> str:
    model = platform.processor() or "unknown"
    try:
        for line in subprocess.run(["lscpu"], capture_output=True, text=True).stdout.splitlines():
            if line.startswith("Model name:"):
                model = line.split(":", 1)[1].strip()
    except OSError:
        pass
    ram = "unknown"
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                ram = f"{int(line.split()[1]) / (1 << 20):.1f} GiB"
    except OSError:
        pass
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return f"{model}; {cores} cores available; {ram} RAM; Python {platform.python_version()}"


def path_table_rows(r1: dict[str, Any], r2: dict[str, Any]) -> list[tuple[str, str]]:
    """The rows of `path_rows`: each path's mean per frame at 1 and 2 threads, as a ratio to
    the exact mode and to the dense evaluation of the same run, then the recommended path's
    stages."""
    jaw = "a jaw rig from jawOpen" if r1["paths_jaw"] else "no jaw shapes, so no rig"
    k = r1["paths_dropout_markers"]
    rows: list[tuple[str, str]] = []

    def cell(r: dict[str, Any], key: str, clean: str | None = None) -> str:
        ms = r[key]
        text = (
            f"{ms:.2f} ms = {ms / r['paths_exact_ms']:.2f} x exact, "
            f"{ms / r['paths_dense_ms']:.2f} x dense"
        )
        if clean is not None:
            text += f", {ms / r[clean]:.2f} x clean"
        return text

    paths = [
        ("paths_exact_ms", None, "Exact mode (the paper's; no rig), `core.solve(frames)`"),
        ("paths_default_ms", None, f"Default `solve(frames)` ({jaw}; pose from the fit)"),
        ("paths_recommended_ms", None, f"Recommended `solve(frames, marker_noise={NOISE})`"),
        (
            "paths_exact_dropout_ms",
            "paths_exact_ms",
            f"Exact mode, {k} fresh missing markers (10 %) every frame",
        ),
        (
            "paths_default_dropout_ms",
            "paths_default_ms",
            f"Default `solve(frames)`, {k} fresh missing markers every frame",
        ),
        (
            "paths_recommended_dropout_ms",
            "paths_recommended_ms",
            f"Recommended, {k} fresh missing markers every frame",
        ),
    ]
    for key, clean, label in paths:
        rows.append(
            (
                f"{label}: mean per frame of the whole call (best of {PATH_PASSES})",
                f"1 thread {cell(r1, key, clean)}; 2 threads {cell(r2, key, clean)}",
            )
        )
    rows.append(
        (
            f"Dense evaluation of all {r1['paths_shapes']} shapes (numpy float32), per frame",
            f"1 thread {r1['paths_dense_ms']:.2f} ms; 2 threads {r2['paths_dense_ms']:.2f} ms",
        )
    )
    if "paths_given_ms" in r1:

        def stages(r: dict[str, Any]) -> str:
            jaw_map = r["paths_given_ms"] - r["paths_rest_ms"]
            noise = r["paths_given_noise_ms"] - r["paths_given_ms"]
            pose = r["paths_recommended_ms"] - r["paths_given_noise_ms"]
            return (
                f"rest pose {r['paths_rest_ms']:.2f} + jaw map {jaw_map:.2f} + "
                f"fit and noise {noise:.2f} + pose {pose:.2f} = "
                f"{r['paths_recommended_ms']:.2f} ms"
            )

        rows.append(
            (
                "Recommended path by stage (the same build solved at the rest pose, with its "
                "poses given, with those poses and the noise)",
                f"1 thread: {stages(r1)}; 2 threads: {stages(r2)}",
            )
        )
    return rows


def paths_table(r1: dict[str, Any], r2: dict[str, Any]) -> str:
    lines = ["| Measure | Value |", "|---|---|", f"| Workload | {r1['workload']} |"]
    lines.append(f"| Frames | {r1['paths_frames']} |")
    lines += [f"| {a} | {b} |" for a, b in path_table_rows(r1, r2)]
    return "\n".join(lines)


def table(r1: dict[str, Any], r2: dict[str, Any]) -> str:
    rows = [
        ("Workload", r1["workload"]),
        (
            "Frames solved (temporal)",
            f"{r1['frames']} ({100 * r1['projected_fraction']:.1f} % of targets projected)",
        ),
        ("Build time", f"{r1['build_s']:.2f} s (1 thread), {r2['build_s']:.2f} s (2 threads)"),
    ]
    for r in (r1, r2):
        rows.append(
            (
                f"Solve per frame, {r['threads']} thread(s)",
                f"median {r['solve_ms_median']:.2f} ms, p95 {r['solve_ms_p95']:.2f} ms, "
                f"{r['fps']:.0f} frames/s",
            )
        )
    for r in (r1, r2):
        rows.append(
            (
                f"Solve per frame into a reused `out=` array, {r['threads']} thread(s)",
                f"median {r['solve_out_ms_median']:.2f} ms, p95 {r['solve_out_ms_p95']:.2f} ms",
            )
        )
    for pct in (2, 10):
        for r in (r1, r2):
            rows.append(
                (
                    f"Solve per frame with a new set of {r[f'dropout{pct}_markers']} missing "
                    f"markers ({pct} %) every frame ({r['dropout_frames']} frames), "
                    f"{r['threads']} thread(s)",
                    f"median after the first 20 {r[f'dropout{pct}_ms_median']:.2f} ms = "
                    f"{r[f'dropout{pct}_ms_median'] / r['solve_ms_median']:.2f} x clean; "
                    f"first 20 frames {r[f'dropout{pct}_ms_first20']:.2f} ms; the take again "
                    f"{r[f'dropout{pct}_ms_again']:.2f} ms = "
                    f"{r[f'dropout{pct}_ms_again'] / r['solve_ms_median']:.2f} x clean",
                )
            )
    for r in (r1, r2):
        rows.append(
            (
                f"Dense blendshape evaluation of every shape (numpy float32), "
                f"{r['threads']} thread(s)",
                f"median {r['dense_eval_ms_median']:.2f} ms = "
                f"{r['dense_eval_ms_median'] / r['solve_ms_median']:.2f} x lgi's solve",
            )
        )
    for r in (r1, r2):
        rows.append(
            (
                f"Noise-aware solve per frame (`marker_noise={NOISE}`), {r['threads']} thread(s)",
                f"median {r['noise_ms_median']:.2f} ms, p95 {r['noise_ms_p95']:.2f} ms = "
                f"{r['noise_ms_median'] / r['solve_ms_median']:.2f} x the exact solve",
            )
        )
    for r in (r1, r2):
        rows.append(
            (
                f"Noise-aware solve per frame into a reused `out=` array, {r['threads']} thread(s)",
                f"median {r['noise_out_ms_median']:.2f} ms = "
                f"{r['noise_out_ms_median'] / r['solve_out_ms_median']:.2f} x the exact solve "
                "into `out=`",
            )
        )
    rows += path_table_rows(r1, r2)
    if "streamed_frames" in r2:
        rows.append(
            (
                f"Streamed take: {r2['streamed_frames']} frames from a memmap through "
                "`Model.solve_iter(chunk=256, out=...)`, default build of "
                f"{r2['streamed_workload'].split(':')[0]}, 2 threads",
                f"peak RSS {r2['streamed_peak_rss_mib']:.0f} MiB "
                f"({r2['streamed_rss_before_mib']:.0f} MiB before the solve); "
                f"{r2['streamed_s'] / r2['streamed_frames'] * 1e3:.2f} ms/frame",
            )
        )
    rows += [
        (
            "Peak RSS (build + solve)",
            f"{r1['peak_rss_mib']:.0f} MiB (1 thread), {r2['peak_rss_mib']:.0f} MiB (2 threads)",
        ),
        ("Model file", f"{r1['save_mib']:.1f} MiB, saved in {r1['save_s']:.2f} s"),
        (
            "Model load (best / worst of 3)",
            f"{r1['load_s']:.2f} / {r1['load_s_max']:.2f} s (1 thread), "
            f"{r2['load_s']:.2f} / {r2['load_s_max']:.2f} s (2 threads)",
        ),
        (
            "Numpy sewing reference (per frame)",
            f"{r1['numpy_sew_ms_median']:.2f} ms = "
            f"{r1['numpy_sew_ms_median'] / r1['solve_ms_median']:.1f} x "
            f"lgi's full 1-thread solve "
            f"({r1['numpy_sew_ms_median'] / r2['solve_ms_median']:.1f} x 2-thread)",
        ),
        (
            "Sewing memory traffic (lower bound)",
            f"{r1['sew_bytes_per_frame'] / 1e6:.2f} MB/frame ({r1['sew_nnz']} weights); "
            f"at the numpy memcpy bandwidth {r1['memcpy_gbps']:.1f} GB/s: "
            f"{r1['sew_bytes_per_frame'] / (r1['memcpy_gbps'] * 1e9) * 1e3:.3f} ms",
        ),
    ]
    usd_ms = r1["usd_s"] / r1["usd_frames"] * 1e3
    rows += [
        (
            f"USD point cache of {r1['usd_frames']} frames ({r1['faces']} faces), written "
            "chunk by chunk",
            f"{r1['usd_s']:.2f} s = {usd_ms:.2f} ms/frame = "
            f"{usd_ms / r1['solve_ms_mean']:.2f} x lgi's 1-thread solve "
            f"({usd_ms / r2['solve_ms_mean']:.2f} x 2-thread); {r1['usd_mib']:.0f} MiB",
        ),
        (
            "OBJ frame with the neutral's polygons",
            f"{r1['obj_ms']:.1f} ms/frame = {r1['obj_ms'] / r1['solve_ms_mean']:.1f} x "
            "lgi's 1-thread solve",
        ),
    ]
    for key, label in [
        ("displacement", "Baseline: displacement interpolation (biharmonic RBF)"),
        ("blendshape", "Baseline: blendshape fit (active set)"),
        ("lgi_rbf", "Baseline: LGI-RBF (LGI choices + Gaussian UV spread + RBF)"),
    ]:
        ms = r1[f"{key}_ms"]
        rows.append(
            (
                f"{label}, 1 thread",
                f"{ms:.2f} ms/frame = {ms / r1['solve_ms_median']:.2f} x lgi's 1-thread solve; "
                f"setup {r1[f'{key}_setup_s']:.2f} s",
            )
        )
    lines = ["| Measure | Value |", "|---|---|"]
    lines += [f"| {a} | {b} |" for a, b in rows]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=500)
    ap.add_argument("--quick", action="store_true", help="100 frames, shorter numpy reference")
    ap.add_argument(
        "--shapes",
        type=int,
        default=ICT_SHAPES,
        help=f"ICT shapes: the 57 of ICT-FaceKit augmented to this many (default {ICT_SHAPES})",
    )
    ap.add_argument("--out", type=Path, help="write the table and machine to this markdown file")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--reference", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument(
        "--streamed",
        type=int,
        default=20000,
        help="frames of the streamed take whose peak RSS is measured (default 20000; 0: none)",
    )
    ap.add_argument(
        "--streamed-shapes",
        type=int,
        default=57,
        help="ICT shapes of the streamed take's model (default 57: ICT-FaceKit as shipped)",
    )
    ap.add_argument("--stream-worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument(
        "--paths",
        action="store_true",
        help="only the solve paths users run (exact, default, recommended; clean and with "
        "10 %% dropouts; the recommended path's stages), at 1 and 2 threads",
    )
    args = ap.parse_args()
    if args.quick:
        args.frames = min(args.frames, 100)
    if args.worker:
        if args.paths:
            print(json.dumps(paths_worker(args)))
        else:
            print(json.dumps(streamed(args) if args.stream_worker else worker(args)))
        return
    if args.paths:
        r1 = run_threads(1, args, reference=False)
        r2 = run_threads(2, args, reference=False)
        text = paths_table(r1, r2)
        print(f"Machine: {machine()}\n\n{text}")
        if args.out:
            marker = f"bench.py:paths-{r1['workload'].split(':')[0]}"
            write_out(args.out, f"Machine: {machine()}\n\n{text}\n", marker=marker)
        return
    r1 = run_threads(1, args, reference=True)
    r2 = run_threads(2, args, reference=False)
    if args.streamed > 0:
        r2.update(run_threads(2, args, reference=False, stream=True))
    text = table(r1, r2)
    desc = machine()
    print(f"Machine: {desc}\n\n{text}")
    if args.out:
        write_out(args.out, f"Machine: {desc}\n\n{text}\n")


def write_out(path: Path, block: str, marker: str = "bench.py") -> None:
    """Replaces the block between the `<!-- MARKER:begin -->` and `<!-- MARKER:end -->` lines
    (keeping hand-written notes around it), or writes a new file with just the block. The full
    table's marker is `bench.py`; `--paths` writes its own, one per workload
    (`bench.py:paths-ICT-300`)."""
    BEGIN, END = f"<!-- {marker}:begin -->", f"<!-- {marker}:end -->"
    block = f"{BEGIN}\n{block}{END}"
    old = path.read_text() if path.is_file() else ""
    if BEGIN in old and END in old:
        head, rest = old.split(BEGIN, 1)
        text = head + block + rest.split(END, 1)[1]
    else:
        text = "# Performance\n\n" + block + "\n"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


if __name__ == "__main__":
    main()
