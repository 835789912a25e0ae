"""The `lgi` command line: argument (and environment) handling only. `lgi demo` runs the whole
pipeline on the built-in sample (`lgi.lab.demo`); `lgi evaluate` a protocol
(`lgi.lab.evaluate`); the file pipeline `lgi build` / `solve` / `export` / `info` / `rig` is
`lgi.app.pipeline`'s, `lgi batch` `lgi.app.batch`'s; `lgi triangulate` the capture front end's
(`lgi.capture.frontend`) and `lgi helmet-demo` the lab's. Only those lab commands import
`lgi.lab`, inside the command. Every user mistake ends as `lgi: error: ...` and exit status
2."""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

import lgi
from lgi.app import files
from lgi.app.arguments import fraction, non_negative, out_folder, positive_int, seed_number
from lgi.app.commands import add_batch_command, add_pipeline_commands
from lgi.app.interrupt import import_usd
from lgi.io.atomic import ready_folder


def _cmd_demo(args: argparse.Namespace) -> int:
    from lgi.lab import demo

    return demo.run(ready_folder(Path(args.out), args.force), seed=args.seed, quiet=args.quiet)


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from lgi.lab import evaluate, ict, scoring

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
    print(scoring.to_markdown(rows), end="")
    written = [f"{args.out}/{n}" for n in ("results.md", "results.csv", "panel.png")]
    print("wrote " + ", ".join(w for w in written if Path(w).is_file()))
    return 0


# --- The file pipeline: build, solve, export, info ----------------------------------------


class _Parser(argparse.ArgumentParser):
    """argparse with the one error format of the CLI: usage, then `lgi: error: ...`, exit 2."""

    def error(self, message: str) -> NoReturn:
        self.print_usage(sys.stderr)
        self.exit(2, f"lgi: error: {message}\n")


def _cmd_triangulate(args: argparse.Namespace) -> int:
    from lgi.capture import calibration, frontend
    from lgi.io import tracks

    files.ready_output(args.out, args.cameras, args.tracks, args.rest, force=args.force)
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
        "--out", type=out_folder, default="lgi-demo-output", help="output folder (created)"
    )
    demo.add_argument(
        "--force",
        action="store_true",
        help="write into an --out folder that already holds files (default: refuse)",
    )
    demo.add_argument("--seed", type=seed_number, default=0, help="seed of the generated sample")
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
        type=non_negative,
        default=0.05,
        help="capture protocol: marker noise per coordinate, data units (default 0.05 cm)",
    )
    ev.add_argument(
        "--holdout",
        type=fraction,
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
        type=positive_int,
        default=None,
        help="lomo and scans protocols: frames solved per take, evenly spaced (default 250 "
        "for lomo, 200 for scans)",
    )
    ev.add_argument(
        "--held-out",
        type=positive_int,
        default=8,
        help="lomo protocol: markers left out, one at a time, per take (default 8)",
    )
    ev.add_argument(
        "--scans",
        type=positive_int,
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
        "--out", type=out_folder, default="lgi-evaluate-output", help="output folder (created)"
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
    add_pipeline_commands(sub)
    add_batch_command(sub)
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
