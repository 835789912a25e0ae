"""The file pipeline's commands: `lgi build`, `solve`, `export`, `rig`, `info`, `report`,
`view` and `batch`, each an argument parser and a call into `lgi.app` (argument handling only)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import lgi
from lgi.app import build, export, files, info, pipeline
from lgi.app.arguments import add_frame_options, add_solve_options, positive_int
from lgi.solve.options import SolveOptions


def _say(args: argparse.Namespace) -> files.Say:
    """Step lines on stderr, silenced by -q."""

    def say(message: str) -> None:
        if not args.quiet:
            print(f"lgi {args.command}: {message}", file=sys.stderr)

    return say


def _cmd_build(args: argparse.Namespace) -> int:
    out = build.build_file(
        args.neutral,
        args.shapes,
        args.markers,
        args.out,
        config=args.config,
        jaw=args.jaw,
        units=args.units,
        force=args.force,
        say=_say(args),
    )
    print(f"wrote {out}")
    return 0


def _cmd_solve(args: argparse.Namespace) -> int:
    out, n = pipeline.solve_file(
        args.model,
        args.take,
        args.out,
        SolveOptions.from_cli(args),
        frames=args.frames,
        fps=args.fps,
        allow_missing=args.allow_missing,
        take_units=args.take_units,
        chunk=args.chunk,
        force=args.force,
        report=args.report,
        curves=args.curves,
        units=args.units,
        scale=args.scale,
        up=args.up,
        quiet=args.quiet,
        say=_say(args),
    )
    print(f"wrote {out} ({n} frames)")
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    out, n = export.export_file(
        args.result,
        args.out,
        frames=args.frames,
        fps=args.fps,
        force=args.force,
        units=args.units,
        scale=args.scale,
        up=args.up,
        quiet=args.quiet,
    )
    print(f"wrote {out} ({n} frames)")
    return 0


def _cmd_rig(args: argparse.Namespace) -> int:
    out, n = export.rig_file(
        args.model,
        args.neutral,
        args.shapes,
        args.out,
        combine=args.combine,
        noise=args.marker_noise,
        force=args.force,
        units=args.units,
        scale=args.scale,
        up=args.up,
        quiet=args.quiet,
        say=_say(args),
    )
    print(f"wrote {out} ({n} shapes)")
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    for line in info.describe(args.file, model=args.model, take_units=args.take_units):
        print(line)
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    out = info.report_file(
        args.solved,
        args.out,
        compare=args.compare,
        take=args.take,
        model=args.model,
        take_units=args.take_units,
        force=args.force,
    )
    print(f"wrote {out}")
    return 0


def _cmd_view(args: argparse.Namespace) -> int:
    import time

    from lgi.review import view

    data = view.load(args.solved, args.compare)
    server, url = view.serve(data, port=args.port)
    print(f"lgi view: {url} (report: {url}report.html); Ctrl-C to stop", flush=True)
    if args.open:
        import webbrowser

        webbrowser.open(url)
    try:
        while True:
            time.sleep(3600)
    finally:
        server.shutdown()
        server.server_close()


def _cmd_batch(args: argparse.Namespace) -> int:
    from lgi.app import batch

    shots: dict[str, str] = {}
    for take in args.takes:
        name = Path(take).stem
        if name in shots:
            raise lgi.InputError(
                f"two takes named {name!r}: {shots[name]} and {take} (shots are named after "
                "their files' stems)"
            )
        shots[name] = take
    if args.scheduler is not None and args.workers is not None:
        raise lgi.InputError(
            "--workers sizes the local cluster; with --scheduler the workers are the "
            "cluster's own (start them with `dask worker ADDRESS`)"
        )
    options = SolveOptions.from_cli(args)
    model = files.existing_file(args.model, "MODEL")
    result = batch.solve_shots(
        model,
        shots,
        args.out,
        client=args.scheduler,
        workers=args.workers,
        threads=args.threads,
        output=args.format,
        fps=args.fps,
        allow_missing=args.allow_missing,
        take_units=args.take_units,
        quiet=args.quiet,
        options=options,
    )
    failed = result.failed
    print(
        f"{len(result.shots) - len(failed)} of {len(result.shots)} shots done "
        f"({len(result.skipped)} skipped: done before); manifest {result.manifest}"
    )
    if failed:
        why = "; ".join(f"{n}: {result.shots[n].error}" for n in failed)
        raise lgi.InputError(f"{len(failed)} of {len(result.shots)} shots failed ({why})")
    return 0


def add_batch_command(sub: Any) -> None:
    """`lgi batch`: many takes as tasks on dask.distributed (`lgi.app.batch`)."""
    from lgi.app.batch import OUTPUT_FORMATS

    b = sub.add_parser(
        "batch",
        help="solve many takes with one model on a Dask cluster (embedded by default)",
        description="Solve every TAKE with MODEL, one dask.distributed task per take, into "
        "OUT/NAME.npz (or --format), NAME the take's file stem; OUT/manifest.json records "
        "each shot, and a rerun skips the shots already done with the same take and settings.",
    )
    b.add_argument("model", metavar="MODEL", help="model file (.lgi) from lgi build")
    b.add_argument("takes", metavar="TAKE", nargs="+", help="marker takes: .c3d .trc .csv .npz")
    b.add_argument("-o", "--out", required=True, help="output folder (created)")
    b.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="a running Dask scheduler (tcp://host:8786); default: a local cluster",
    )
    b.add_argument(
        "--workers",
        type=positive_int,
        default=None,
        metavar="N",
        help="worker processes of the local cluster (default: one per two cores)",
    )
    b.add_argument(
        "--threads",
        type=positive_int,
        default=None,
        metavar="N",
        help="solve threads per task (default: the cores shared among the local workers)",
    )
    b.add_argument(
        "--format",
        choices=list(OUTPUT_FORMATS),
        default="npz",
        help="output per shot: npz (solved take), usd (NAME.usdc), obj (NAME.NNNN.obj)",
    )
    add_solve_options(b)
    b.add_argument("--fps", type=float, default=None, help="frame rate of takes without one")
    b.add_argument("--allow-missing", action="store_true", help="as lgi solve --allow-missing")
    b.add_argument("--take-units", default=None, help="the takes' length unit, overriding theirs")
    b.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    b.set_defaults(func=_cmd_batch)


def add_pipeline_commands(sub: Any) -> None:
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
    b.add_argument(
        "--force", action="store_true", help="replace an existing output (default: refuse)"
    )
    b.add_argument("--config", default=None, help="JSON object of BuildConfig fields")
    b.add_argument(
        "--jaw",
        choices=["auto", "none"],
        default="auto",
        help="auto (default): a jaw rig estimated from the jaw shapes when the dataset has "
        "'jawOpen'; none: no rig",
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
        "--force", action="store_true", help="replace an existing output (default: refuse)"
    )
    add_frame_options(s)
    s.add_argument(
        "--curves",
        default=None,
        metavar="FILE",
        help="also write each frame's global blendshape fit and jaw pose as curves: "
        ".usd/.usda/.usdc (UsdSkel animation over the blend-shape rig) or .csv (Live Link "
        "Face, ARKit names)",
    )
    s.add_argument(
        "--report",
        default=None,
        metavar="FILE.html",
        help="also write lgi report's page of the solve (not with --chunk)",
    )
    add_solve_options(s)
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
        "--chunk",
        type=positive_int,
        default=None,
        metavar="N",
        help="solve and write N frames at a time (bounded memory; each chunk continues from "
        "the last frame of the one before, so the result is that of one solve); default: the "
        "whole range in one solve",
    )
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    s.set_defaults(func=_cmd_solve)

    e = sub.add_parser(
        "export",
        help="convert a solved .npz to a USD point cache, an OBJ sequence or another .npz",
    )
    e.add_argument("result", metavar="RESULT", help="solved take (.npz from lgi solve)")
    e.add_argument("-o", "--out", required=True, help="output: .usd/.usdc/.usda, NAME.obj, .npz")
    e.add_argument(
        "--force", action="store_true", help="replace an existing output (default: refuse)"
    )
    add_frame_options(e)
    e.add_argument("--frames", default=None, metavar="A:B", help="frames A..B-1 (0-based)")
    e.add_argument("--fps", type=float, default=None, help="frame rate (default: the result's)")
    e.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    e.set_defaults(func=_cmd_export)

    r = sub.add_parser(
        "rig",
        help="an actor rig from a template rig: its shapes and correctives through MODEL",
        description="Reconstruct the template rig's shapes (NEUTRAL + SHAPES, the model's "
        "topology) and --combine combinations with MODEL; --out's suffix picks the format.",
    )
    r.add_argument("model", metavar="MODEL", help="the actor's model file (.lgi)")
    r.add_argument("neutral", metavar="NEUTRAL", help="template neutral: .obj, .gltf/.glb or .npz")
    r.add_argument(
        "shapes",
        metavar="SHAPES",
        help="template shape OBJs (folder, glob or file); '-' when NEUTRAL holds them",
    )
    r.add_argument(
        "-o",
        "--out",
        required=True,
        help="output: .usd/.usdc/.usda (UsdSkel blendshapes), .gltf/.glb (morph targets), .npz",
    )
    r.add_argument(
        "--force", action="store_true", help="replace an existing output (default: refuse)"
    )
    r.add_argument(
        "--combine",
        action="append",
        default=[],
        metavar="A+B",
        help="a combination of template shapes to make a corrective for (repeatable)",
    )
    r.add_argument(
        "--marker-noise",
        default=None,
        metavar="SIGMA|none",
        help="as for lgi solve (default none: markers interpolated exactly)",
    )
    add_frame_options(r)
    r.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    r.set_defaults(func=_cmd_rig)

    i = sub.add_parser("info", help="summarise a model, a take, a solved .npz or a USD file")
    i.add_argument("file", metavar="FILE")
    i.add_argument(
        "--model", default=None, help="with a take: how its labels match this model's markers"
    )
    i.add_argument(
        "--take-units",
        default=None,
        help="with a take and --model: the take's length unit when its file is silent or wrong",
    )
    i.set_defaults(func=_cmd_info)

    rp = sub.add_parser(
        "report",
        help="write a self-contained HTML QC page of a solved take (.npz)",
        description="Residual heatmap, worst markers and frames, dropouts, the jaw, and the "
        "difference to a second solve (--compare), in one HTML file readable without a server.",
    )
    rp.add_argument(
        "solved", metavar="SOLVED", help="solved take: .npz or USD point cache from lgi solve"
    )
    rp.add_argument("-o", "--out", required=True, help="report to write (.html)")
    rp.add_argument(
        "--force", action="store_true", help="replace an existing output (default: refuse)"
    )
    rp.add_argument(
        "--compare",
        default=None,
        metavar="NPZ",
        help="another solve of the same mesh and frames (another method, an older model, a "
        "ground truth): per-frame and per-vertex differences",
    )
    rp.add_argument("--take", default=None, help="the take solved: its marker noise is estimated")
    rp.add_argument("--model", default=None, help="the model (.lgi), with --take")
    rp.add_argument("--take-units", default=None, help="as for lgi solve")
    rp.set_defaults(func=_cmd_report)

    vw = sub.add_parser(
        "view",
        help="play a solved take in the browser (a local page on 127.0.0.1)",
        description="Serve SOLVED to a browser page on 127.0.0.1: play, scrub and orbit the "
        "solved mesh with its markers coloured by residual; colour vertices by displacement or "
        "by the difference to --compare; the residual heatmap and worst frames seek.",
    )
    vw.add_argument(
        "solved", metavar="SOLVED", help="solved take: .npz or USD point cache from lgi solve"
    )
    vw.add_argument("--compare", default=None, metavar="NPZ", help="a second solve (A/B colour)")
    vw.add_argument("--port", type=int, default=0, help="port on 127.0.0.1 (default: any free)")
    vw.add_argument("--open", action="store_true", help="open the page in the default browser")
    vw.set_defaults(func=_cmd_view)
