"""The command line's arguments that more than one command shares: how a take is solved
(`add_solve_options`: the arguments `SolveOptions.from_cli` builds the options from, checked
there once), the mesh writers' frame (`add_frame_options`) and the argument types."""

from __future__ import annotations

import argparse
from pathlib import Path

from lgi.app import pipeline


def _local_fits_option(text: str) -> str:
    """`--local-fits auto` or `--local-fits unbounded` (the flag alone is True)."""
    if text not in ("auto", "unbounded"):
        raise argparse.ArgumentTypeError(f"expected no value, 'unbounded' or 'auto', got {text!r}")
    return text


def add_solve_options(parser: argparse.ArgumentParser) -> None:
    """How a take is solved (`lgi solve`, `lgi batch`): the arguments `SolveOptions.from_cli`
    builds the options from, checked there once."""
    parser.add_argument(
        "--marker-noise",
        default=None,
        metavar="SIGMA|auto|none",
        help="markers' noise sigma in model units (auto: estimated from the take); default "
        "none: every marker interpolated exactly",
    )
    parser.add_argument(
        "--detail-weight",
        default=None,
        metavar="W|auto|none",
        help="how much of the dataset's detail between the markers to keep, 0..1 (auto: read "
        "from the take's markers left out one at a time; for a performer the dataset is not); "
        "default none: all of it",
    )
    _add_local_fits_argument(
        parser,
        "each bundle's piece is the blendshape fit of the markers around it (needs "
        "--marker-noise; the most accurate with a dataset of whole-face scans, docs/results.md); "
        "unbounded: the windows' and the global fit's weights not held to [0, 1] (for scans, "
        "not a FACS rig); "
        "auto: used, and which kind, when they predict the take's own markers, left out one "
        "at a time, better",
    )
    _add_unbounded_fit_argument(parser)
    _add_take_prior_argument(parser)
    _add_denoise_argument(parser)
    _add_recommended_argument(parser)
    parser.add_argument(
        "--no-steady",
        dest="steady",
        action="store_false",
        help="solve each frame from its own markers alone: by default a dropout is filled from "
        "the take (its motion given the frame's other markers, or the marker's neighbours) and "
        "the dataset's detail is averaged over neighbouring frames, so the surface does not pop "
        "(for frames that are not a take's consecutive frames, e.g. a take sampled once a "
        "second)",
    )
    parser.add_argument(
        "--no-repair",
        dest="repair",
        action="store_false",
        help="keep the markers as given: by default a named label swap is undone and a spike "
        "or a marker off its track is solved as missing over its frames, and the take solved "
        "again (the take file is never touched; what was repaired is said and recorded)",
    )
    parser.add_argument(
        "--jaw",
        choices=list(pipeline.JAW_POSES),
        default="auto",
        help="models with a jaw rig: each frame's jaw pose from its blendshape fit (auto, "
        "fit), from the jaw's markers (track), or the rest pose (rest); see Model.solve",
    )


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
    """`--recommended` (`lgi solve`, `lgi batch`): `lgi.plan.choices.plan_solve`
    (recommended=True)."""
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


def add_frame_options(p: argparse.ArgumentParser) -> None:
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


def out_folder(value: str) -> str:
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


def seed_number(value: str) -> int:
    try:
        seed = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{value!r} is not an integer") from None
    if not 0 <= seed < 2**32:
        raise argparse.ArgumentTypeError(f"{seed}: a seed is an integer in 0..2^32-1")
    return seed


def positive_int(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {n}")
    return n


def non_negative(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (x >= 0 and x < float("inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text!r}")
    return x


def fraction(text: str) -> float:
    x = non_negative(text)
    if x >= 1:
        raise argparse.ArgumentTypeError(f"expected a fraction in [0, 1), got {text!r}")
    return x
