"""What a TD reads about a file: `lgi info` (a model, a take and how it meets a model, a solved
`.npz`, a USD file) and `lgi report` (the QC page of a solved take)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from lgi.app.files import existing_file, ready_output
from lgi.app.pipeline import check_take_scale
from lgi.data.dataset import Dataset
from lgi.errors import InputError
from lgi.io import takes
from lgi.io.result import Result, read_result_npz
from lgi.plan.noise import estimate_marker_noise
from lgi.solve.diagnose import diagnose_result, summary
from lgi.solve.model import Model
from lgi.solve.placement import describe_scale


def describe(
    path: str | os.PathLike[str],
    model: str | os.PathLike[str] | None = None,
    take_units: str | None = None,
) -> list[str]:
    """`lgi info`: a few lines summarising a model (`.lgi`), a take, a solved `.npz` or a USD
    file; for a take with `model` (`--model`), how its labels match the model's markers."""
    path = existing_file(os.fspath(path), "FILE")
    suffix = path.suffix.lower()
    if suffix == ".lgi":
        m = Model.load(path)
        d = m.dataset
        polys = d.polygons
        faces = (
            f"{polys[0].size} polygons ({np.asarray(d.triangles).shape[0]} triangles)"
            if polys is not None
            else f"{np.asarray(d.triangles).shape[0]} triangles"
        )
        names = m.marker_names
        shown = ", ".join(names[:8]) + (", ..." if len(names) > 8 else "")
        jaw_bins = m.jaw_bins
        return [
            f"model {path}",
            f"  neutral: {d.num_vertices} vertices, {faces}, "
            f"{'with' if np.asarray(d.uv_triangles).size else 'without'} UVs",
            f"  shapes: {d.num_shapes}",
            f"  markers: {m.num_bundles} ({shown})",
            f"  units: {m.units or 'not given'}",
            f"  jaw: {'none' if m.jaw_rig is None else 'rig'}"
            + ("" if jaw_bins is None else f", {len(jaw_bins) - 1} bins"),
            f"  face size (bounding-box diagonal): {m.diagonal:.6g}",
        ]
    if suffix == ".npz":
        try:
            with np.load(path, allow_pickle=False) as z:
                files = set(z.files)
        except Exception as e:  # not a zip, a pickled array, ...: numpy raises various classes
            raise InputError(f"{path}: not a readable .npz archive: {e}") from None
        if "neutral" in files and "triangles" in files:
            d = Dataset.from_npz(path)
            polys = d.polygons
            faces = "no source polygons" if polys is None else f"{polys[0].size} polygons"
            return [
                f"dataset {path}",
                f"  neutral: {d.num_vertices} vertices, "
                f"{np.asarray(d.triangles).shape[0]} triangles, {faces}",
                f"  shapes: {d.num_shapes}",
            ]
        if "vertices" in files:
            r = read_result_npz(path)
            found = diagnose_result(r)
            return [
                f"solved take {path}",
                f"  frames: {r.vertices.shape[0]} from time code {r.start}, "
                f"fps {r.fps if r.fps is not None else 'unknown'}",
                f"  mesh: {r.vertices.shape[1]} vertices, {r.topology.num_faces} faces",
                f"  markers: {len(r.marker_names)}",
                f"  units: {r.units or 'not given'}",
                "  solved with: "
                + (
                    r.settings.describe(r.units, r.start)
                    if r.settings is not None
                    else "not recorded"
                ),
                *(
                    f"  {line}"
                    for line in summary(
                        r.bundle_residuals,
                        r.missing,
                        r.marker_names,
                        found,
                        start=r.start,
                        units=r.units,
                        shown=6,
                    )
                ),
                *_worst_lines(r),
            ]
    if suffix in takes.TAKE_SUFFIXES:
        raw = takes.read_raw(path)
        miss = np.isnan(raw.points).any(axis=2)
        shown = ", ".join(raw.labels[:8]) + (", ..." if len(raw.labels) > 8 else "")
        return [
            f"take {path}",
            f"  frames: {raw.points.shape[0]} from frame {raw.first_frame}, "
            f"fps {raw.fps if raw.fps is not None else 'unknown'}",
            f"  markers: {len(raw.labels)} ({shown})",
            f"  units: {raw.units or 'not given'}",
            f"  missing samples: {100 * miss.mean():.1f}%",
            *(
                []
                if model is None
                else _matching(
                    raw, Model.load(existing_file(os.fspath(model), "--model")), take_units
                )
            ),
        ]
    if suffix in (".usd", ".usdc", ".usda"):
        from pxr import Usd, UsdGeom

        stage = Usd.Stage.Open(str(path))
        if stage is None:
            raise InputError(f"{path}: not a readable USD file")
        lines = [
            f"USD {path}",
            f"  time codes: {stage.GetStartTimeCode():g} to {stage.GetEndTimeCode():g} "
            f"at {stage.GetTimeCodesPerSecond():g} per second",
            f"  metersPerUnit: {UsdGeom.GetStageMetersPerUnit(stage):g}",
        ]
        for prim in stage.Traverse():
            if prim.IsA(UsdGeom.Mesh):
                mesh = UsdGeom.Mesh(prim)
                counts = mesh.GetFaceVertexCountsAttr().Get()
                samples = mesh.GetPointsAttr().GetNumTimeSamples()
                lines.append(f"  mesh {prim.GetPath()}: {len(counts)} faces, {samples} samples")
                from lgi.io.usd import solve_settings, stage_units

                s = solve_settings(prim, str(path))
                if s is not None:
                    start = round(stage.GetStartTimeCode())
                    lines.append(f"    solved with: {s.describe(stage_units(stage), start)}")
        return lines
    raise InputError(
        f"{path}: unknown file kind {suffix or '(no suffix)'!r}; lgi info reads .lgi models, "
        f"takes ({', '.join(takes.TAKE_SUFFIXES)}), solved .npz and USD files"
    )


def _worst_lines(r: Result, shown: int = 5) -> list[str]:
    """`lgi info`'s worst markers (by largest residual) and worst frames of a solved take."""
    from lgi.review.report import marker_stats, worst_frames, worst_markers

    stats = marker_stats(r)
    markers = worst_markers(stats, shown)
    if not markers:
        return []
    u = f" {r.units}" if r.units else ""
    return [
        "  worst markers (largest residual): "
        + ", ".join(
            f"{r.marker_names[b]} {stats.max[b]:.3g}{u} at {r.start + int(stats.worst_frame[b])}"
            for b in markers
        ),
        "  worst frames (time code, largest residual, marker): "
        + ", ".join(
            f"{r.start + w.frame} {w.residual:.3g}{u} {r.marker_names[w.marker]}"
            for w in worst_frames(r, shown)
        ),
    ]


def _matching(raw: takes.RawTake, model: Model, take_units: str | None = None) -> list[str]:
    """How a take's labels meet a model's marker names, and its size against the model's
    layout (`lgi info TAKE --model MODEL`)."""
    _, absent, unknown = takes.label_columns(raw, model.marker_names)
    if not absent and not unknown:
        t = takes.read(raw.path, model.marker_names, units=model.units, take_units=take_units)
        try:
            size = describe_scale(
                check_take_scale(t, t.frames, model, stated=take_units is not None)
            )
        except InputError as e:
            size = f"  size: refused by lgi solve: {e}"
        return [f"  matches the model's {model.num_bundles} markers by name", size]
    out = []
    if absent:
        out.append(f"  model markers not in the take ({len(absent)}): {', '.join(absent)}")
    if unknown:
        out.append(f"  take labels not in the model ({len(unknown)}): {', '.join(unknown)}")
    return out


def report_file(
    solved: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    compare: str | os.PathLike[str] | None = None,
    take: str | os.PathLike[str] | None = None,
    model: str | os.PathLike[str] | None = None,
    take_units: str | None = None,
    force: bool = False,
) -> Path:
    """`lgi report`: the QC page of a solved `.npz` (`lgi.review.report`), compared with `compare`
    (another solve of the same mesh and frames) when given; `take` with `model` adds the
    take's estimated marker noise."""
    from lgi.review import report

    if Path(out).suffix.lower() not in (".html", ".htm"):
        raise InputError(f"--out {out}: the report is an .html file")
    dest = ready_output(
        out, *(p for p in (solved, compare, take, model) if p is not None), force=force
    )
    noise = None
    if take is not None:
        if model is None:
            raise InputError("--take needs --model (the take's labels and units are the model's)")
        m = Model.load(existing_file(os.fspath(model), "--model"))
        t = takes.read(
            existing_file(os.fspath(take), "--take"),
            m.marker_names,
            units=m.units,
            take_units=take_units,
            allow_missing=True,
        )
        noise = estimate_marker_noise(t.frames)
    return report.write_report(
        dest,
        existing_file(os.fspath(solved), "SOLVED"),
        reference_path=None if compare is None else existing_file(os.fspath(compare), "--compare"),
        take_noise=noise,
    )
