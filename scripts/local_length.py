"""The local fits' window length (`lgi._lgi.LOCAL_LENGTH`, median marker spacings) against the
face-skin error, on the protocols' own takes (issue 34; docs/concepts.md): the scans protocol
(K = 120 scans from the other recording, 200 frames, 2 % dropouts, seed 3; linear or
nonlinear truth) and the capture protocol with a quarter of ICT's shapes held out. Each take's
plan is read as `--recommended` reads it, with the local fits' kind given (unbounded on scans,
bounded with ICT's shapes: what it chooses there); the take is solved once and its local fits'
surface made with windows of each length. One line per take and length: the mean face-skin
error (cm) and the windows' mean size; the solve without local fits first.

Usage: python scripts/local_length.py [--protocol scans|heldout|nonlinear]
[--layouts markers_120 random:160:1] [--sigma 0 0.02 0.05] [--lengths 1 1.2 1.4 1.7]
(from the checkout, ../shared beside it). A layout is `markers_120` or `random:N:SEED`.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

import lgi
from lgi.choices import plan_solve
from lgi.io.livelink import read_livelinkface
from lgi.lab import ict
from lgi.lab.capture import HingeJaw, NonlinearTruth
from lgi.lab.evaluate import _performance
from lgi.lab.scans import scan_session
from lgi.local import UNBOUNDED, local_pieces
from lgi.model import _auto_rig

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scans_results


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--protocol", choices=["scans", "heldout", "nonlinear"], default="scans")
    ap.add_argument("--layouts", nargs="+", default=["markers_120", "random:160:1"])
    ap.add_argument("--sigma", type=float, nargs="+", default=[0.0, 0.02, 0.05])
    ap.add_argument("--lengths", type=float, nargs="+", default=[1.0, 1.2, 1.4, 1.7])
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    d = ict.load_dataset(scans_results.ICT)
    hinge = HingeJaw.fit(d, ict.lower_teeth())
    rig, theta = _auto_rig(d)
    truth_rig = NonlinearTruth(d) if args.protocol == "nonlinear" else None
    bounded = args.protocol == "heldout"
    region = ict.skin()
    curves = [read_livelinkface(r).for_dataset(d.names) for r in scans_results.RECORDINGS]
    print("| layout | performance | sigma (cm) | windows (spacings) | mean window | error (cm) |")
    print("|---" * 6 + "|")
    for name in args.layouts:
        markers = scans_results.layout(name, d)
        for perf, rec in enumerate(scans_results.RECORDINGS):
            source = np.concatenate([c for k, c in enumerate(curves) if k != perf])
            for sigma in args.sigma:
                take, _ = _performance(
                    d,
                    curves[perf],
                    markers,
                    frames=200,
                    sigma=sigma,
                    dropout=0.02,
                    holdout=0.25 if bounded else 0.0,
                    seed=3,
                    hinge=hinge,
                    truth=truth_rig,
                    region=region,
                )
                if bounded:
                    model = lgi.Model.build(take.dataset, markers)
                else:
                    session = scan_session(d, source, 120, hinge, theta, nonlinear=truth_rig)
                    model = lgi.Model.build(
                        session.dataset, markers, jaw=rig, shape_theta=session.theta
                    )
                plan = plan_solve(
                    np.asarray(take.frames),
                    model,
                    recommended=True,
                    local_fits=True if bounded else UNBOUNDED,
                    unbounded_fit=not bounded,
                    take_prior=False,
                )
                options = plan.solve_options()
                options.pop("local_fits", None)
                res = model.solve(plan.frames, quiet=True, **options)
                truth = np.asarray(take.truth)[:, region]

                def error(vertices: np.ndarray, truth: np.ndarray = truth) -> float:
                    return float(np.linalg.norm(vertices[:, region] - truth, axis=-1).mean())

                cell = f"| {name} | {Path(rec).stem} | {sigma}"
                print(f"{cell} | none | - | {error(np.asarray(res.vertices)):.5f} |", flush=True)
                pieces = local_pieces(model)
                for length in args.lengths:
                    got = pieces.surface(res, bounded=bounded, lengths=length)
                    size = pieces.fits_for(bounded, length).window_sizes.mean()
                    print(f"{cell} | {length} | {size:.1f} | {error(got):.5f} |", flush=True)


if __name__ == "__main__":
    main()
