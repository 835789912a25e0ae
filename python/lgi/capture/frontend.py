"""The capture front end in one call: 2D marker tracks from calibrated cameras to stabilised
bundles ready for `Model.solve`, with what each stage found (views, rejections, head
transforms, removed spikes). Its files (tracks in, bundles out) are `lgi.io.tracks`'s.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi.capture import stabilize
from lgi.capture.camera import Camera, Rays
from lgi.capture.triangulation import Triangulation, triangulate
from lgi.errors import InputError

F64 = NDArray[np.float64]

__all__ = ["FrontEnd", "process"]


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
        """Rays of the single-view markers in the frames' (rest) space, for
        `lgi.capture.rays`."""
        from lgi.capture.rays import to_rest_space

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
