"""The capture front end's files: 2D marker tracks in (`read_tracks`: an `.npz` with `uv`),
the marker rest layout they are stabilised against (`read_rest`: a layout CSV or `.npy`
positions), and the stabilised bundles out (`write_bundles`: an `.npz` that is also a take,
with every stage's output beside it)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from lgi.errors import InputError
from lgi.io.atomic import atomic_path
from lgi.io.paths import output_file
from lgi.io.takes import Layout, read_layout

if TYPE_CHECKING:
    from lgi.capture.frontend import FrontEnd

F64 = NDArray[np.float64]

__all__ = ["read_rest", "read_tracks", "write_bundles"]


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


def read_rest(path: str | os.PathLike[str]) -> Layout:
    """The marker rest layout the tracks are stabilised against: a layout CSV
    (`lgi.io.takes.read_layout`), or `.npy` positions (B, 3) (names `m000`, ...)."""
    p = Path(path)
    if p.suffix.lower() != ".npy":
        return read_layout(p)
    try:
        rest = np.asarray(np.load(p), dtype=np.float64)
    except (OSError, ValueError) as e:
        raise InputError(f"{p}: cannot read marker rest positions ({e})") from None
    if rest.ndim != 2 or rest.shape[1] != 3:
        raise InputError(f"{p}: expected (B, 3) marker positions, got {rest.shape}")
    return Layout(names=[f"m{i:03d}" for i in range(rest.shape[0])], positions=rest, path=str(p))


def write_bundles(path: str | Path, front: FrontEnd, names: Sequence[str]) -> None:
    """Writes the stabilised bundles and the stages' outputs to an `.npz` that is also a take
    (`lgi.io.takes.read_npz`: `markers` and the layout's `names`, so `lgi solve` reads it, with
    the head transforms `rotations`, `translations`): `frames` (= `markers`), `points` (rig
    space), `views`, `reprojection_error`, `ray_origins`, `ray_directions` (rest space),
    `weights`, `spikes`."""
    rays = front.rays
    if len(names) != front.frames.shape[1]:
        raise InputError(f"{len(names)} marker names for {front.frames.shape[1]} markers")
    with atomic_path(output_file(path, "bundles output")) as tmp, open(tmp, "wb") as fh:
        _save_bundles(fh, front, names, rays)


def _save_bundles(fh: Any, front: FrontEnd, names: Sequence[str], rays: Any) -> None:
    np.savez(
        fh,
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
