"""What `--local-fits auto` chooses (`lgi.estimate_local_fits`, issue 34) on the protocols'
own takes: the scans protocol's (K = 120 scans from the other recording, 200 frames, 2 %
dropouts, seed 3), the capture protocol's with a quarter of ICT's shapes held out, and the
lomo protocol's real takes (AnimFace, retargeted; their noise estimated). Each line: the take,
whether local fits are chosen and which kind, and the left-out markers' mean distance (cm)
from the surface with them (bounded, unbounded) and without; docs/results.md puts the
choices beside the protocols' errors.

Usage: python scripts/local_fits_choices.py [--layouts markers_120 random:160:1 random:140:7]
[--sigma 0 0.02 0.05] [--held-out 0 0.25] [--no-lomo] [--denoise] [--unbounded-fit-auto
[--take-prior-auto]] (from the
checkout, ../shared beside it). `--unbounded-fit-auto`: every take is read as `--unbounded-fit
auto --local-fits auto` reads it (`lgi.choices.fits_choice`): the two choices and the lines
`lgi solve` says about them; `--take-prior-auto` with it: then `--take-prior auto` too.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import lgi
from lgi.io.livelink import read_livelinkface
from lgi.io.takes import read_raw
from lgi.lab import ict, lomo
from lgi.lab.capture import HingeJaw, random_layout
from lgi.lab.evaluate import _performance, capture_methods
from lgi.lab.scans import scan_session
from lgi.model import _auto_rig

ICT = "../shared/data/ict-facekit"
NAMES = ("alex_rom_4", "jmtechart_myslate_3")
RECORDINGS = [f"../shared/data/livelinkface/{r}.csv" for r in NAMES]


def layout(name: str, dataset: lgi.Dataset) -> np.ndarray:
    if name == "markers_120":
        return ict.load_layout(ICT).positions
    _, count, seed = name.split(":")
    return random_layout(dataset, int(count), int(seed), np.arange(ict.NARROW_FACE))  # type: ignore[arg-type]


def line(what: str, est: lgi.LocalFitsEstimate, seconds: float) -> None:
    chosen = {False: "no", True: "yes", "unbounded": "unbounded"}[est.local_fits]
    print(
        f"| {what} | {chosen} | {est.error_with:.4f} | {est.error_unbounded:.4f} | "
        f"{est.error_without:.4f} | {seconds:.1f} |",
        flush=True,
    )


def choose_both(
    frames: np.ndarray, model: lgi.Model, sigma: float | None, what: str, prior: bool
) -> None:
    """What `--unbounded-fit auto --local-fits auto` chooses (`lgi.choices.fits_choice`; with
    `prior`, then `--take-prior auto`: `lgi.choices.take_prior_choice`), and the distances it
    read, as one line."""
    from lgi.choices import fits_choice, take_prior_choice
    from lgi.local import UNBOUNDED

    said: list[str] = []
    t0 = time.perf_counter()
    local, free = fits_choice(
        "auto", "auto", frames, model, sigma, "auto", said.append, "auto" if prior else False
    )
    kind = {False: "no", True: "yes", "unbounded": "unbounded"}[local]
    took = ""
    if prior:
        unbounded = free or local == UNBOUNDED
        got = take_prior_choice("auto", frames, model, sigma, "auto", said.append, unbounded)
        took = f" | {'yes' if got is not None else 'no'}"
    print(
        f"| {what} | {kind} | {'unbounded' if free else 'boxed'}{took} | {'; '.join(said)} "
        f"| {time.perf_counter() - t0:.1f} |",
        flush=True,
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--layouts", nargs="+", default=["markers_120", "random:160:1", "random:140:7"])
    ap.add_argument("--sigma", type=float, nargs="+", default=[0.0, 0.02, 0.05])
    ap.add_argument("--held-out", type=float, nargs="+", default=[0.0, 0.25])
    ap.add_argument("--no-lomo", action="store_true", help="skip the real takes")
    ap.add_argument("--unbounded-fit-auto", action="store_true", help="the fit chosen per take")
    ap.add_argument(
        "--take-prior-auto", action="store_true", help="with --unbounded-fit-auto: the prior too"
    )
    ap.add_argument(
        "--denoise",
        action="store_true",
        help="each take denoised first (`lgi.denoise_take`, as `--denoise` does) and read with "
        "the noise it leaves",
    )
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    d = ict.load_dataset(ICT)
    region = ict.skin()
    hinge = HingeJaw.fit(d, ict.lower_teeth())
    rig, theta = _auto_rig(d)
    curves = [read_livelinkface(r).for_dataset(d.names) for r in RECORDINGS]
    if args.unbounded_fit_auto:
        prior_column = " take prior chosen |" if args.take_prior_auto else ""
        print(f"| take | local fits chosen | global fit chosen |{prior_column}", end="")
        print(" what was read | seconds |")
        print("|---|---|---|---|---|" + ("---|" if args.take_prior_auto else ""))
    else:
        print(
            "| take | local fits chosen | left out, with (cm) | with unbounded (cm) "
            "| without (cm) | seconds |"
        )
        print("|---|---|---|---|---|---|")
    for held in args.held_out:
        for name in args.layouts if held == 0.0 else ["markers_120"]:
            markers = layout(name, d)
            for i, perf in enumerate(curves):
                session = None
                if held == 0.0:
                    source = np.concatenate([c for k, c in enumerate(curves) if k != i])
                    session = scan_session(d, source, 120, hinge, theta, nonlinear=None)
                for sigma in args.sigma if held == 0.0 else [s for s in args.sigma if s > 0]:
                    take, _ = _performance(
                        d, perf, markers, frames=200, sigma=sigma, dropout=0.02,
                        holdout=held, seed=3, hinge=hinge, truth=None, region=region,
                    )  # fmt: skip
                    if session is not None:
                        methods = capture_methods(
                            session.dataset, markers, sigma, jaw=(rig, session.theta)
                        )
                    else:
                        methods = capture_methods(take.dataset, markers, sigma)
                    t0 = time.perf_counter()
                    kind = "scans K=120" if held == 0.0 else "capture, 25 % held out"
                    what = f"{kind}, {name}, {NAMES[i]}, sigma {sigma}"
                    model = methods["LGI"].model
                    frames, noise = take.frames, sigma
                    if args.denoise and sigma > 0:
                        den = lgi.denoise_take(frames, sigma)
                        frames, noise = den.frames, den.marker_noise
                    if args.unbounded_fit_auto:
                        choose_both(frames, model, noise, what, args.take_prior_auto)
                        continue
                    est = lgi.estimate_local_fits(frames, model, marker_noise=noise)
                    line(what, est, time.perf_counter() - t0)
    if args.no_lomo:
        return
    lm = np.asarray(ict.load_landmarks(ICT), dtype=np.int64)
    marks = {n: int(lm[k]) for n, k in lomo.ANIMFACE_IBUG.items()}
    face = ict.face_triangles(d)
    for path in ict.animface(Path(ICT).parent):
        real = lomo.retarget(read_raw(path), d.neutral, face, marks)
        frames = real.frames[:: max(1, real.frames.shape[0] // 250)]
        model = capture_methods(d, real.rest, None, frames)["LGI"]
        t0 = time.perf_counter()
        if args.unbounded_fit_auto:
            choose_both(
                frames,
                model.model,
                model.marker_noise,
                f"lomo, {Path(path).stem}",
                args.take_prior_auto,
            )
            continue
        est = lgi.estimate_local_fits(frames, model.model, marker_noise=model.marker_noise)
        line(f"lomo, {Path(path).stem}", est, time.perf_counter() - t0)


if __name__ == "__main__":
    sys.exit(main())
