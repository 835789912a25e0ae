"""The `lgi` command line: argument (and environment) handling only. `lgi demo` runs the whole
pipeline on the built-in sample (`lgi.demo`); `lgi evaluate` a protocol (`lgi.evaluate`)."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

import lgi


def _cmd_demo(args: argparse.Namespace) -> int:
    from lgi import demo

    return demo.run(Path(args.out), seed=args.seed, quiet=args.quiet)


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from lgi import evaluate, ict

    ict_dir = args.ict_dir
    if args.data == "ict" and ict_dir is None:
        ict_dir = ict.find(os.environ.get(ict.ENV))
    rows = evaluate.run_protocol(
        args.data, args.protocol, args.out, ict_dir, sigma=args.sigma, holdout=args.holdout
    )
    print(evaluate.to_markdown(rows), end="")
    print(f"wrote {args.out}/results.md and {args.out}/results.csv")
    return 0


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


def _read_rest(path: Path) -> np.ndarray:
    """Marker rest positions (B, 3): `.npy`, or CSV with a header row and name,x,y,z columns."""
    try:
        if path.suffix.lower() == ".npy":
            rest = np.load(path)
        else:
            rest = np.loadtxt(path, delimiter=",", skiprows=1, usecols=(1, 2, 3), ndmin=2)
    except (OSError, ValueError) as e:
        raise lgi.InputError(f"{path}: cannot read marker rest positions ({e})") from None
    rest = np.asarray(rest, dtype=np.float64)
    if rest.ndim != 2 or rest.shape[1] != 3:
        raise lgi.InputError(f"{path}: expected (B, 3) marker positions, got {rest.shape}")
    return rest


def _cmd_triangulate(args: argparse.Namespace) -> int:
    from lgi import camera, frontend

    cams = camera.load_cameras(args.cameras)
    uv = frontend.read_tracks(args.tracks, len(cams))
    rest = _read_rest(Path(args.rest))
    front = frontend.process(cams, uv, rest, max_error=args.max_error, despike=not args.no_despike)
    frontend.write_bundles(args.out, front)
    print(front.summary())
    print(f"wrote {args.out}")
    return 0


def _cmd_helmet_demo(args: argparse.Namespace) -> int:
    from lgi import frontend

    frontend.helmet_demo(Path(args.out), seed=args.seed, quiet=args.quiet)
    return 0


def _add_front_end_commands(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """`lgi triangulate` (2D tracks to stabilised bundles) and `lgi helmet-demo`."""
    tr = sub.add_parser(
        "triangulate",
        help="2D marker tracks from calibrated cameras -> stabilised bundles (.npz)",
    )
    tr.add_argument("--cameras", required=True, help="calibration (.yaml/.yml/.json, OpenCV)")
    tr.add_argument("--tracks", required=True, help=".npz with uv (F, B, C, 2) in pixels")
    tr.add_argument("--rest", required=True, help="marker rest layout: .npy or name,x,y,z CSV")
    tr.add_argument("--out", required=True, help="output .npz (frames, rotations, ...)")
    tr.add_argument("--max-error", type=float, default=3.0, help="reject above this RMS px")
    tr.add_argument("--no-despike", action="store_true", help="keep one-frame jumps")
    tr.set_defaults(func=_cmd_triangulate)
    hd = sub.add_parser(
        "helmet-demo",
        help="the sample filmed by a synthetic helmet, through the whole capture front end",
    )
    hd.add_argument("--out", default="lgi-helmet-output", help="output folder (created)")
    hd.add_argument("--seed", type=int, default=0, help="seed of the sample and the take")
    hd.add_argument("-q", "--quiet", action="store_true", help="print nothing")
    hd.set_defaults(func=_cmd_helmet_demo)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="lgi",
        description="Local Geometric Indexing: sparse facial markers to dense face meshes.",
    )
    p.add_argument("--version", action="version", version=f"lgi {lgi.__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    demo = sub.add_parser(
        "demo",
        help="build the built-in sample, solve its performance, write meshes and a report",
    )
    demo.add_argument("--out", default="lgi-demo-output", help="output folder (created)")
    demo.add_argument("--seed", type=int, default=0, help="seed of the generated sample")
    demo.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    demo.set_defaults(func=_cmd_demo)

    ev = sub.add_parser("evaluate", help="compare LGI with the baselines against ground truth")
    ev.add_argument("--data", choices=["sample", "ict"], default="sample")
    ev.add_argument(
        "--protocol",
        choices=["performance", "verification", "loo", "noise", "dropout", "capture"],
        default="performance",
        help="capture (--data ict): the shared Live Link Face recordings drive ICT with a "
        "hinged jaw, markers with noise, dropouts and held-out shapes (docs/results.md)",
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
    ev.add_argument("--out", default="lgi-evaluate-output", help="output folder (created)")
    ev.add_argument(
        "--ict-dir",
        default=None,
        help="ICT-FaceKit folder (for --data ict; default: ict-facekit under $LGI_SHARED_DATA, "
        "else under shared/data beside the working directory)",
    )
    ev.set_defaults(func=_cmd_evaluate)
    _add_front_end_commands(sub)
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


if __name__ == "__main__":
    sys.exit(main())
