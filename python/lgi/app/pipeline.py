"""The file pipeline behind `lgi build` / `solve` / `export` / `info` / `rig`: files in (a
neutral and its shapes, a named marker layout, a take, a template rig), files out (a model
file, a USD point cache, an OBJ sequence, a solved `.npz`, a blendshape rig), and
one-paragraph summaries of each kind of file. The readers and writers themselves are
`lgi.io`'s (takes, solved frames by kind, rigs); the CLI only parses arguments and calls
`build_file`, `solve_file`, `export_file`, `rig_file` and `describe`. Error messages name the
CLI's arguments and options (`--frames`, `MARKERS`), which these functions' parameters
mirror."""

from __future__ import annotations

import json
import os
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from lgi._lgi import BuildConfig, SolveResult
from lgi.choices import marker_noise, plan_solve
from lgi.dataset import Dataset
from lgi.denoise import DenoisedTake
from lgi.diagnose import Finding, diagnose, diagnose_result, face_size, summary
from lgi.errors import InputError, MarkerError
from lgi.io import takes
from lgi.io.atomic import check_writable, existing_sequence, refuse_existing
from lgi.io.frame import DATASET_NPZ, OutputFrame, output_frame
from lgi.io.paths import output_file
from lgi.io.result import Result, read_result_npz
from lgi.io.settings import SolveSettings
from lgi.io.sink import FrameSink
from lgi.io.topology import Topology, topology
from lgi.model import PROGRESS_DELAY, Model
from lgi.noise import estimate_marker_noise
from lgi.placement import ScaleFit, check_scale, describe_scale

__all__ = [
    "CHUNK_FRAMES",
    "JAW_POSES",
    "build_file",
    "describe",
    "export_file",
    "frame_range",
    "output_kind",
    "read_dataset",
    "rig_file",
    "solve_file",
]

CHUNK_FRAMES = 100
"""Frames written per chunk (one progress step)."""

JAW_POSES = ("auto", "fit", "track", "rest")
"""`lgi solve --jaw`: `Model.solve`'s jaw modes for models with a rig ("rest" = None)."""

Say = Callable[[str], None]


def _silent(_message: str) -> None:
    pass


def existing_file(path: str, what: str) -> Path:
    """An input file that exists and is not a folder (`what` names the argument)."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"{what} {path}: no such file")
    if p.is_dir():
        raise InputError(f"{what} {path}: is a folder, expected a file")
    return p


def not_an_input(out: Path, *inputs: str | os.PathLike[str]) -> None:
    """Refuses an output path that is one of the command's inputs (nothing given is modified)."""
    for i in inputs:
        q = Path(i)
        if q.exists() and q.resolve() == out.resolve():
            raise InputError(f"--out {out}: is an input of the command ({i}); choose another path")


def ready_output(out: str | os.PathLike[str], *inputs: str | os.PathLike[str], force: bool) -> Path:
    """The checks every command makes on `--out` before any work: a file path in a folder that
    exists, not one of the command's `inputs`, not an existing file (or, for `NAME.obj`, an
    existing sequence `NAME.NNNN.obj`) unless `force`, in a folder lgi can write to (a probe
    file is made and removed: a read-only folder fails now, not after the solve)."""
    dest = output_file(os.fspath(out), "--out")
    not_an_input(dest, *inputs)
    if dest.suffix.lower() == ".obj" and not dest.exists():
        old = existing_sequence(dest.parent, dest.stem)
        if old and not force:
            raise InputError(
                f"--out {dest}: the sequence {dest.stem}.NNNN.obj exists ({len(old)} frames, "
                f"{old[0].name} to {old[-1].name}); use --force to replace it (its frames are "
                "removed, never mixed with the new ones)"
            )
    else:
        refuse_existing(dest, "--out", force)
    check_writable(dest)
    return dest


def read_dataset(neutral: str, shapes: str) -> Dataset:
    """NEUTRAL (.obj with SHAPES a folder of OBJs or a glob; .gltf/.glb/.npz holding its
    shapes, SHAPES then '-' or the same file)."""
    n = existing_file(neutral, "NEUTRAL")
    suffix = n.suffix.lower()
    if suffix in (".gltf", ".glb", ".npz"):
        if shapes not in ("-", neutral) and Path(shapes) != n:
            raise InputError(
                f"SHAPES {shapes}: a {suffix} neutral holds its shapes "
                f"({'morph targets' if suffix != '.npz' else 'the shapes array'}); pass '-'"
            )
        if suffix == ".npz":
            return Dataset.from_npz(n)
        return Dataset.from_gltf(n)
    if suffix != ".obj":
        raise InputError(f"NEUTRAL {neutral}: expected .obj, .gltf, .glb or .npz")
    if shapes == "-":
        return Dataset.from_obj(n)
    s = Path(shapes)
    if s.is_dir():
        files = sorted(p for p in s.iterdir() if p.suffix.lower() == ".obj")
        if not files:
            raise InputError(f"SHAPES {shapes}: the folder holds no .obj files")
        return Dataset.from_obj(n, files)
    if s.suffix.lower() in (".gltf", ".glb"):
        raise InputError(
            f"SHAPES {shapes}: glTF morph targets come with their own neutral; "
            f"pass the glTF as NEUTRAL and '-' as SHAPES"
        )
    if not any(c in shapes for c in "*?["):
        if not s.exists():
            raise InputError(f"SHAPES {shapes}: no such folder or file (or a glob pattern)")
        return Dataset.from_obj(n, [s])
    return Dataset.from_obj(n, shapes)


def read_config(path: str | None) -> BuildConfig | None:
    """`--config`: a JSON object of `BuildConfig` fields (None: the defaults)."""
    if path is None:
        return None
    p = existing_file(path, "--config")
    try:
        fields = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(f"--config {path}: not a JSON file: {e}") from None
    if not isinstance(fields, dict):
        raise InputError(f"--config {path}: expected a JSON object of BuildConfig fields")
    known = BuildConfig().to_dict()
    unknown = sorted(set(fields) - set(known))
    if unknown:
        raise InputError(
            f"--config {path}: unknown fields {unknown} (BuildConfig has {', '.join(known)})"
        )
    try:
        return BuildConfig(**fields)
    except InputError as e:
        raise InputError(f"--config {path}: {e}") from None


def frame_range(spec: str | None, count: int) -> slice:
    """`--frames a:b` (0-based take frames, b exclusive; either end may be left out)."""
    if spec is None:
        return slice(0, count)
    parts = spec.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        a = int(parts[0]) if parts[0].strip() else 0
        b = int(parts[1]) if parts[1].strip() else count
    except ValueError:
        raise InputError(f"--frames {spec!r}: expected START:END (e.g. 0:100)") from None
    if not 0 <= a < b <= count:
        raise InputError(
            f"--frames {spec}: the take has frames 0:{count}; START must be < END within it"
        )
    return slice(a, b)


def solved_residuals(res: SolveResult, given: np.ndarray, den: DenoisedTake | None) -> np.ndarray:
    """The residuals (F, B) a solve of the markers `given` writes and is read by: the result's
    own (a copy), or where the take was denoised first (`den`: other markers were solved), each
    given marker's distance from its position on the surface; 0 where it is missing."""
    if den is None:
        return np.array(res.bundle_residuals)
    d = np.linalg.norm(np.asarray(given, dtype=np.float64) - res.bundle_positions, axis=2)
    return np.where(np.isnan(d), 0.0, d)


def output_kind(path: str) -> str:
    """`--out`'s format by suffix: 'usd', 'obj' (a sequence), 'npz', 'pc2' or 'mdd'."""
    suffix = Path(path).suffix.lower()
    kinds = {".usd": "usd", ".usdc": "usd", ".usda": "usd", ".npz": "npz", ".obj": "obj"}
    kinds |= {".pc2": "pc2", ".mdd": "mdd"}
    if suffix not in kinds:
        raise InputError(
            f"--out {path}: unknown output format {suffix or '(no suffix)'!r}; "
            "use .usd/.usdc/.usda (point cache), .obj (OBJ sequence), .pc2 or .mdd (point "
            "caches for Blender's Mesh Cache, Houdini, 3ds Max) or .npz"
        )
    return kinds[suffix]


def frame_rate(given: float | None, take_fps: float | None, kind: str) -> float | None:
    """`--fps`, else the take's rate; a USD output needs one."""
    if given is not None:
        if not np.isfinite(given) or given <= 0:
            raise InputError(f"--fps {given}: must be a positive number")
        return float(given)
    if take_fps is None and kind in ("usd", "mdd"):
        raise InputError(f"the take has no frame rate; pass --fps for the {kind.upper()} times")
    return take_fps


def write_output(
    kind: str,
    out: Path,
    topo: Topology,
    vertices: np.ndarray,
    *,
    residuals: np.ndarray,
    missing: np.ndarray,
    names: list[str],
    fps: float | None,
    start: int,
    units: str | None,
    jaw_theta: np.ndarray | None,
    head: takes.HeadMotion | None = None,
    markers: np.ndarray | None = None,
    frame: OutputFrame | None = None,
    quiet: bool = False,
    settings: SolveSettings | None = None,
) -> Path:
    """Writes solved frames as `kind` (`output_kind`) to `out`, `CHUNK_FRAMES` at a time with
    a progress bar (the head transform, when known, beside them in a USD cache; the take's
    `markers` and the `settings` it was solved with in an npz, the settings in a USD cache);
    returns the path written (`NAME.NNNN.obj` for a sequence). Nothing is left at `out` if it
    fails or is interrupted."""
    from tqdm import tqdm

    sink = FrameSink(
        kind,
        out,
        topo,
        names=names,
        fps=fps,
        start=start,
        units=units,
        frame=frame,
        settings=settings,
    )
    n = vertices.shape[0]
    try:
        with tqdm(
            total=n, desc=f"lgi write {kind}", unit="frame", disable=quiet, leave=False
        ) as bar:
            for a in range(0, n, CHUNK_FRAMES):
                b = min(n, a + CHUNK_FRAMES)
                sink.add(
                    vertices[a:b],
                    residuals[a:b],
                    missing[a:b],
                    None if jaw_theta is None else jaw_theta[a:b],
                    None if head is None else head[a:b],
                    None if markers is None else markers[a:b],
                )
                bar.update(b - a)
        return sink.close()
    except BaseException:
        sink.abort()
        raise


def write_solved(
    kind: str,
    out: Path,
    topo: Topology,
    res: SolveResult,
    m: Model,
    *,
    fps: float | None,
    start: int,
    head: takes.HeadMotion | None = None,
    markers: np.ndarray | None = None,
    frame: OutputFrame | None = None,
    quiet: bool = False,
    settings: SolveSettings | None = None,
    residuals: np.ndarray | None = None,
) -> Path:
    """`write_output` of a whole `SolveResult` of model `m` (its marker names and unit);
    `residuals` in place of the result's (e.g. the given markers', `solved_residuals`)."""
    return write_output(
        kind,
        out,
        topo,
        res.vertices,
        residuals=res.bundle_residuals if residuals is None else residuals,
        missing=res.missing,
        names=m.marker_names,
        fps=fps,
        start=start,
        units=m.units,
        jaw_theta=res.jaw_theta,
        head=head,
        markers=markers,
        frame=frame,
        quiet=quiet,
        settings=settings,
    )


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
                + (r.settings.describe(r.units) if r.settings is not None else "not recorded"),
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
                    lines.append(f"    solved with: {s.describe(stage_units(stage))}")
        return lines
    raise InputError(
        f"{path}: unknown file kind {suffix or '(no suffix)'!r}; lgi info reads .lgi models, "
        f"takes ({', '.join(takes.TAKE_SUFFIXES)}), solved .npz and USD files"
    )


def _joined(parts: list[np.ndarray | None]) -> np.ndarray | None:
    """Chunks' arrays end to end; None if any chunk had none."""
    whole = [p for p in parts if p is not None]
    return np.concatenate(whole) if whole and len(whole) == len(parts) else None


def _write_curves(
    out: Path,
    fit: np.ndarray | None,
    jaw_theta: np.ndarray | None,
    m: Model,
    *,
    fps: float | None,
    start: int,
    frame: OutputFrame | None = None,
) -> None:
    """`lgi solve --curves`: the solve's global fit weights and jaw pose as curves (a USD rig
    in the output's frame)."""
    from lgi.io.curves import write_curves

    if fit is None:
        raise InputError(
            "--curves: this solve made no global fit (a model built with fit off, or without "
            "shapes), so there are no curves to write"
        )
    write_curves(
        out, m.dataset, fit, fps=fps, start=start, units=m.units, jaw_theta=jaw_theta, frame=frame
    )


def _write_solve_report(
    page: Path,
    res: SolveResult,
    m: Model,
    topo: Topology,
    markers: np.ndarray,
    found: list[Finding],
    *,
    fps: float | None,
    start: int,
    source: Path,
    settings: SolveSettings | None = None,
    residuals: np.ndarray | None = None,
) -> None:
    """`lgi solve --report`: `lgi report`'s page of the solve just made, from memory, with
    the findings the summary printed and the settings it was solved with (`residuals` as
    `write_solved`'s)."""
    from lgi.io.atomic import atomic_path
    from lgi.io.result import Result
    from lgi.report import render_report

    solved = Result(
        vertices=np.asarray(res.vertices, dtype=np.float32),
        bundle_residuals=res.bundle_residuals if residuals is None else residuals,
        missing=res.missing,
        marker_names=list(m.marker_names),
        fps=fps,
        start=start,
        units=m.units,
        topology=topo,
        jaw_theta=res.jaw_theta,
        markers=np.asarray(markers, dtype=np.float32),
        settings=settings,
    )
    lines = [f.describe(start, m.units) for f in found]
    with atomic_path(page) as tmp:
        tmp.write_text(render_report(solved, source=str(source), findings=lines), encoding="utf-8")


def _say_findings(
    say: Say,
    residuals: np.ndarray,
    missing: np.ndarray,
    markers: np.ndarray,
    first_frame: np.ndarray,
    m: Model,
    start: int,
    noise: float | None,
) -> list[Finding]:
    """The solve's summary (`lgi.diagnose`): residuals, then flagged markers and frames;
    returns the findings (measured as `lgi info` measures them on the file)."""
    names = m.marker_names
    found = diagnose(
        residuals, missing, names, size=face_size(first_frame), markers=markers, noise=noise
    )
    for line in summary(residuals, missing, names, found, start=start, units=m.units):
        say(line)
    return found


def check_take_scale(
    t: takes.Take, frames: np.ndarray, m: Model, *, stated: bool
) -> ScaleFit | None:
    """`lgi.placement.check_scale` of a take read for model `m` (its frames `frames`)."""
    return check_scale(
        frames,
        m.markers_rest,
        path=t.path,
        file_units=t.source_units,
        model_units=m.units,
        stated=stated,
    )


def _worst_lines(r: Result, shown: int = 5) -> list[str]:
    """`lgi info`'s worst markers (by largest residual) and worst frames of a solved take."""
    from lgi.report import marker_stats, worst_frames, worst_markers

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


def build_file(
    neutral: str | os.PathLike[str],
    shapes: str,
    markers: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    config: str | os.PathLike[str] | None = None,
    jaw: str = "auto",
    units: str | None = None,
    force: bool = False,
    say: Say = _silent,
) -> Path:
    """`lgi build`: a model file `out` from `neutral` and `shapes` (`read_dataset`), the
    layout CSV `markers` (`lgi.io.takes.read_layout`) and a JSON `config`; `jaw` is
    `Model.build`'s: "auto" (a rig from the jaw shapes when the dataset has `jawOpen`) or
    "none". The model keeps the layout's names and
    `units`. Returns `out`."""
    if jaw not in ("auto", "none"):
        raise InputError(f"--jaw {jaw!r}: expected 'auto' or 'none'")
    dest = ready_output(
        out, neutral, shapes, markers, *([config] if config is not None else []), force=force
    )
    cfg = read_config(None if config is None else os.fspath(config))
    layout = takes.read_layout(existing_file(os.fspath(markers), "MARKERS"))
    t0 = time.perf_counter()
    data = read_dataset(os.fspath(neutral), shapes)
    say(
        f"read the neutral ({data.num_vertices} vertices) and {data.num_shapes} shapes "
        f"({time.perf_counter() - t0:.1f} s)"
    )
    t0 = time.perf_counter()
    say(f"building the model for {len(layout.names)} markers ...")
    try:
        model = Model.build(
            data,
            layout.positions,
            cfg,
            jaw="auto" if jaw == "auto" else None,
            marker_names=layout.names,
            units=units,
        )
    except MarkerError as e:
        # The core counts markers; the user knows them by name.
        found = re.match(r"marker (\d+)", str(e))
        name = f" ({layout.names[int(found.group(1))]!r})" if found else ""
        raise MarkerError(f"MARKERS {os.fspath(markers)}: {e}{name}") from None
    model.save(dest)
    rig = model.jaw_rig
    say(
        f"built in {time.perf_counter() - t0:.1f} s, "
        + ("without a jaw rig" if rig is None else f"jaw pivot {np.round(rig.pivot, 3).tolist()}")
    )
    return dest


def solve_file(
    model: str | os.PathLike[str],
    take: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    noise: str | None = None,
    detail: str | None = None,
    frames: str | None = None,
    fps: float | None = None,
    allow_missing: bool = False,
    take_units: str | None = None,
    jaw: str = "auto",
    chunk: int | None = None,
    force: bool = False,
    report: str | os.PathLike[str] | None = None,
    curves: str | os.PathLike[str] | None = None,
    units: str | None = None,
    scale: float | None = None,
    up: str = "y",
    quiet: bool = False,
    say: Say = _silent,
    local_fits: bool | str = False,
    unbounded_fit: bool | str = False,
    take_prior: bool | str = False,
    denoise: bool | str = False,
    recommended: bool = False,
) -> tuple[Path, int]:
    """`lgi solve`: the take file solved with the model file, written by `out`'s suffix
    (`output_kind`). `noise` is `--marker-noise` (a number, 'auto' or 'none'; 'auto' looks at
    the whole range), `denoise` `--denoise` (`take_denoised`: the range denoised first and
    solved with the noise it leaves; residuals and findings are the given markers'),
    `detail` `--detail-weight` (the same forms, `detail_weight`),
    `local_fits` `--local-fits` (`Model.solve(local_fits=True)`; 'auto': `local_fits_choice`),
    `unbounded_fit` `--unbounded-fit` (`Model.solve(fit="unbounded")`; 'auto':
    `unbounded_fit_choice`), `take_prior` `--take-prior` (`lgi.estimate_take_prior`; 'auto':
    `take_prior_choice`), `recommended` `--recommended` (every option left at its default read
    from the take: `lgi.choices.plan_solve`), `frames` is `--frames A:B`. By default the range
    is solved in one `Model.solve` (frames prefer their predecessor's choices across the whole
    range), then written chunk by chunk; `chunk` (`--chunk N`) solves and writes N frames at a
    time into one reused buffer, so the solve's memory stays that of N frames (each chunk continues
    from the last frame of the one before: the same frames as one solve, except with
    `--jaw track`, tracked chunk by chunk). Returns the path written (the `NAME.NNNN.obj`
    pattern for OBJ sequences) and the frame count."""
    if chunk is not None and (isinstance(chunk, bool) or int(chunk) < 1):
        raise InputError(f"--chunk {chunk}: must be a whole number of frames >= 1")
    if jaw not in JAW_POSES:
        raise InputError(f"--jaw {jaw!r}: expected one of {', '.join(JAW_POSES)}")
    not_an_input(output_file(os.fspath(out), "--out"), model, take)
    kind = output_kind(os.fspath(out))
    dest = ready_output(out, model, take, force=force)
    page = None
    if report is not None:
        if chunk is not None:
            raise InputError(
                "--report needs the whole take solved at once; without --chunk, or run "
                "lgi report on an .npz output"
            )
        if Path(report).suffix.lower() not in (".html", ".htm"):
            raise InputError(f"--report {report}: the report is an .html file")
        page = ready_output(report, model, take, out, force=force)
    curves_out = None
    if curves is not None:
        from lgi.io.curves import CURVE_SUFFIXES

        if Path(curves).suffix.lower() not in CURVE_SUFFIXES:
            raise InputError(
                f"--curves {curves}: use .usd/.usda/.usdc (UsdSkel) or .csv (Live Link Face)"
            )
        curves_out = ready_output(curves, model, take, out, force=force)
    m = Model.load(existing_file(os.fspath(model), "MODEL"))
    frame = output_frame(m.units, units=units, scale=scale, up=up)
    frame.check_writer(kind, f"--out {dest}")  # before the take is read
    t = takes.read(
        existing_file(os.fspath(take), "TAKE"),
        m.marker_names,
        units=m.units,
        take_units=take_units,
        allow_missing=allow_missing,
    )
    if t.ignored:
        say(f"left out {len(t.ignored)} labels unknown to the model: {', '.join(t.ignored)}")
    rng = frame_range(frames, t.num_frames)
    x = t.frames[rng]
    check_take_scale(t, x, m, stated=take_units is not None)
    head = None if t.head is None else t.head[rng]
    rate = frame_rate(fps, t.fps, kind)
    jaw_mode = None if m.jaw_rig is None or jaw == "rest" else jaw
    plan = plan_solve(
        x,
        m,
        noise=noise,
        denoise=denoise,
        local_fits=local_fits,
        unbounded_fit=unbounded_fit,
        take_prior=take_prior,
        detail=detail,
        jaw=jaw_mode,
        recommended=recommended,
        say=say,
    )
    # What is solved: the given markers, or the take denoised with the noise it leaves. The
    # residuals written and the findings are always the given markers' (`given`).
    given, given_sigma, den = x, plan.given_noise, plan.denoised
    x, sigma, weight = plan.frames, plan.marker_noise, plan.detail_weight
    settings = plan.settings(has_jaw_rig=m.jaw_rig is not None, jaw=jaw)
    missing = np.isnan(x).any(axis=2)
    say(
        f"{x.shape[0]} frames of {x.shape[1]} markers "
        f"({100 * missing.mean():.1f}% samples missing)"
        + ("" if sigma is None else f", marker noise {sigma:.4g}")
        + ("" if weight is None else f", detail weight {weight:.3f}")
        + settings.pieces()
    )
    topo = topology(m.dataset)
    start = t.first_frame + rng.start
    # What both ways of solving (one call, or chunk by chunk) are given.
    how: dict[str, Any] = plan.solve_options()
    if chunk is None:
        res = m.solve(x, quiet=quiet, **how)
        if curves_out is not None:
            _write_curves(
                curves_out, res.fit_weights, res.jaw_theta, m, fps=rate, start=start, frame=frame
            )
            say(f"wrote the curves {curves_out}")
        given_residuals = solved_residuals(res, given, den)
        written = write_solved(
            kind,
            dest,
            topo,
            res,
            m,
            fps=rate,
            start=start,
            head=head,
            markers=given,
            frame=frame,
            quiet=quiet,
            settings=settings,
            residuals=given_residuals,
        )
        found = _say_findings(
            say,
            given_residuals,
            res.missing,
            given,
            res.vertices[0],
            m,
            start,
            given_sigma,
        )
        if page is not None:
            _write_solve_report(
                page,
                res,
                m,
                topo,
                given,
                found,
                fps=rate,
                start=start,
                source=dest,
                settings=settings,
                residuals=given_residuals,
            )
            say(f"wrote the report {page}")
        return written, int(x.shape[0])
    from tqdm import tqdm

    n, size = int(x.shape[0]), int(chunk)
    sink = FrameSink(
        kind,
        dest,
        topo,
        names=m.marker_names,
        fps=rate,
        start=start,
        units=m.units,
        frame=frame,
        settings=settings,
    )
    buf = np.empty((min(size, n), m.num_vertices, 3))
    # Each chunk continues the temporal solve from the last frame of the one before
    # (`Model.solve_iter`): the chunks together are one `solve` of the range.
    chunks = m.solve_iter(x, chunk=size, quiet=True, out=buf, **how)
    residuals: list[np.ndarray] = []
    absent: list[np.ndarray] = []
    fits: list[np.ndarray | None] = []
    first_frame: np.ndarray | None = None
    jaws: list[np.ndarray | None] = []
    try:
        with tqdm(
            total=n,
            desc="lgi solve",
            unit="frame",
            disable=quiet,
            leave=False,
            delay=PROGRESS_DELAY,
        ) as bar:
            for a, res in zip(range(0, n, size), chunks, strict=True):
                b = min(n, a + size)
                if first_frame is None:
                    first_frame = res.vertices[0].copy()
                chunk_residuals = solved_residuals(res, given[a:b], den)
                residuals.append(chunk_residuals)
                absent.append(res.missing.copy())
                fits.append(None if res.fit_weights is None else res.fit_weights.copy())
                jaws.append(None if res.jaw_theta is None else res.jaw_theta.copy())
                sink.add(
                    res.vertices,
                    chunk_residuals,
                    res.missing,
                    res.jaw_theta,
                    None if head is None else head[a:b],
                    given[a:b],
                )
                bar.update(b - a)
        if curves_out is not None:
            weights = _joined(fits)
            jaw_all = _joined(jaws)
            _write_curves(curves_out, weights, jaw_all, m, fps=rate, start=start, frame=frame)
            say(f"wrote the curves {curves_out}")
        written = sink.close()
    except BaseException:
        sink.abort()
        raise
    assert first_frame is not None  # a take has at least one frame (takes.read)
    _say_findings(
        say,
        np.concatenate(residuals),
        np.concatenate(absent),
        given,
        first_frame,
        m,
        start,
        given_sigma,
    )
    return written, n


def export_file(
    result: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    frames: str | None = None,
    fps: float | None = None,
    force: bool = False,
    units: str | None = None,
    scale: float | None = None,
    up: str = "y",
    quiet: bool = False,
) -> tuple[Path, int]:
    """`lgi export`: a solved `.npz` (`lgi solve -o x.npz`) written again by `out`'s suffix,
    optionally a frame range (`--frames A:B`) at another rate. Returns the path written and
    the frame count."""
    not_an_input(output_file(os.fspath(out), "--out"), result)
    kind = output_kind(os.fspath(out))
    src = existing_file(os.fspath(result), "RESULT")
    dest = ready_output(out, src, force=force)
    r = read_result_npz(src)
    frame = output_frame(r.units, units=units, scale=scale, up=up)
    rng = frame_range(frames, r.vertices.shape[0])
    written = write_output(
        kind,
        dest,
        r.topology,
        r.vertices[rng],
        residuals=r.bundle_residuals[rng],
        missing=r.missing[rng],
        names=r.marker_names,
        fps=frame_rate(fps, r.fps, kind),
        start=r.start + rng.start,
        units=r.units,
        jaw_theta=None if r.jaw_theta is None else r.jaw_theta[rng],
        markers=None if r.markers is None else r.markers[rng],
        frame=frame,
        quiet=quiet,
        settings=r.settings,
    )
    return written, int(r.vertices[rng].shape[0])


RIG_OUTPUTS = (".usd", ".usdc", ".usda", ".gltf", ".glb", ".npz")
"""`lgi rig --out` suffixes: a USD blendshape rig, glTF morph targets or a dataset `.npz`."""


def rig_file(
    model: str | os.PathLike[str],
    neutral: str,
    shapes: str,
    out: str | os.PathLike[str],
    *,
    combine: list[str] | None = None,
    noise: str | None = None,
    force: bool = False,
    units: str | None = None,
    scale: float | None = None,
    up: str = "y",
    quiet: bool = False,
    say: Say = _silent,
) -> tuple[Path, int]:
    """`lgi rig`: the actor rig of MODEL from the template NEUTRAL + SHAPES (`read_dataset`;
    `lgi.rig.actor_rig`), each `combine` entry ('A+B[+C]', template shape names) adding a
    corrective, written by `out`'s suffix (`RIG_OUTPUTS`: `lgi.io.rig.write_usd_rig`,
    `write_gltf_rig`, or `Dataset.to_npz`). `noise`: `--marker-noise` as a number or
    'none' ('auto' has no take to look at). Returns the path and the number of shapes."""
    from lgi import rig
    from lgi.io.rig import write_gltf_rig, write_usd_rig

    dest = output_file(os.fspath(out), "--out")
    suffix = dest.suffix.lower()
    if suffix not in RIG_OUTPUTS:
        raise InputError(
            f"--out {dest}: unknown rig format {suffix or '(no suffix)'!r}; use "
            ".usd/.usdc/.usda (UsdSkel blendshapes), .gltf/.glb (morph targets) or .npz"
        )
    ready_output(dest, model, neutral, *([] if shapes == "-" else [shapes]), force=force)
    if noise == "auto":
        raise InputError("--marker-noise auto: a rig has no take to estimate it from")
    sigma = marker_noise(noise, np.zeros((0, 0, 3)), None)
    m = Model.load(existing_file(os.fspath(model), "MODEL"))
    frame = output_frame(m.units, units=units, scale=scale, up=up)
    rig_kind = {".npz": "npz", ".gltf": "gltf", ".glb": "gltf"}.get(suffix, "usd")
    frame.check_writer(rig_kind, f"--out {dest}", npz=DATASET_NPZ)
    template = read_dataset(neutral, shapes)
    combos = []
    for spec in combine or []:
        names = spec.split("+")
        if len(names) < 2 or any(not n for n in names):
            raise InputError(f"--combine {spec!r}: expected template shape names joined by '+'")
        combos.append(names)
    say(f"template: {template.num_shapes} shapes, {len(combos)} combinations")
    try:
        result = rig.actor_rig(m, template, combos, marker_noise=sigma, quiet=quiet)
    except InputError as e:
        raise InputError(f"--combine: {e}" if str(e).startswith("combination") else str(e)) from e
    if suffix in (".gltf", ".glb"):
        write_gltf_rig(dest, result, frame=frame)
    elif suffix == ".npz":
        result.to_npz(dest)
    else:
        write_usd_rig(dest, result, units=m.units, frame=frame)
    return dest, result.num_shapes


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
    """`lgi report`: the QC page of a solved `.npz` (`lgi.report`), compared with `compare`
    (another solve of the same mesh and frames) when given; `take` with `model` adds the
    take's estimated marker noise."""
    from lgi import report

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
