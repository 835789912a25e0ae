"""The CLI's demos. `lgi demo` (`run`): generate the built-in sample, build its model, solve its
held-out performance, write meshes and a short report. `lgi helmet-demo` (`helmet_demo`): the
sample filmed by the synthetic helmet and taken through the whole capture front end, each stage
scored against its truth. Everything comes from the project's own code and a seed."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lgi.capture.calibration import save_cameras
from lgi.capture.frontend import process
from lgi.data.dataset import Dataset
from lgi.io.atomic import atomic_path, write_text
from lgi.io.obj import write_obj
from lgi.io.result import write_sequence_npz
from lgi.lab import helmet
from lgi.lab.sample import describe, make_sample, sample_dataset
from lgi.plan.noise import estimate_marker_noise
from lgi.solve.model import Model

F64 = NDArray[np.float64]


def _say(quiet: bool, msg: str) -> None:
    if not quiet:
        print(msg, flush=True)


def run(out: Path, seed: int = 0, quiet: bool = False) -> int:
    """Runs the demo into folder `out`; returns a process exit code."""
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    sample = make_sample(seed)
    t_sample = time.perf_counter() - t0
    print(describe(sample))
    data = sample_dataset(sample)
    t0 = time.perf_counter()
    model = Model.build(data, sample.markers_rest)
    t_build = time.perf_counter() - t0
    _say(quiet, f"built model: {model.num_bundles} bundles in {t_build:.2f} s")
    # The recommended path: the take's marker noise, estimated from the take itself.
    sigma = estimate_marker_noise(sample.performance)
    _say(quiet, f"estimated marker noise: {10 * sigma:.3f} mm per coordinate")
    t0 = time.perf_counter()
    result = model.solve(sample.performance, quiet=quiet, marker_noise=sigma)
    t_solve = time.perf_counter() - t0
    nf = sample.performance.shape[0]
    _say(quiet, f"solved {nf} frames in {t_solve:.2f} s ({1e3 * t_solve / nf:.2f} ms/frame)")

    err = np.linalg.norm(result.vertices - sample.truth, axis=2)  # (F, V)
    diag = model.diagonal
    rel_res = result.bundle_residuals.max() / diag
    stats = {
        "frames": nf,
        "vertices": int(err.shape[1]),
        "bundles": model.num_bundles,
        "estimated marker noise (mm)": 10 * sigma,
        "missing marker entries": int(result.missing.sum()),
        "projected choices": int(result.choices.projected.sum()),
        "vertex error mean (mm)": 10 * float(err.mean()),
        "vertex error p95 (mm)": 10 * float(np.percentile(err, 95)),
        "vertex error max (mm)": 10 * float(err.max()),
        "max bundle residual / diagonal": float(rel_res),
        "sample generation (s)": t_sample,
        "build (s)": t_build,
        "solve (ms/frame)": 1e3 * t_solve / nf,
    }
    write_sequence_npz(
        out / "performance.npz",
        vertices=result.vertices.astype(np.float32),
        bundle_residuals=result.bundle_residuals,
        missing=result.missing,
    )
    frames_dir = out / "frames"
    frames_dir.mkdir(exist_ok=True)
    for f in sorted({0, nf // 3, (2 * nf) // 3, nf - 1}):
        write_obj(
            frames_dir / f"frame_{f:04d}.obj",
            result.vertices[f],
            sample.triangles,
            sample.uvs,
            sample.uv_triangles,
        )
    lines = [
        "# lgi demo report",
        "",
        f"Sample seed {seed}. Errors are against the sample's ground-truth meshes; the markers",
        "carry noise and dropouts, so the error includes the noise the solve must interpolate.",
        "",
        "| quantity | value |",
        "|---|---|",
        *(
            f"| {k} | {v:.4g} |" if isinstance(v, float) else f"| {k} | {v} |"
            for k, v in stats.items()
        ),
        "",
    ]
    write_text(out / "report.md", "\n".join(lines))
    print("\n".join(lines[5:]))
    _say(quiet, f"wrote {out}/report.md, {out}/performance.npz and {frames_dir}/*.obj")
    _compare(out, sample, data, model, result, t_solve, quiet)
    return 0


def _compare(out: Path, sample, data: Dataset, model: Model, result, t_solve: float, quiet: bool):  # type: ignore[no-untyped-def]
    """All methods on the held-out performance: the evaluation table and an error panel."""
    from lgi.lab import render, scoring
    from lgi.lab.baselines import BlendshapeFit, DisplacementInterpolation, LgiRbf

    _say(quiet, "comparing with the baselines ...")
    methods: dict[str, DisplacementInterpolation | BlendshapeFit | LgiRbf] = {
        DisplacementInterpolation.label: DisplacementInterpolation(data, sample.markers_rest),
        BlendshapeFit.label: BlendshapeFit(data, sample.markers_rest),
        LgiRbf.label: LgiRbf(data, sample.markers_rest),
    }
    perf, truth = sample.performance, sample.truth
    rows, verts = [], {}
    for name, m in methods.items():
        t0 = time.perf_counter()
        res = m.solve(perf, quiet=True)
        rows.append(scoring.score(name, res, truth, time.perf_counter() - t0))
        verts[name] = res.vertices
    rows.append(scoring.score("LGI", result, truth, t_solve))
    verts["LGI"] = result.vertices
    table = scoring.to_markdown(rows)
    scoring.to_csv(rows, out / "results.csv")
    write_text(
        out / "results.md",
        "# Held-out performance, all methods (errors in cm; residual relative to diagonal)\n\n"
        + table,
    )
    print(table, end="")
    # The most expressive frame: largest mean motion from the neutral.
    f = int(np.argmax(np.linalg.norm(truth - sample.neutral[None], axis=2).mean(axis=1)))
    meshes = {"ground truth": truth[f], **{k: v[f] for k, v in verts.items()}}
    errors = {k: np.linalg.norm(v[f] - truth[f], axis=1) for k, v in verts.items()}
    # Each method on its own colour scale: on one shared scale the worst method's errors set
    # it and LGI's, ten times smaller, are invisible.
    render.panel(out / "panel.png", meshes, sample.triangles, errors, units="cm", per_column=True)
    _say(quiet, f"wrote {out}/results.md, {out}/results.csv and {out}/panel.png (frame {f})")
    _qc_report(out, data, model, result, truth)


def _qc_report(out: Path, data: Dataset, model: Model, result, truth) -> None:  # type: ignore[no-untyped-def]
    """`lgi report`'s page of the demo's LGI solve, compared with the ground truth."""
    from lgi.io.result import Result
    from lgi.io.topology import topology
    from lgi.review.report import render_report

    topo = topology(data)
    names = list(model.marker_names)

    def solved(vertices: np.ndarray) -> Result:
        return Result(
            vertices=vertices.astype(np.float32),
            bundle_residuals=result.bundle_residuals,
            missing=result.missing,
            marker_names=names,
            fps=None,
            start=0,
            units="cm",
            topology=topo,
            jaw_theta=result.jaw_theta,
        )

    page = render_report(
        solved(result.vertices),
        source=str(out / "performance.npz"),
        reference=solved(truth),
        reference_label="the ground truth",
    )
    write_text(out / "report.html", page)


def helmet_demo(out: Path, seed: int = 0, quiet: bool = False) -> str:
    """`lgi helmet-demo`: the built-in sample's performance filmed by the synthetic helmet
    (`lgi.lab.helmet`) and taken through the whole capture front end (`lgi.capture`); writes
    `out/helmet_report.md`, `out/helmet.yaml` (the rig's calibration) and `out/tracks.npz`
    (the 2D tracks), and returns the report."""
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    s = make_sample(seed)
    data = sample_dataset(s)
    # The jaw stage: the default build estimates a rig from the dataset's jaw shapes and the
    # default solve takes each frame's jaw pose from its global fit.
    model = Model.build(data, s.markers_rest)
    true_bundles = model.bundle_positions(s.truth)
    cams = helmet.helmet_cameras(s.markers_rest)
    motion = helmet.head_motion(true_bundles.shape[0], s.markers_rest, seed=seed)
    take = helmet.make_helmet_take(true_bundles, cams, motion, seed=seed + 1)
    save_cameras(out / "helmet.yaml", cams)
    with atomic_path(out / "tracks.npz") as tmp, open(tmp, "wb") as fh:
        np.savez(fh, uv=take.uv)
    front = process(cams, take.uv, s.markers_rest)
    sigma = estimate_marker_noise(front.frames)
    diag = model.diagonal

    def face(frames: F64, **kw: object) -> str:
        res = model.solve(frames, quiet=True, **kw)  # type: ignore[arg-type]
        e = np.linalg.norm(res.vertices - s.truth, axis=2) / diag
        return f"{e.mean():.2e} | {np.percentile(e, 95):.2e} | {e.max():.2e}"

    e3d = np.linalg.norm(front.triangulation.points - take.points, axis=2) / diag
    rel = np.einsum("fji,fjk->fik", front.alignment.rotations, motion.rotations)
    cos = np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0)
    deg = np.degrees(np.arccos(cos))
    lines = [
        "# lgi helmet demo",
        "",
        f"Sample seed {seed}: {true_bundles.shape[0]} frames, {true_bundles.shape[1]} markers, "
        f"2 fisheye cameras, 0.5 px noise, occlusions and mistracks (lgi.lab.helmet). Chain: "
        "triangulate -> stabilise (stable weights) -> despike -> jaw (estimated rig, pose "
        "from each frame's fit) -> solve.",
        "",
        *front.summary().splitlines(),
        "",
        "| stage | mean | p95 | max |",
        "|---|---|---|---|",
        f"| 3D marker error / diagonal | {np.nanmean(e3d):.2e} | "
        f"{np.nanpercentile(e3d, 95):.2e} | {np.nanmax(e3d):.2e} |",
        f"| head rotation error (deg) | {deg.mean():.3f} | {np.percentile(deg, 95):.3f} | "
        f"{deg.max():.3f} |",
        f"| face error / diagonal, solved from the true bundles | {face(true_bundles)} |",
        f"| face error / diagonal, full chain (marker_noise={sigma:.3g}) | "
        f"{face(front.frames, marker_noise=sigma)} |",
        f"| face error / diagonal, triangulated, not stabilised | "
        f"{face(front.triangulation.points, marker_noise=sigma)} |",
        "",
        f"({time.perf_counter() - t0:.1f} s)",
    ]
    text = "\n".join(lines) + "\n"
    write_text(out / "helmet_report.md", text)
    if not quiet:
        print(text, end="")
        print(f"wrote {out}/helmet_report.md, {out}/helmet.yaml and {out}/tracks.npz")
    return text
