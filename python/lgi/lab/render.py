"""Figures of per-vertex error for the docs and the demo: several methods' meshes drawn
headless side by side (`lgi.review.render.draw_mesh`) on one colour scale, so the panels are
comparable."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi.review.render import draw_mesh

F64 = NDArray[np.float64]

__all__ = ["panel"]


def panel(
    path: str | os.PathLike[str],
    meshes: Mapping[str, ArrayLike],
    triangles: ArrayLike,
    errors: Mapping[str, ArrayLike],
    *,
    vmax: float | None = None,
    views: Sequence[float] = (0.0, 35.0),
    cell_inches: float = 3.0,
    dpi: int = 100,
    units: str = "",
    label: str = "vertex error",
    per_column: bool = False,
) -> tuple[int, int]:
    """Side-by-side panel: one column per mesh (e.g. ground truth | displacement interpolation
    | blendshape fit | LGI-RBF | LGI), one row per view (front, three-quarter). Meshes without
    an entry in `errors` are drawn grey. Every column shares one colour scale (0..`vmax`,
    default the largest error), named `label` (in `units`) on the colour bar; with
    `per_column`, each column has its own scale (0..its largest error) and colour bar under
    it, so a method whose errors are 10x smaller than the worst one's is still readable.
    Writes a PNG; returns its (width, height) in pixels."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    names = list(meshes)
    if vmax is None:
        vmax = max((float(np.max(e)) for e in errors.values()), default=1.0) or 1.0
    norm = Normalize(0.0, vmax)
    cmap = _cmap()
    ncol, nrow = len(names), len(views)
    width_in = cell_inches * ncol + (0.2 if per_column else 1.0)
    below = 0.9 if per_column else 0.0
    fig = Figure(figsize=(width_in, cell_inches * nrow + 0.4 + below), dpi=dpi)
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrow, ncol, squeeze=False)
    centre = np.asarray(next(iter(meshes.values())), dtype=np.float64).mean(axis=0)
    height_in = cell_inches * nrow + 0.4 + below
    norms = {
        name: Normalize(0.0, float(np.max(errors[name])) or 1.0) if per_column else norm
        for name in names
        if name in errors
    }
    for j, name in enumerate(names):
        for i, yaw in enumerate(views):
            ax = axes[i][j]
            col_norm = norms.get(name, norm)
            draw_mesh(ax, meshes[name], triangles, errors.get(name), col_norm, cmap, yaw, centre)
            if i == 0:
                ax.set_title(name, fontsize=10)
    if per_column:
        fig.subplots_adjust(
            left=0.01, right=0.99, top=1 - 0.4 / height_in, bottom=below / height_in, wspace=0.02
        )
        for j, name in enumerate(names):
            if name not in norms:
                continue
            box = axes[-1][j].get_position()
            cax = fig.add_axes(
                (box.x0 + 0.1 * box.width, 0.45 / height_in, 0.8 * box.width, 0.1 / height_in)
            )
            cb = fig.colorbar(
                ScalarMappable(norm=norms[name], cmap=cmap), cax=cax, orientation="horizontal"
            )
            cb.ax.tick_params(labelsize=7)
            cb.set_label(f"{label}{' (' + units + ')' if units else ''}", fontsize=7)
        _save(fig, path, dpi)
        w, h = fig.canvas.get_width_height()
        return int(w), int(h)
    fig.subplots_adjust(left=0.01, right=1 - 0.9 / width_in, top=0.92, bottom=0.01, wspace=0.02)
    cax = fig.add_axes((1 - 0.75 / width_in, 0.1, 0.15 / width_in, 0.75))
    cb = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), cax=cax)
    cb.set_label(f"{label}{' (' + units + ')' if units else ''}")
    _save(fig, path, dpi)
    w, h = fig.canvas.get_width_height()
    return int(w), int(h)


def _save(fig: Any, path: str | os.PathLike[str], dpi: int) -> None:
    """The figure as a PNG written whole or not at all (`lgi.io.atomic`)."""
    from lgi.io.atomic import atomic_path

    with atomic_path(path) as tmp:
        fig.savefig(os.fspath(tmp), dpi=dpi, format="png")


def _cmap():  # type: ignore[no-untyped-def]
    from matplotlib import colormaps

    return colormaps["viridis"]
