"""Jaw articulation and temporal smoothing on the built-in sample (true rigid jaw rotation up
to 25 degrees): per-vertex error with and without jaw handling, jaw tracking error against the
sample's true jaw poses, and temporal jitter with and without smoothing at 0.5 mm marker noise.
Prints markdown tables (docs/results.md quotes them).

Usage: python scripts/jaw_results.py
"""

from __future__ import annotations

import time

import numpy as np

import lgi
from lgi.lab.sample import make_sample, sample_dataset
from lgi.solve.jaw import JawRig, estimate_rig


def jitter(v: np.ndarray) -> float:
    """Mean norm of the second difference of vertex positions over time (cm)."""
    return float(np.linalg.norm(v[2:] - 2 * v[1:-1] + v[:-2], axis=2).mean())


def errors(v: np.ndarray, truth: np.ndarray) -> str:
    e = 10 * np.linalg.norm(v - truth, axis=2)  # mm
    return f"{e.mean():.3f} | {np.percentile(e, 95):.3f} | {e.max():.2f}"


def lookup_bytes(model: lgi.Model) -> int:
    """Bytes of the per-bin lookup data: grid indices plus the re-posed shapes (f32) and the
    bin's neutral (f64) each bin keeps for blending."""
    index = int(model.core.bundle_stats()["index_bytes"].sum())
    j = model.core.jaw()
    v = model.num_vertices
    if j is None or "bin_members" not in j:
        members = [len(model.dataset.names)] if j is not None else [0]
    else:
        members = [len(m) for m in j["bin_members"]]
    return index + sum(12 * v * m + 24 * v for m in members)


def binned_results(s, data, rig, theta, unbinned, jawed) -> None:  # type: ignore[no-untyped-def]
    """Point clouds binned by jaw opening: error with tracked and true poses, build time and
    lookup memory per bin count (unbinned first, for reference)."""
    opens, counts = np.unique(np.round(np.degrees(theta[:, 0]), 3) + 0.0, return_counts=True)
    by_opening = dict(zip(opens.tolist(), counts.tolist(), strict=True))
    print(f"\nShape openings (deg: count): {by_opening}\n")
    print(
        "| clouds | members per bin | tracked: mean / p95 / max (mm) "
        "| true poses: mean / p95 / max (mm) | build (s) | lookup memory (MB) |"
    )
    print("|---|---|---|---|---|---|")
    t0 = time.perf_counter()
    lgi.Model.build(data, s.markers_rest, jaw=rig, shape_theta=theta)
    build0 = time.perf_counter() - t0
    r1, r2 = unbinned
    print(
        f"| unbinned (rest pose) | {len(s.names)} | {errors(r1.vertices, s.truth)} "
        f"| {errors(r2.vertices, s.truth)} | {build0:.2f} | {lookup_bytes(jawed) / 1e6:.1f} |"
    )
    for bins, overlap in ((2, 0.0), (2, 0.25), (3, 0.15), (3, 0.3)):
        t0 = time.perf_counter()
        m = lgi.Model.build(
            data, s.markers_rest, jaw=rig, shape_theta=theta, jaw_bins=bins, bin_overlap=overlap
        )
        build = time.perf_counter() - t0
        members = "/".join(str(len(b)) for b in m.core.jaw()["bin_members"])
        b1 = m.solve(s.performance, jaw="track", quiet=True)
        b2 = m.solve(s.performance, jaw=s.jaw_theta, quiet=True)
        res = max(b1.bundle_residuals.max(), b2.bundle_residuals.max()) / m.diagonal
        use = np.bincount(b2.jaw_bin, minlength=bins).tolist()
        print(
            f"| {bins} bins, overlap {np.degrees(overlap):.1f} deg (frames per bin {use}, "
            f"residual {res:.0e}) | {members} | {errors(b1.vertices, s.truth)} "
            f"| {errors(b2.vertices, s.truth)} | {build:.2f} | {lookup_bytes(m) / 1e6:.1f} |"
        )


def main() -> None:
    s = make_sample(0)
    data = sample_dataset(s)
    plain = lgi.Model.build(data, s.markers_rest, jaw=None)
    rig, theta = estimate_rig(s.neutral, s.shapes, s.names, triangles=s.triangles)
    jawed = lgi.Model.build(data, s.markers_rest, jaw=rig, shape_theta=theta)
    r0 = plain.solve(s.performance, quiet=True)
    r1 = jawed.solve(s.performance, jaw="track", quiet=True)
    r2 = jawed.solve(s.performance, jaw=s.jaw_theta, quiet=True)
    print("| method (sample performance, 0.2 mm noise) | mean (mm) | p95 (mm) | max (mm) |")
    print("|---|---|---|---|")
    print(f"| LGI without jaw handling | {errors(r0.vertices, s.truth)} |")
    print(f"| LGI, estimated rig, tracked jaw | {errors(r1.vertices, s.truth)} |")
    print(f"| LGI, estimated rig, true jaw poses | {errors(r2.vertices, s.truth)} |")
    res = max(r.bundle_residuals.max() for r in (r0, r1, r2)) / plain.diagonal
    print(f"\nMax bundle residual over the three: {res:.1e} of the diagonal.\n")
    d = np.abs(r1.jaw_theta - s.jaw_theta)
    print("| tracked jaw vs truth | mean | max |\n|---|---|---|")
    print(f"| open (deg) | {np.degrees(d[:, 0]).mean():.3f} | {np.degrees(d[:, 0]).max():.3f} |")
    print(f"| lateral (deg) | {np.degrees(d[:, 1]).mean():.3f} | {np.degrees(d[:, 1]).max():.3f} |")
    print(f"| forward (mm) | {10 * d[:, 2].mean():.3f} | {10 * d[:, 2].max():.3f} |")

    binned_results(s, data, rig, theta, (r1, r2), jawed)

    noisy = make_sample(0, noise_mm=0.5)
    true_rig = JawRig(pivot=noisy.jaw_pivot, weights=noisy.jaw_weights)
    m = lgi.Model.build(data, noisy.markers_rest, jaw=true_rig, shape_theta=noisy.shape_jaw_theta)
    print("\n| smoothing (0.5 mm noise) | jitter (mm) | mean error (mm) | max residual / diag |")
    print("|---|---|---|---|")
    print(f"| ground truth | {10 * jitter(noisy.truth):.4f} | 0 | - |")
    for w in (0, 3, 5, 9):
        r = m.solve(noisy.performance, jaw=noisy.jaw_theta, smooth_window=w, quiet=True)
        e = 10 * np.linalg.norm(r.vertices - noisy.truth, axis=2).mean()
        rr = r.bundle_residuals.max() / m.diagonal
        print(f"| window {w} | {10 * jitter(r.vertices):.4f} | {e:.3f} | {rr:.1e} |")


if __name__ == "__main__":
    main()
