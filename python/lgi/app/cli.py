"""The `lgi` command line: argument (and environment) handling only. `lgi demo` runs the whole
pipeline on the built-in sample (`lgi.lab.demo`); `lgi evaluate` a protocol
(`lgi.lab.evaluate`); the file pipeline `lgi build` / `solve` / `export` / `info` / `rig` is
`lgi.pipeline`'s, `lgi batch` `lgi.batch`'s; `lgi triangulate` the capture front end's
(`lgi.capture.frontend`) and `lgi helmet-demo` the lab's. Only those lab commands import
`lgi.lab`, inside the command. Every user mistake ends as `lgi: error: ...` and exit status
2."""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

import lgi
from lgi import choices, pipeline
from lgi.interrupt import import_usd
from lgi.io.atomic import ready_folder


def _cmd_demo(args: argparse.Namespace) -> int:
    from lgi.lab import demo

    return demo.run(ready_folder(Path(args.out), args.force), seed=args.seed, quiet=args.quiet)


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from lgi.lab import evaluate, ict

    ready_folder(Path(args.out), args.force)
    ict_dir = args.ict_dir
    if args.data == "ict" and ict_dir is None:
        ict_dir = ict.find(os.environ.get(ict.ENV))
    rows = evaluate.run_protocol(
        args.data,
        args.protocol,
        args.out,
        ict_dir,
        sigma=args.sigma,
        holdout=args.holdout,
        takes=args.take,
        frames_per_take=args.frames,
        held_out=args.held_out,
        scans=args.scans,
        nonlinear=args.truth == "nonlinear",
        quiet=args.quiet,
    )
    print(evaluate.to_markdown(rows), end="")
    written = [f"{args.out}/{n}" for n in ("results.md", "results.csv", "panel.png")]
    print("wrote " + ", ".join(w for w in written if Path(w).is_file()))
    return 0


# --- The file pipeline: build, solve, export, info ----------------------------------------


def _say(args: argparse.Namespace) -> pipeline.Say:
    """Step lines on stderr, silenced by -q."""

    def say(message: str) -> None:
        if not args.quiet:
            print(f"lgi {args.command}: {message}", file=sys.stderr)

    return say


def _cmd_build(args: argparse.Namespace) -> int:
    out = pipeline.build_file(
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
        noise=args.marker_noise,
        detail=args.detail_weight,
        local_fits=args.local_fits,
        unbounded_fit=args.unbounded_fit,
        take_prior=args.take_prior,
        denoise=args.denoise,
        recommended=args.recommended,
        frames=args.frames,
        fps=args.fps,
        allow_missing=args.allow_missing,
        take_units=args.take_units,
        jaw=args.jaw,
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
    out, n = pipeline.export_file(
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
    out, n = pipeline.rig_file(
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
    for line in pipeline.describe(args.file, model=args.model, take_units=args.take_units):
        print(line)
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    out = pipeline.report_file(
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

    from lgi import view

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
    from lgi import batch

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
    options: dict[str, Any] = {}
    if args.marker_noise is not None:
        options["marker_noise"] = args.marker_noise
    if args.detail_weight is not None:
        options["detail_weight"] = args.detail_weight
    if args.local_fits:
        choices.check_local_fits_noise(args.local_fits, args.marker_noise)
        options["local_fits"] = args.local_fits
    if args.unbounded_fit:
        options["fit"] = "auto" if args.unbounded_fit == "auto" else "unbounded"
    if args.take_prior:
        options["take_prior"] = args.take_prior
    if args.denoise:
        options["denoise"] = True
    if args.recommended:
        options["recommended"] = True
    if args.jaw != "auto":
        options["jaw"] = None if args.jaw == "rest" else args.jaw
    model = pipeline.existing_file(args.model, "MODEL")
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
        **options,
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


def _number_auto_or_none(
    text: str, number: Callable[[str], float], expected: str
) -> float | str | None:
    """A `lgi batch` option's value: 'auto' (per take), 'none' (None) or `number(text)`; an
    ArgumentTypeError saying `expected` otherwise."""
    if text in ("auto", "none"):
        return None if text == "none" else text
    try:
        return number(text)
    except (argparse.ArgumentTypeError, lgi.InputError):
        raise argparse.ArgumentTypeError(
            f"expected {expected}, 'auto' or 'none', got {text!r}"
        ) from None


def _detail_weight_option(text: str) -> float | str | None:
    """`lgi batch --detail-weight`: a weight in [0, 1], 'auto' (per take) or 'none'."""
    from lgi.detail import check_detail_weight

    return _number_auto_or_none(text, check_detail_weight, "a number in [0, 1]")


def _local_fits_option(text: str) -> str:
    """`--local-fits auto` or `--local-fits unbounded` (the flag alone is True)."""
    if text not in ("auto", "unbounded"):
        raise argparse.ArgumentTypeError(f"expected no value, 'unbounded' or 'auto', got {text!r}")
    return text


def _add_local_fits_argument(parser: argparse.ArgumentParser, help: str) -> None:
    """`--local-fits [auto|unbounded]` (`lgi solve`, `lgi batch`): False, True, 'unbounded' or
    'auto'."""
    parser.add_argument(
        "--local-fits",
        nargs="?",
        const=True,
        default=False,
        type=_local_fits_option,
        metavar="auto|unbounded",
        help=help,
    )


def _auto_only(text: str) -> str:
    """`--unbounded-fit auto`, `--take-prior auto` (the flag alone is True)."""
    if text != "auto":
        raise argparse.ArgumentTypeError(f"expected no value or 'auto', got {text!r}")
    return text


def _add_take_prior_argument(parser: argparse.ArgumentParser) -> None:
    """`--take-prior [auto]` (`lgi solve`, `lgi batch`): `lgi.estimate_take_prior` on the
    unbounded fit, or 'auto' (`lgi.estimate_take_prior_use`)."""
    parser.add_argument(
        "--take-prior",
        nargs="?",
        const=True,
        default=False,
        type=_auto_only,
        metavar="auto",
        help="the unbounded global fit with the take's own prior on its weights (the "
        "directions its frames move in above the marker noise), for noisy markers; needs "
        "--marker-noise and --unbounded-fit or --local-fits unbounded; auto: used when it "
        "predicts the take's own markers, left out one at a time, better",
    )


def _add_denoise_argument(parser: argparse.ArgumentParser) -> None:
    """`--denoise` (`lgi solve`, `lgi batch`): `lgi.denoise_take` before the solve."""
    parser.add_argument(
        "--denoise",
        action="store_true",
        help="first remove the markers' noise as far as the take's own low-rank motion allows "
        "(lgi.denoise_take; needs --marker-noise above 0), then solve with the noise it "
        "leaves; the residuals written stay the given markers'",
    )


def _add_recommended_argument(parser: argparse.ArgumentParser) -> None:
    """`--recommended` (`lgi solve`, `lgi batch`): `lgi.choices.plan_solve(recommended=True)`."""
    parser.add_argument(
        "--recommended",
        action="store_true",
        help="read every choice from the take: --marker-noise, --denoise, --unbounded-fit, "
        "--local-fits and --take-prior auto, and --detail-weight auto where no local fits are "
        "used; options given keep their values (docs/results.md measures this call)",
    )


def _add_unbounded_fit_argument(parser: argparse.ArgumentParser) -> None:
    """`--unbounded-fit [auto]` (`lgi solve`, `lgi batch`): `Model.solve(fit="unbounded")`,
    or 'auto' (`lgi.estimate_unbounded_fit`)."""
    parser.add_argument(
        "--unbounded-fit",
        nargs="?",
        const=True,
        default=False,
        type=_auto_only,
        metavar="auto",
        help="the frame's global fit without holding its weights to [0, 1]: for a dataset of "
        "whole-face scans (a scan's weight is no activation), not a FACS rig; implied by "
        "--local-fits unbounded; auto: used when it predicts the take's own markers, left out "
        "one at a time, better",
    )


def _marker_noise_option(text: str) -> float | str | None:
    """`lgi batch --marker-noise`: a sigma >= 0, 'auto' (per take) or 'none'."""
    return _number_auto_or_none(text, _non_negative, "a number >= 0 (model units)")


def _add_batch_command(sub: Any) -> None:
    """`lgi batch`: many takes as tasks on dask.distributed (`lgi.batch`)."""
    from lgi.batch import OUTPUT_FORMATS

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
        type=_positive_int,
        default=None,
        metavar="N",
        help="worker processes of the local cluster (default: one per two cores)",
    )
    b.add_argument(
        "--threads",
        type=_positive_int,
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
    b.add_argument(
        "--marker-noise",
        type=_marker_noise_option,
        default=None,
        metavar="SIGMA|auto|none",
        help="markers' noise sigma in model units (auto: estimated per take); default none",
    )
    b.add_argument(
        "--detail-weight",
        type=_detail_weight_option,
        default=None,
        metavar="W|auto|none",
        help="as lgi solve --detail-weight (auto: read per take); default none",
    )
    _add_local_fits_argument(
        b, "as lgi solve --local-fits (needs --marker-noise; auto: chosen per take)"
    )
    _add_unbounded_fit_argument(b)
    _add_take_prior_argument(b)
    _add_denoise_argument(b)
    _add_recommended_argument(b)
    b.add_argument(
        "--jaw",
        choices=list(pipeline.JAW_POSES),
        default="auto",
        help="as lgi solve --jaw",
    )
    b.add_argument("--fps", type=float, default=None, help="frame rate of takes without one")
    b.add_argument("--allow-missing", action="store_true", help="as lgi solve --allow-missing")
    b.add_argument("--take-units", default=None, help="the takes' length unit, overriding theirs")
    b.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    b.set_defaults(func=_cmd_batch)


def _add_frame_options(p: argparse.ArgumentParser) -> None:
    """`--units`, `--scale`, `--up` of the mesh writers (lgi.io.frame)."""
    p.add_argument(
        "--units",
        default=None,
        help="write the mesh in this unit (mm, cm, m, in, ft), converted from the model's",
    )
    p.add_argument(
        "--scale",
        type=float,
        default=None,
        help="multiply the mesh's coordinates (not with --units)",
    )
    p.add_argument(
        "--up",
        choices=["y", "z"],
        default="y",
        help="the output's up axis (default y, the model's)",
    )


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
    _add_frame_options(s)
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
    s.add_argument(
        "--marker-noise",
        default=None,
        metavar="SIGMA|auto|none",
        help="markers' noise sigma in model units (auto: estimated from the take); default "
        "none: every marker interpolated exactly",
    )
    s.add_argument(
        "--detail-weight",
        default=None,
        metavar="W|auto|none",
        help="how much of the dataset's detail between the markers to keep, 0..1 (auto: read "
        "from the take's markers left out one at a time; for a performer the dataset is not); "
        "default none: all of it",
    )
    _add_local_fits_argument(
        s,
        "each bundle's piece is the blendshape fit of the markers around it (needs "
        "--marker-noise; the most accurate with a dataset of whole-face scans, docs/results.md); "
        "unbounded: the windows' and the global fit's weights not held to [0, 1] (for scans, "
        "not a FACS rig); "
        "auto: used, and which kind, when they predict the take's own markers, left out one "
        "at a time, better",
    )
    _add_unbounded_fit_argument(s)
    _add_take_prior_argument(s)
    _add_denoise_argument(s)
    _add_recommended_argument(s)
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
        choices=list(pipeline.JAW_POSES),
        default="auto",
        help="models with a jaw rig: each frame's jaw pose from its blendshape fit (auto, "
        "fit), from the jaw's markers (track), or the rest pose (rest); see Model.solve",
    )
    s.add_argument(
        "--chunk",
        type=_positive_int,
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
    _add_frame_options(e)
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
    _add_frame_options(r)
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


def _positive_int(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {n}")
    return n


def _non_negative(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (x >= 0 and x < float("inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text!r}")
    return x


def _fraction(text: str) -> float:
    x = _non_negative(text)
    if x >= 1:
        raise argparse.ArgumentTypeError(f"expected a fraction in [0, 1), got {text!r}")
    return x


def _cmd_triangulate(args: argparse.Namespace) -> int:
    from lgi.capture import frontend
    from lgi.io import calibration, tracks

    pipeline.ready_output(args.out, args.cameras, args.tracks, args.rest, force=args.force)
    cams = calibration.load_cameras(args.cameras)
    uv = tracks.read_tracks(args.tracks, len(cams))
    rest = tracks.read_rest(args.rest)
    front = frontend.process(
        cams, uv, rest.positions, max_error=args.max_error, despike=not args.no_despike
    )
    tracks.write_bundles(args.out, front, rest.names)
    print(front.summary())
    print(f"wrote {args.out}")
    return 0


def _cmd_helmet_demo(args: argparse.Namespace) -> int:
    from lgi.lab import demo

    demo.helmet_demo(ready_folder(Path(args.out), args.force), seed=args.seed, quiet=args.quiet)
    return 0


def _add_front_end_commands(sub: argparse._SubParsersAction[_Parser]) -> None:
    """`lgi triangulate` (2D tracks to stabilised bundles) and `lgi helmet-demo`."""
    tr = sub.add_parser(
        "triangulate",
        help="2D marker tracks from calibrated cameras -> stabilised bundles (.npz)",
    )
    tr.add_argument("--cameras", required=True, help="calibration (.yaml/.yml/.json, OpenCV)")
    tr.add_argument("--tracks", required=True, help=".npz with uv (F, B, C, 2) in pixels")
    tr.add_argument("--rest", required=True, help="marker rest layout: .npy or name,x,y,z CSV")
    tr.add_argument("--out", required=True, help="output .npz (frames, rotations, ...)")
    tr.add_argument(
        "--force", action="store_true", help="replace an existing output (default: refuse)"
    )
    tr.add_argument("--max-error", type=float, default=3.0, help="reject above this RMS px")
    tr.add_argument("--no-despike", action="store_true", help="keep one-frame jumps")
    tr.set_defaults(func=_cmd_triangulate)
    hd = sub.add_parser(
        "helmet-demo",
        help="the sample filmed by a synthetic helmet, through the whole capture front end",
    )
    hd.add_argument("--out", default="lgi-helmet-output", help="output folder (created)")
    hd.add_argument(
        "--force",
        action="store_true",
        help="write into an --out folder that already holds files (default: refuse)",
    )
    hd.add_argument("--seed", type=int, default=0, help="seed of the sample and the take")
    hd.add_argument("-q", "--quiet", action="store_true", help="print nothing")
    hd.set_defaults(func=_cmd_helmet_demo)


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
    demo.add_argument(
        "--force",
        action="store_true",
        help="write into an --out folder that already holds files (default: refuse)",
    )
    demo.add_argument("--seed", type=_seed, default=0, help="seed of the generated sample")
    demo.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    demo.set_defaults(func=_cmd_demo)

    ev = sub.add_parser("evaluate", help="compare LGI with the baselines against ground truth")
    ev.add_argument("--data", choices=["sample", "ict"], default="sample")
    ev.add_argument(
        "--protocol",
        choices=[
            "performance",
            "verification",
            "loo",
            "noise",
            "dropout",
            "capture",
            "scans",
            "lomo",
        ],
        default="performance",
        help="capture (--data ict): the shared Live Link Face recordings drive ICT with a "
        "hinged jaw, markers with noise, dropouts and held-out shapes; scans (--data ict): the "
        "dataset is whole-face scans picked from one recording's curves, the performance "
        "another recording; lomo (--data ict): real "
        "marker takes retargeted onto ICT, each method scored on markers it was not given "
        "(docs/results.md)",
    )
    ev.add_argument(
        "--sigma",
        type=_non_negative,
        default=0.05,
        help="capture protocol: marker noise per coordinate, data units (default 0.05 cm)",
    )
    ev.add_argument(
        "--holdout",
        type=_fraction,
        default=0.0,
        help="capture protocol: fraction of the shapes the methods do not get (default 0)",
    )
    ev.add_argument(
        "--take",
        action="append",
        default=[],
        metavar="FILE",
        help="lomo protocol: a real take (TRC or C3D) with the AnimFace marker labels, its first "
        "frame at rest; repeat for more (default: the takes in animface/ beside ict-facekit/)",
    )
    ev.add_argument(
        "--frames",
        type=_positive_int,
        default=None,
        help="lomo and scans protocols: frames solved per take, evenly spaced (default 250 "
        "for lomo, 200 for scans)",
    )
    ev.add_argument(
        "--held-out",
        type=_positive_int,
        default=8,
        help="lomo protocol: markers left out, one at a time, per take (default 8)",
    )
    ev.add_argument(
        "--scans",
        type=_positive_int,
        default=120,
        help="scans protocol: whole-face scans in the dataset (default 120)",
    )
    ev.add_argument(
        "--truth",
        choices=["linear", "nonlinear"],
        default="linear",
        help="capture and scans protocols: the linear rig with a hinged jaw (default), or the "
        "shapes' rotations and stretches blended per triangle (lgi.lab.capture.NonlinearTruth)",
    )
    ev.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    ev.add_argument(
        "--out", type=_out_folder, default="lgi-evaluate-output", help="output folder (created)"
    )
    ev.add_argument(
        "--force",
        action="store_true",
        help="write into an --out folder that already holds files (default: refuse)",
    )
    ev.add_argument(
        "--ict-dir",
        default=None,
        help="ICT-FaceKit folder (for --data ict; default: ict-facekit under $LGI_SHARED_DATA, "
        "else under shared/data beside the working directory)",
    )
    ev.set_defaults(func=_cmd_evaluate)
    _add_pipeline_commands(sub)
    _add_batch_command(sub)
    _add_front_end_commands(sub)
    return p


def _say_warning(
    message: Warning | str,
    category: type[Warning],
    filename: str,
    lineno: int,
    file: Any = None,
    line: str | None = None,
) -> None:
    """A warning as one line in lgi's words (not Python's file, line and source)."""
    print(f"lgi: warning: {message}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    try:
        if any(str(a).lower().endswith((".usd", ".usda", ".usdc")) for a in argv or sys.argv):
            import_usd()  # up front, so a Ctrl-C during pxr's import cannot be swallowed
        with warnings.catch_warnings():
            warnings.showwarning = _say_warning
            return int(args.func(args))
    except KeyboardInterrupt:
        print("lgi: interrupted", file=sys.stderr)
        return 130
    except lgi.LgiError as e:
        print(f"lgi: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:  # a file the user named cannot be read or written
        print(f"lgi: error: {e}", file=sys.stderr)
        return 2


def entry() -> None:
    """The `lgi` command: `main`, with a Ctrl-C that arrives while Python is still loading the
    package answered the same way (one line, exit 130)."""
    try:
        code = main()
    except KeyboardInterrupt:
        print("lgi: interrupted", file=sys.stderr)
        code = 130
    sys.exit(code)


if __name__ == "__main__":
    entry()
