"""The `lgi` command line: argument (and environment) handling only. `lgi demo` runs the whole
pipeline on the built-in sample (`lgi.demo`); `lgi evaluate` a protocol (`lgi.evaluate`); the
file pipeline `lgi build` / `solve` / `export` / `info` reads and writes through `lgi.takes`
and `lgi.export`. Every user mistake ends as `lgi: error: ...` and exit status 2."""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

import lgi
from lgi import export


def _cmd_demo(args: argparse.Namespace) -> int:
    from lgi import demo

    return demo.run(Path(args.out), seed=args.seed, quiet=args.quiet)


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from lgi import evaluate, ict

    ict_dir = args.ict_dir
    if args.data == "ict" and ict_dir is None:
        ict_dir = ict.find(os.environ.get(ict.ENV))
    rows = evaluate.run_protocol(args.data, args.protocol, args.out, ict_dir)
    print(evaluate.to_markdown(rows), end="")
    print(f"wrote {args.out}/results.md and {args.out}/results.csv")
    return 0


# --- The file pipeline: build, solve, export, info ----------------------------------------


def _say(args: argparse.Namespace, message: str) -> None:
    """A step's line on stderr (silenced by -q)."""
    if not getattr(args, "quiet", False):
        print(f"lgi {args.command}: {message}", file=sys.stderr)


def _existing_file(path: str, what: str) -> Path:
    p = Path(path)
    if not p.exists():
        raise lgi.InputError(f"{what} {path}: no such file")
    if p.is_dir():
        raise lgi.InputError(f"{what} {path}: is a folder, expected a file")
    return p


def _output_file(path: str, what: str) -> Path:
    """An output file path: not a folder, in a folder that exists (an old file is replaced)."""
    p = Path(path)
    if p.is_dir():
        raise lgi.InputError(f"{what} {path}: is a folder, expected a file path")
    if not p.parent.is_dir():
        raise lgi.InputError(f"{what} {path}: the folder {p.parent} does not exist")
    return p


def _read_dataset(neutral: str, shapes: str) -> lgi.Dataset:
    """NEUTRAL (.obj with SHAPES a folder of OBJs or a glob; .gltf/.glb/.npz holding its
    shapes, SHAPES then '-' or the same file)."""
    n = _existing_file(neutral, "NEUTRAL")
    suffix = n.suffix.lower()
    if suffix in (".gltf", ".glb", ".npz"):
        if shapes not in ("-", neutral) and Path(shapes) != n:
            raise lgi.InputError(
                f"SHAPES {shapes}: a {suffix} neutral holds its shapes "
                f"({'morph targets' if suffix != '.npz' else 'the shapes array'}); pass '-'"
            )
        if suffix == ".npz":
            return lgi.Dataset.from_npz(n)
        return lgi.Dataset.from_gltf(n)
    if suffix != ".obj":
        raise lgi.InputError(f"NEUTRAL {neutral}: expected .obj, .gltf, .glb or .npz")
    if shapes == "-":
        return lgi.Dataset.from_obj(n)
    s = Path(shapes)
    if s.is_dir():
        files = sorted(p for p in s.iterdir() if p.suffix.lower() == ".obj")
        if not files:
            raise lgi.InputError(f"SHAPES {shapes}: the folder holds no .obj files")
        return lgi.Dataset.from_obj(n, files)
    if s.suffix.lower() in (".gltf", ".glb"):
        raise lgi.InputError(
            f"SHAPES {shapes}: glTF morph targets come with their own neutral; "
            f"pass the glTF as NEUTRAL and '-' as SHAPES"
        )
    if not any(c in shapes for c in "*?["):
        if not s.exists():
            raise lgi.InputError(f"SHAPES {shapes}: no such folder or file (or a glob pattern)")
        return lgi.Dataset.from_obj(n, [s])
    return lgi.Dataset.from_obj(n, shapes)


def _read_config(path: str | None) -> lgi.BuildConfig | None:
    if path is None:
        return None
    p = _existing_file(path, "--config")
    try:
        fields = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise lgi.InputError(f"--config {path}: not a JSON file: {e}") from None
    if not isinstance(fields, dict):
        raise lgi.InputError(f"--config {path}: expected a JSON object of BuildConfig fields")
    known = lgi.BuildConfig().to_dict()
    unknown = sorted(set(fields) - set(known))
    if unknown:
        raise lgi.InputError(
            f"--config {path}: unknown fields {unknown} (BuildConfig has {', '.join(known)})"
        )
    try:
        return lgi.BuildConfig(**fields)
    except lgi.InputError as e:
        raise lgi.InputError(f"--config {path}: {e}") from None


def _cmd_build(args: argparse.Namespace) -> int:
    import time

    from lgi import jaw, takes

    out = _output_file(args.out, "--out")
    config = _read_config(args.config)
    layout = takes.read_layout(_existing_file(args.markers, "MARKERS"))
    t0 = time.perf_counter()
    data = _read_dataset(args.neutral, args.shapes)
    _say(
        args,
        f"read the neutral ({data.num_vertices} vertices) and {data.num_shapes} shapes "
        f"({time.perf_counter() - t0:.1f} s)",
    )
    rig = theta = None
    if args.jaw == "auto":
        if "jawOpen" not in data.names:
            raise lgi.InputError(
                "--jaw auto: the dataset has no 'jawOpen' shape to estimate the jaw from "
                "(name it so, or pass --jaw none)"
            )
        rig, theta = jaw.estimate_rig(
            data.neutral, data.shapes, data.names, triangles=data.triangles
        )
        _say(args, f"estimated the jaw rig (pivot {np.round(rig.pivot, 3).tolist()})")
    t0 = time.perf_counter()
    _say(args, f"building the model for {len(layout.names)} markers ...")
    try:
        model = lgi.Model.build(
            data,
            layout.positions,
            config,
            jaw=rig,
            shape_theta=theta,
            marker_names=layout.names,
            units=args.units,
        )
    except lgi.MarkerError as e:
        # The core counts markers; the user knows them by name.
        found = re.match(r"marker (\d+)", str(e))
        name = f" ({layout.names[int(found.group(1))]!r})" if found else ""
        raise lgi.MarkerError(f"MARKERS {args.markers}: {e}{name}") from None
    model.save(out)
    _say(args, f"built in {time.perf_counter() - t0:.1f} s")
    print(f"wrote {out}")
    return 0


def _frame_range(spec: str | None, count: int) -> slice:
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
        raise lgi.InputError(f"--frames {spec!r}: expected START:END (e.g. 0:100)") from None
    if not 0 <= a < b <= count:
        raise lgi.InputError(
            f"--frames {spec}: the take has frames 0:{count}; START must be < END within it"
        )
    return slice(a, b)


def _marker_noise(spec: str | None, frames: np.ndarray) -> float | None:
    if spec is None or spec == "none":
        return None
    if spec == "auto":
        return lgi.estimate_marker_noise(frames)
    try:
        sigma = float(spec)
    except ValueError:
        raise lgi.InputError(
            f"--marker-noise {spec!r}: expected a number (data units), 'auto' or 'none'"
        ) from None
    if not np.isfinite(sigma) or sigma < 0:
        raise lgi.InputError(f"--marker-noise {spec}: must be a finite number >= 0")
    return sigma


def _output_kind(path: str) -> str:
    suffix = Path(path).suffix.lower()
    kinds = {".usd": "usd", ".usdc": "usd", ".usda": "usd", ".npz": "npz", ".obj": "obj"}
    if suffix not in kinds:
        raise lgi.InputError(
            f"--out {path}: unknown output format {suffix or '(no suffix)'!r}; "
            "use .usd/.usdc/.usda (point cache), .obj (OBJ sequence) or .npz"
        )
    return kinds[suffix]


def _fps(given: float | None, take_fps: float | None, kind: str) -> float | None:
    if given is not None:
        if not np.isfinite(given) or given <= 0:
            raise lgi.InputError(f"--fps {given}: must be a positive number")
        return float(given)
    if take_fps is None and kind == "usd":
        raise lgi.InputError("the take has no frame rate; pass --fps for the USD time codes")
    return take_fps


def _write_output(
    args: argparse.Namespace,
    kind: str,
    out: Path,
    topo: export.Topology,
    vertices: np.ndarray,
    *,
    residuals: np.ndarray,
    missing: np.ndarray,
    names: list[str],
    fps: float | None,
    start: int,
    units: str | None,
    jaw_theta: np.ndarray | None,
) -> None:
    from tqdm import tqdm

    n = vertices.shape[0]
    chunk = 100
    if kind == "usd":
        assert fps is not None
        cache = export.UsdCache(out, topo, fps=fps, units=units, start=start)
        with tqdm(
            total=n, desc="lgi write USD", unit="frame", disable=args.quiet, leave=False
        ) as bar:
            for a in range(0, n, chunk):
                b = min(n, a + chunk)
                cache.add(
                    vertices[a:b],
                    jaw_theta=None if jaw_theta is None else jaw_theta[a:b],
                    marker_residuals=residuals[a:b],
                )
                bar.update(b - a)
        cache.close()
    elif kind == "obj":
        with tqdm(
            total=n, desc="lgi write OBJ", unit="frame", disable=args.quiet, leave=False
        ) as bar:
            for a in range(0, n, chunk):
                b = min(n, a + chunk)
                export.write_obj_sequence(
                    out.parent, topo, vertices[a:b], name=out.stem, start=start + a
                )
                bar.update(b - a)
    else:
        export.write_result_npz(
            out,
            topo,
            vertices,
            residuals,
            missing,
            names,
            fps=fps,
            start=start,
            units=units,
            jaw_theta=jaw_theta,
        )
    where = f"{out.parent}/{out.stem}.NNNN.obj" if kind == "obj" else str(out)
    print(f"wrote {where} ({n} frames)")


def _cmd_solve(args: argparse.Namespace) -> int:
    from lgi import takes

    out = _output_file(args.out, "--out")
    kind = _output_kind(args.out)
    model = lgi.Model.load(_existing_file(args.model, "MODEL"))
    take = takes.read(
        _existing_file(args.take, "TAKE"),
        model.marker_names,
        units=model.units,
        take_units=args.take_units,
        allow_missing=args.allow_missing,
    )
    if take.ignored:
        _say(
            args,
            f"left out {len(take.ignored)} labels unknown to the model: {', '.join(take.ignored)}",
        )
    rng = _frame_range(args.frames, take.num_frames)
    frames = take.frames[rng]
    fps = _fps(args.fps, take.fps, kind)
    sigma = _marker_noise(args.marker_noise, frames)
    jaw_mode = None if model.jaw_rig is None or args.jaw == "rest" else "track"
    missing = np.isnan(frames).any(axis=2)
    _say(
        args,
        f"{frames.shape[0]} frames of {frames.shape[1]} markers "
        f"({100 * missing.mean():.1f}% samples missing)"
        + ("" if sigma is None else f", marker noise {sigma:.4g}"),
    )
    res = model.solve(frames, jaw=jaw_mode, marker_noise=sigma, quiet=args.quiet)
    _write_output(
        args,
        kind,
        out,
        export.topology(model.dataset),
        res.vertices,
        residuals=res.bundle_residuals,
        missing=res.missing,
        names=model.marker_names,
        fps=fps,
        start=take.first_frame + rng.start,
        units=model.units,
        jaw_theta=res.jaw_theta,
    )
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    out = _output_file(args.out, "--out")
    kind = _output_kind(args.out)
    src = _existing_file(args.result, "RESULT")
    if src.resolve() == out.resolve():
        raise lgi.InputError(f"--out {args.out}: is the RESULT file itself")
    r = export.read_result_npz(src)
    rng = _frame_range(args.frames, r.vertices.shape[0])
    fps = _fps(args.fps, r.fps, kind)
    _write_output(
        args,
        kind,
        out,
        r.topology,
        r.vertices[rng],
        residuals=r.bundle_residuals[rng],
        missing=r.missing[rng],
        names=r.marker_names,
        fps=fps,
        start=r.start + rng.start,
        units=r.units,
        jaw_theta=None if r.jaw_theta is None else r.jaw_theta[rng],
    )
    return 0


def _info_lines(path: Path) -> list[str]:
    from lgi import takes

    suffix = path.suffix.lower()
    if suffix == ".lgi":
        m = lgi.Model.load(path)
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
        with np.load(path, allow_pickle=False) as z:
            files = set(z.files)
        if "vertices" in files:
            r = export.read_result_npz(path)
            return [
                f"solved take {path}",
                f"  frames: {r.vertices.shape[0]} from time code {r.start}, "
                f"fps {r.fps if r.fps is not None else 'unknown'}",
                f"  mesh: {r.vertices.shape[1]} vertices, {r.topology.num_faces} faces",
                f"  markers: {len(r.marker_names)}, residual max {r.bundle_residuals.max():.3g}",
                f"  units: {r.units or 'not given'}",
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
        ]
    if suffix in (".usd", ".usdc", ".usda"):
        from pxr import Usd, UsdGeom

        stage = Usd.Stage.Open(str(path))
        if stage is None:
            raise lgi.InputError(f"{path}: not a readable USD file")
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
        return lines
    raise lgi.InputError(
        f"{path}: unknown file kind {suffix or '(no suffix)'!r}; lgi info reads .lgi models, "
        f"takes ({', '.join(takes.TAKE_SUFFIXES)}), solved .npz and USD files"
    )


def _cmd_info(args: argparse.Namespace) -> int:
    for line in _info_lines(_existing_file(args.file, "FILE")):
        print(line)
    return 0


def _add_pipeline_commands(sub: Any) -> None:
    b = sub.add_parser(
        "build",
        help="build a model file from a neutral, its shapes and a named marker layout",
        description="Build a model (.lgi) from NEUTRAL, SHAPES and a MARKERS layout.",
    )
    b.add_argument("neutral", metavar="NEUTRAL", help="neutral mesh: .obj, .gltf/.glb or .npz")
    b.add_argument(
        "shapes",
        metavar="SHAPES",
        help="shape OBJs: a folder, a glob pattern ('shapes/*.obj') or one file; '-' when "
        "NEUTRAL holds the shapes (glTF morph targets, .npz) or for none",
    )
    b.add_argument("markers", metavar="MARKERS", help="marker layout CSV: name,x,y,z")
    b.add_argument("-o", "--out", required=True, help="model file to write (.lgi)")
    b.add_argument("--config", default=None, help="JSON object of BuildConfig fields")
    b.add_argument(
        "--jaw",
        choices=["auto", "none"],
        default="none",
        help="auto: estimate a jaw rig from the 'jawOpen' (and jawLeft/Right/Forward) shapes",
    )
    b.add_argument(
        "--units",
        default=None,
        help="length unit of the neutral and markers (mm, cm, m, in, ft): takes are "
        "converted to it and USD's metersPerUnit is set from it",
    )
    b.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    b.set_defaults(func=_cmd_build)

    s = sub.add_parser(
        "solve",
        help="solve a marker take into meshes: USD point cache, OBJ sequence or .npz",
        description="Solve TAKE (.c3d, .trc, .csv, .npz) with MODEL; --out's suffix picks "
        "the format.",
    )
    s.add_argument("model", metavar="MODEL", help="model file (.lgi) from lgi build")
    s.add_argument("take", metavar="TAKE", help="marker take: .c3d, .trc, labelled .csv, .npz")
    s.add_argument(
        "-o",
        "--out",
        required=True,
        help="output: .usd/.usdc/.usda point cache, NAME.obj (writes NAME.0000.obj, ...) or .npz",
    )
    s.add_argument(
        "--marker-noise",
        default=None,
        metavar="SIGMA|auto|none",
        help="markers' noise sigma in model units (auto: estimated from the take); default "
        "none: every marker interpolated exactly",
    )
    s.add_argument("--frames", default=None, metavar="A:B", help="take frames A..B-1 (0-based)")
    s.add_argument("--fps", type=float, default=None, help="frame rate (default: the take's)")
    s.add_argument(
        "--allow-missing",
        action="store_true",
        help="solve with layout markers absent from the take as missing, ignoring unknown labels",
    )
    s.add_argument(
        "--take-units", default=None, help="the take's length unit, overriding the file's"
    )
    s.add_argument(
        "--jaw",
        choices=["track", "rest"],
        default="track",
        help="jaw models: track the jaw from the markers (default) or solve at rest",
    )
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    s.set_defaults(func=_cmd_solve)

    e = sub.add_parser(
        "export",
        help="convert a solved .npz to a USD point cache, an OBJ sequence or another .npz",
    )
    e.add_argument("result", metavar="RESULT", help="solved take (.npz from lgi solve)")
    e.add_argument("-o", "--out", required=True, help="output: .usd/.usdc/.usda, NAME.obj, .npz")
    e.add_argument("--frames", default=None, metavar="A:B", help="frames A..B-1 (0-based)")
    e.add_argument("--fps", type=float, default=None, help="frame rate (default: the result's)")
    e.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    e.set_defaults(func=_cmd_export)

    i = sub.add_parser("info", help="summarise a model, a take, a solved .npz or a USD file")
    i.add_argument("file", metavar="FILE")
    i.set_defaults(func=_cmd_info)


class _Parser(argparse.ArgumentParser):
    """argparse with the one error format of the CLI: usage, then `lgi: error: ...`, exit 2."""

    def error(self, message: str) -> NoReturn:
        self.print_usage(sys.stderr)
        self.exit(2, f"lgi: error: {message}\n")


def _out_folder(value: str) -> str:
    """`--out` of demo/evaluate: a folder to create or reuse, not a file nor under one."""
    p = Path(value)
    if p.exists() and not p.is_dir():
        raise argparse.ArgumentTypeError(f"{value} is a file; --out is a folder (created)")
    for parent in p.absolute().parents:
        if parent.exists():
            if not parent.is_dir():
                raise argparse.ArgumentTypeError(f"{value}: {parent} is a file, not a folder")
            break
    return value


def _seed(value: str) -> int:
    try:
        seed = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{value!r} is not an integer") from None
    if not 0 <= seed < 2**32:
        raise argparse.ArgumentTypeError(f"{seed}: a seed is an integer in 0..2^32-1")
    return seed


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="lgi",
        description="Local Geometric Indexing: sparse facial markers to dense face meshes.",
    )
    p.add_argument("--version", action="version", version=f"lgi {lgi.__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    demo = sub.add_parser(
        "demo",
        help="build the built-in sample, solve its performance, write meshes and a report",
    )
    demo.add_argument(
        "--out", type=_out_folder, default="lgi-demo-output", help="output folder (created)"
    )
    demo.add_argument("--seed", type=_seed, default=0, help="seed of the generated sample")
    demo.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    demo.set_defaults(func=_cmd_demo)

    ev = sub.add_parser("evaluate", help="compare LGI with the baselines against ground truth")
    ev.add_argument("--data", choices=["sample", "ict"], default="sample")
    ev.add_argument(
        "--protocol",
        choices=["performance", "verification", "loo", "noise", "dropout"],
        default="performance",
    )
    ev.add_argument(
        "--out", type=_out_folder, default="lgi-evaluate-output", help="output folder (created)"
    )
    ev.add_argument(
        "--ict-dir",
        default=None,
        help="ICT-FaceKit folder (for --data ict; default: ict-facekit under $LGI_SHARED_DATA, "
        "else under shared/data beside the working directory)",
    )
    ev.set_defaults(func=_cmd_evaluate)
    _add_pipeline_commands(sub)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    try:
        return int(args.func(args))
    except lgi.LgiError as e:
        print(f"lgi: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:  # a file the user named cannot be read or written
        print(f"lgi: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
