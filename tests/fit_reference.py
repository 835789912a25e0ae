"""The global fit's rows from their definition, an independent reference for the core's: the
rig's own unskinning of each shape's marker positions by that shape's pose and of a take's
markers by each frame's pose (each bundle's jaw weight), less the bundles' rest."""

from __future__ import annotations

from typing import Any

import numpy as np


def fit_reference(model: Any, frames: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, ...]:
    """The fit's matrix (3B, S; row 3n + d coordinate d of bundle n), the bundles' rest (B, 3)
    and `frames` unskinned by the poses `theta` (F, B, 3; missing markers as zeros)."""
    data, rig = model.dataset, model.jaw_rig
    jaw = model.core.jaw()
    bundle_jaw = np.asarray(jaw["bundle_weights"], dtype=np.float64)
    x0, shapes = np.asarray(data.neutral), np.asarray(data.shapes, dtype=np.float64)
    rest = model.bundle_positions(x0)
    on_shapes = model.bundle_positions(x0[None] + shapes)
    thetas = np.asarray(jaw["shape_theta"], dtype=np.float64)
    columns = rig.unskin(on_shapes, thetas, weights=bundle_jaw) - rest[None]
    a = columns.transpose(1, 2, 0).reshape(-1, len(shapes))
    markers = rig.unskin(np.nan_to_num(frames), np.asarray(theta), weights=bundle_jaw)
    return a, rest, markers
