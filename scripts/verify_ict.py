"""ICT-FaceKit accuracy tables for docs/results.md: the paper's §7.1 verification (every shape's
own marker positions) and leave-one-out (build without shape k, solve shape k), on the real
ICT data with markers_120. Prints markdown; `--out FILE` also writes it.

Usage: python scripts/verify_ict.py [--data ../shared/data/ict-facekit] [--out docs/ict-tables.md]
"""

from __future__ import annotations

import argparse
import os
import resource
import time
from pathlib import Path

import numpy as np

import lgi
from lgi.data.dataset import without_shapes
from lgi.lab import ict as ict_data

SKIN = ict_data.SKIN_VERTICES
MOVED = 1e-3  # cm


def region(p: np.ndarray) -> str:
    """Coarse face region of a point (ICT coordinates, cm) for saying where errors are."""
    x, y, z = p
    if 1.5 < abs(x) < 5.5 and 2.0 < y < 5.0:
        return "eyelids/eye"
    if y > 5.0:
        return "forehead/brow"
    if abs(x) < 3.0 and -6.5 < y < -1.5 and z > 8.5:
        return "lips/mouth"
    if y < -6.5:
        return "chin/jaw"
    if abs(x) >= 5.5 or z < 6.0:
        return "side of face"
    return "cheek/nose"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    default = ict_data.find(os.environ.get(ict_data.ENV), start=Path(__file__).parent)
    ap.add_argument("--data", type=Path, default=default)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--skip-loo", action="store_true")
    args = ap.parse_args()

    t0 = time.perf_counter()
    data = ict_data.load_dataset(args.data)
    t_load = time.perf_counter() - t0
    markers = ict_data.load_markers(args.data)
    t0 = time.perf_counter()
    model = lgi.Model.build(data, markers, jaw=None)
    t_build = time.perf_counter() - t0
    stats = model.core.bundle_stats()
    out: list[str] = []
    say = out.append
    say("## ICT-FaceKit build (markers_120)\n")
    say("| quantity | value |\n|---|---|")
    say(f"| load neutral + 57 shapes (s) | {t_load:.2f} |")
    say(f"| build (s) | {t_build:.2f} |")
    pts, tets, mem = stats["points"], stats["tets"], stats["index_bytes"]
    say(f"| cloud points per bundle (min/mean/max) | {pts.min()}/{pts.mean():.1f}/{pts.max()} |")
    say(f"| tets per bundle (min/mean/max) | {tets.min()}/{tets.mean():.0f}/{tets.max()} |")
    say(f"| tet index memory, all bundles (MiB) | {mem.sum() / 2**20:.1f} |")
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    say(f"| peak RSS so far (MiB) | {rss:.0f} |")
    say("")

    meshes = data.neutral[None] + data.shapes.astype(np.float64)
    frames = model.bundle_positions(meshes)
    rest = model.bundle_positions(data.neutral)
    t0 = time.perf_counter()
    res = model.solve(frames, temporal=False, quiet=True)
    t_solve = (time.perf_counter() - t0) / len(frames)
    w = model.core.sew_weights()
    ip, ix = w["indptr"], w["indices"]
    say("## Verification (paper §7.1): each shape's own marker positions\n")
    say(
        f"Solve: {1e3 * t_solve:.2f} ms per frame (57 independent frames, 2 threads). "
        f"Max bundle residual: {res.bundle_residuals.max():.2e} cm "
        f"({res.bundle_residuals.max() / model.diagonal:.1e} of the diagonal).\n"
    )
    say(
        "Errors over the face skin (vertices 0..9408), cm. *Observed* vertices are those whose "
        "natural-neighbour bundles all selected the shape; the rest of the error is skin that no "
        "marker observes.\n"
    )
    say(
        "| shape | mean disp. | moved bundles | selected alone | mean err | max err | "
        "max err (observed) | where the max is |"
    )
    say("|---|---|---|---|---|---|---|---|")
    worst_obs = 0.0
    for k, name in enumerate(data.names):
        moved = np.linalg.norm(frames[k] - rest, axis=1) > MOVED
        sel = res.choices.weights[k] * (res.choices.shapes[k] == k)
        alone = sel.sum(axis=1) >= 0.999
        err = np.linalg.norm(res.vertices[k, :SKIN] - meshes[k, :SKIN], axis=1)
        disp = np.linalg.norm(data.shapes[k, :SKIN], axis=1)
        obs = np.array([alone[ix[ip[v] : ip[v + 1]]].all() for v in range(SKIN)])
        max_obs = float(err[obs].max()) if obs.any() else 0.0
        worst_obs = max(worst_obs, max_obs)
        vmax = int(err.argmax())
        say(
            f"| {name} | {disp.mean():.4f} | {moved.sum()} | {(alone & moved).sum()} | "
            f"{err.mean():.2e} | {err.max():.2e} | {max_obs:.1e} | "
            f"{region(data.neutral[vmax])} (v{vmax}) |"
        )
    say(f"\nLargest error on observed skin over all shapes: {worst_obs:.2e} cm.\n")

    if not args.skip_loo:
        say("## Leave-one-out: build without shape k, solve shape k's markers\n")
        say("| shape | mean disp. | mean err | max err | mean err / mean disp. |")
        say("|---|---|---|---|---|")
        means = []
        t0 = time.perf_counter()
        for k, name in enumerate(data.names):
            sub = without_shapes(data, [k])
            m = lgi.Model.build(sub, markers, jaw=None)
            r = m.solve(frames[k : k + 1], temporal=False, quiet=True)
            err = np.linalg.norm(r.vertices[0, :SKIN] - meshes[k, :SKIN], axis=1)
            disp = np.linalg.norm(data.shapes[k, :SKIN], axis=1).mean()
            means.append((err.mean(), disp))
            say(
                f"| {name} | {disp:.4f} | {err.mean():.4f} | {err.max():.4f} | "
                f"{err.mean() / max(disp, 1e-12):.2f} |"
            )
        e = np.array(means)
        say(
            f"\nOver the 57 shapes: mean error {e[:, 0].mean():.4f} cm against a mean displacement "
            f"of {e[:, 1].mean():.4f} cm ({time.perf_counter() - t0:.0f} s for 57 builds).\n"
        )
    text = "\n".join(out)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
