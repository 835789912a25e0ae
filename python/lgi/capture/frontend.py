"""The capture front end in one call: 2D marker tracks from calibrated cameras to stabilised
bundles ready for `Model.solve`, with what each stage found (views, rejections, head
transforms, removed spikes). Also the helmet demo: the built-in sample filmed by the synthetic
helmet and taken through the whole chain, each stage scored against its truth.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi import stabilize
from lgi.camera import Camera, Rays, Triangulation, triangulate
from lgi.errors import InputError

F64 = NDArray[np.float64]

__all__ = ["FrontEnd", "helmet_demo", "process", "read_tracks", "write_bundles"]


@dataclass(frozen=True)
class FrontEnd:
    """Stabilised bundles and the stages that made them."""

    frames: F64
    """(F, B, 3) bundles in the rest layout's space; NaN = missing (give to `Model.solve`)."""
    triangulation: Triangulation
    """Points in rig space, views, reprojection errors, rays of single-view markers."""
    alignment: stabilize.Alignment
    """Head transforms per frame (`capture = R rest + t`) and inlier flags."""
    weights: F64
    """(B,) the stable weights the alignment used."""
    spikes: NDArray[np.bool_]
    """(F, B) samples `despike` removed."""

    @property
    def rays(self) -> Rays:
        """Rays of the single-view markers in the frames' (rest) space, for `lgi.rays`."""
        from lgi.rays import to_rest_space

        return to_rest_space(self.triangulation.rays, self.alignment)

    def summary(self) -> str:
        """Lines saying what each stage did."""
        return "\n".join(
            [
                f"triangulation: {self.triangulation.summary()}",
                f"stabilisation: inlier RMS median {np.median(self.alignment.rms):.4g} "
                f"(data units), {self.alignment.inliers.mean():.1%} of marker samples inliers",
                f"despike: {int(self.spikes.sum())} samples removed",
            ]
        )


def process(
    cameras: Sequence[Camera],
    uv: ArrayLike,
    rest: ArrayLike,
    *,
    max_error: float | None = 3.0,
    weights: ArrayLike | None = None,
    despike: bool = True,
) -> FrontEnd:
    """2D tracks uv (F, B, C, 2) (pixels, NaN = unseen) of markers with rest layout (B, 3)
    -> `triangulate` (rejecting markers above `max_error` px RMS) -> `stable_weights` (unless
    `weights` are given) -> `align` -> `despike` (unless False)."""
    r = np.asarray(rest, dtype=np.float64)
    a = np.asarray(uv, dtype=np.float64)
    if a.ndim != 4 or r.ndim != 2 or a.shape[1] != r.shape[0]:
        raise InputError(
            f"uv (F, B, C, 2) and rest (B, 3) must agree on B: got {a.shape} and {r.shape}"
        )
    tri = triangulate(cameras, a, max_error=max_error)
    w = (
        stabilize.stable_weights(tri.points, r)
        if weights is None
        else np.asarray(weights, dtype=np.float64)
    )
    al = stabilize.align(tri.points, r, w)
    frames, spikes = (
        stabilize.despike(al.frames) if despike else (al.frames, np.zeros(a.shape[:2], bool))
    )
    return FrontEnd(frames=frames, triangulation=tri, alignment=al, weights=w, spikes=spikes)


def read_tracks(path: str | Path, num_cameras: int) -> F64:
    """2D tracks from an `.npz` with `uv` (F, B, C, 2) in pixels (NaN = unseen)."""
    p = Path(path)
    try:
        with np.load(p) as z:
            if "uv" not in z.files:
                raise InputError(f"{p}: no array 'uv' (F, B, C, 2); it has {sorted(z.files)}")
            uv = np.asarray(z["uv"], dtype=np.float64)
    except (OSError, ValueError) as e:
        raise InputError(f"{p}: cannot read the tracks ({e})") from None
    if uv.ndim != 4 or uv.shape[2:] != (num_cameras, 2):
        raise InputError(f"{p}: uv must be (F, B, {num_cameras}, 2), got {uv.shape}")
    return uv


def write_bundles(path: str | Path, front: FrontEnd, names: Sequence[str]) -> None:
    """Writes the stabilised bundles and the stages' outputs to an `.npz` that is also a take
    (`lgi.takes.read_npz`: `markers` and the layout's `names`, so `lgi solve` reads it, with
    the head transforms `rotations`, `translations`): `frames` (= `markers`), `points` (rig
    space), `views`, `reprojection_error`, `ray_origins`, `ray_directions` (rest space),
    `weights`, `spikes`."""
    rays = front.rays
    if len(names) != front.frames.shape[1]:
        raise InputError(f"{len(names)} marker names for {front.frames.shape[1]} markers")
    np.savez(
        Path(path),
        markers=front.frames,
        names=np.asarray(list(names), dtype=str),
        frames=front.frames,
        points=front.triangulation.points,
        rotations=front.alignment.rotations,
        translations=front.alignment.translations,
        views=front.triangulation.views,
        reprojection_error=front.triangulation.reprojection_error,
        ray_origins=rays.origins,
        ray_directions=rays.directions,
        weights=front.weights,
        spikes=front.spikes,
    )


def helmet_demo(out: Path, seed: int = 0, quiet: bool = False) -> str:
    """The built-in sample's performance filmed by the synthetic helmet (`lgi.helmet`) and
    taken through the whole chain; writes `out/helmet_report.md`, `out/helmet.yaml` (the
    rig's calibration) and `out/tracks.npz` (the 2D tracks), and returns the report."""
    from lgi import camera, helmet
    from lgi.dataset import sample_dataset
    from lgi.model import Model, estimate_marker_noise
    from lgi.sample import make_sample

    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    s = make_sample(seed)
    data = sample_dataset(s)
    # The jaw stage: the default build estimates a rig from the dataset's jaw shapes and the
    # default solve takes each frame's jaw pose from its global fit.
    model = Model.build(data, s.markers_rest)
    true_bundles = model.bundle_positions(s.truth)
    cams = helmet.helmet_cameras(s.markers_rest)
    motion = helmet.head_motion(true_bundles.shape[0], s.markers_rest, seed=seed)
    take = helmet.make_helmet_take(true_bundles, cams, motion, seed=seed + 1)
    camera.save_cameras(out / "helmet.yaml", cams)
    np.savez(out / "tracks.npz", uv=take.uv)
    front = process(cams, take.uv, s.markers_rest)
    sigma = estimate_marker_noise(front.frames)
    diag = model.diagonal

    def face(frames: F64, **kw: object) -> str:
        res = model.solve(frames, quiet=True, **kw)  # type: ignore[arg-type]
        e = np.linalg.norm(res.vertices - s.truth, axis=2) / diag
        return f"{e.mean():.2e} | {np.percentile(e, 95):.2e} | {e.max():.2e}"

    e3d = np.linalg.norm(front.triangulation.points - take.points, axis=2) / diag
    rel = np.einsum("fji,fjk->fik", front.alignment.rotations, motion.rotations)
    cos = np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0)
    deg = np.degrees(np.arccos(cos))
    lines = [
        "# lgi helmet demo",
        "",
        f"Sample seed {seed}: {true_bundles.shape[0]} frames, {true_bundles.shape[1]} markers, "
        f"2 fisheye cameras, 0.5 px noise, occlusions and mistracks (lgi.helmet). Chain: "
        "triangulate -> stabilise (stable weights) -> despike -> jaw (estimated rig, pose "
        "from each frame's fit) -> solve.",
        "",
        *front.summary().splitlines(),
        "",
        "| stage | mean | p95 | max |",
        "|---|---|---|---|",
        f"| 3D marker error / diagonal | {np.nanmean(e3d):.2e} | "
        f"{np.nanpercentile(e3d, 95):.2e} | {np.nanmax(e3d):.2e} |",
        f"| head rotation error (deg) | {deg.mean():.3f} | {np.percentile(deg, 95):.3f} | "
        f"{deg.max():.3f} |",
        f"| face error / diagonal, solved from the true bundles | {face(true_bundles)} |",
        f"| face error / diagonal, full chain (marker_noise={sigma:.3g}) | "
        f"{face(front.frames, marker_noise=sigma)} |",
        f"| face error / diagonal, triangulated, not stabilised | "
        f"{face(front.triangulation.points, marker_noise=sigma)} |",
        "",
        f"({time.perf_counter() - t0:.1f} s)",
    ]
    text = "\n".join(lines) + "\n"
    (out / "helmet_report.md").write_text(text)
    if not quiet:
        print(text, end="")
        print(f"wrote {out}/helmet_report.md, {out}/helmet.yaml and {out}/tracks.npz")
    return text
