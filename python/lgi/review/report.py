"""`lgi report`: one self-contained HTML page to review a solved take (an `lgi solve -o *.npz`
file): units on every figure, missing samples, a marker x frame heatmap of residuals, the
worst markers and frames, the jaw pose over time and, given a second solve of the same mesh (a
reference: another method, an older model, a ground truth), per-frame and per-vertex
differences. Plots are matplotlib PNGs embedded as data URIs, so the file opens without a
server or a network."""

from __future__ import annotations

import base64
import html
import io
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lgi.errors import InputError
from lgi.io.atomic import atomic_path
from lgi.io.result import Result, read_result_npz

F64 = NDArray[np.float64]

__all__ = [
    "Comparison",
    "Jump",
    "MarkerStats",
    "WorstFrame",
    "compare",
    "marker_stats",
    "render_report",
    "surface_jumps",
    "worst_frames",
    "worst_markers",
    "write_report",
]

WORST_SHOWN = 10
"""Rows of the worst-markers and worst-frames tables."""

_CHI3_MEDIAN = 1.5381722
"""Median of a chi distribution with 3 degrees of freedom: the median distance of an isotropic
Gaussian 3D error of sigma 1 per coordinate (turns a median residual into a sigma)."""


@dataclass(frozen=True)
class MarkerStats:
    """Per-marker summary of a solved take's residuals (NaN where a marker is never present)."""

    names: list[str]
    median: F64
    p95: F64
    max: F64
    worst_frame: NDArray[np.int64]
    """Index (0-based, into the solve) of each marker's largest residual; -1 if never present."""
    missing: F64
    """Fraction of frames each marker is missing."""
    longest_gap: NDArray[np.int64]
    """Longest run of consecutive missing frames."""


def _longest_run(flags: NDArray[np.bool_]) -> int:
    """Length of the longest run of True in a 1-D bool array."""
    if not flags.any():
        return 0
    padded = np.concatenate([[False], flags, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return int((edges[1::2] - edges[::2]).max())


def _present(solved: Result) -> F64:
    """(F, B) residuals, NaN where a marker is missing."""
    return np.where(solved.missing, np.nan, solved.bundle_residuals.astype(np.float64))


def marker_stats(solved: Result) -> MarkerStats:
    """Residual statistics of every marker over the frames where it is present."""
    r = _present(solved)
    present = ~solved.missing
    seen = present.any(axis=0)
    with np.errstate(all="ignore"):
        filled = np.where(present, r, -np.inf)
        worst = np.where(seen, np.argmax(filled, axis=0), -1)
        median = np.full(r.shape[1], np.nan)
        p95 = np.full(r.shape[1], np.nan)
        mx = np.full(r.shape[1], np.nan)
        if seen.any():
            median[seen] = np.nanmedian(r[:, seen], axis=0)
            p95[seen] = np.nanpercentile(r[:, seen], 95, axis=0)
            mx[seen] = np.nanmax(r[:, seen], axis=0)
    gaps = np.array([_longest_run(solved.missing[:, b]) for b in range(r.shape[1])], np.int64)
    return MarkerStats(
        names=list(solved.marker_names),
        median=median,
        p95=p95,
        max=mx,
        worst_frame=worst.astype(np.int64),
        missing=solved.missing.mean(axis=0).astype(np.float64),
        longest_gap=gaps,
    )


def _largest_first(values: F64, count: int) -> list[int]:
    """Indices of the `count` largest finite `values`, largest first."""
    order = np.argsort(np.nan_to_num(values, nan=-np.inf, neginf=-np.inf))[::-1][:count]
    return [int(k) for k in order if np.isfinite(values[k])]


def worst_markers(stats: MarkerStats, count: int) -> list[int]:
    """The markers with the largest residual, largest first (never-present ones left out)."""
    return _largest_first(stats.max, count)


@dataclass(frozen=True)
class WorstFrame:
    frame: int
    """Index into the solve (its time code is `start + frame`)."""
    residual: float
    marker: int
    """The marker with that residual."""


def worst_frames(solved: Result, count: int) -> list[WorstFrame]:
    """The `count` frames with the largest present residual, largest first, with the marker."""
    r = _present(solved)
    with np.errstate(all="ignore"):
        frame_max = np.nanmax(np.where(np.isfinite(r), r, -np.inf), axis=1)
    return [
        WorstFrame(
            f, float(frame_max[f]), int(np.nanargmax(np.where(np.isfinite(r[f]), r[f], -np.inf)))
        )
        for f in _largest_first(frame_max, count)
    ]


@dataclass(frozen=True)
class Jump:
    """A frame where the solved surface jumps: some vertex's second difference in time
    |v(t+1) - 2 v(t) + v(t-1)| (a one-frame excursion; a steady motion is none)."""

    frame: int
    """Index into the solve (its time code is `start + frame`)."""
    size: float
    """The largest vertex's jump (model units)."""
    vertex: int
    markers: list[str]
    """The given markers nearest that vertex at that frame, nearest first (none without the
    given markers)."""


_JUMP_BLOCK = 256
"""Frames read at once for the jumps (memory flat on a long take)."""

_JUMP_MARKERS = 3
"""Markers named beside each jump."""


def surface_jumps(solved: Result, count: int) -> list[Jump]:
    """The `count` frames where the solved surface jumps most, largest first."""
    v = solved.vertices
    nf = v.shape[0]
    size = np.zeros(nf)
    where = np.zeros(nf, dtype=np.int64)
    for a in range(1, nf - 1, _JUMP_BLOCK):
        b = min(nf - 1, a + _JUMP_BLOCK)
        block = np.asarray(v[a - 1 : b + 1], dtype=np.float64)
        jump = np.linalg.norm(block[2:] - 2.0 * block[1:-1] + block[:-2], axis=2)  # (n, V)
        where[a:b] = jump.argmax(axis=1)
        size[a:b] = jump.max(axis=1)
    out = []
    for f in _largest_first(np.where(size > 0, size, np.nan), count):
        near: list[str] = []
        if solved.markers is not None:
            d = np.linalg.norm(np.asarray(solved.markers[f], np.float64) - v[f, where[f]], axis=1)
            order = np.argsort(np.where(np.isfinite(d), d, np.inf))[:_JUMP_MARKERS]
            near = [solved.marker_names[k] for k in order if np.isfinite(d[k])]
        out.append(Jump(f, float(size[f]), int(where[f]), near))
    return out


@dataclass(frozen=True)
class Comparison:
    """Vertex distances between a solve and a reference of the same mesh and frames."""

    label: str
    per_frame_mean: F64
    """(F,) mean vertex distance per frame."""
    per_frame_max: F64
    per_vertex_mean: F64
    """(V,) mean distance of each vertex over the frames."""


def compare(solved: Result, reference: Result, label: str) -> Comparison:
    """Per-frame and per-vertex distances between two solves of one mesh over the same frames;
    `InputError` when the meshes or frame counts differ."""
    a, b = solved.vertices, reference.vertices
    if a.shape != b.shape:
        raise InputError(
            f"--compare {label}: {b.shape[0]} frames of {b.shape[1]} vertices, the solve has "
            f"{a.shape[0]} frames of {a.shape[1]} vertices; compare solves of the same mesh "
            "and frames"
        )
    if (solved.units or "") != (reference.units or ""):
        raise InputError(
            f"--compare {label}: its units are {reference.units or 'not given'}, the solve's "
            f"{solved.units or 'not given'}"
        )
    per_frame_mean = np.empty(a.shape[0])
    per_frame_max = np.empty(a.shape[0])
    per_vertex = np.zeros(a.shape[1])
    chunk = 64  # frames at a time: a 1,500-frame ICT take is 0.5 GB of float32 per solve
    for s in range(0, a.shape[0], chunk):
        d = np.linalg.norm(
            a[s : s + chunk].astype(np.float64) - b[s : s + chunk].astype(np.float64), axis=2
        )
        per_frame_mean[s : s + chunk] = d.mean(axis=1)
        per_frame_max[s : s + chunk] = d.max(axis=1)
        per_vertex += d.sum(axis=0)
    return Comparison(label, per_frame_mean, per_frame_max, per_vertex / max(a.shape[0], 1))


def _png(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=fig.dpi)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _figure(width: float, height: float) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _unit(units: str | None) -> str:
    return f" ({units})" if units else ""


def _face_size(solved: Result) -> float:
    """The first frame's bounding-box diagonal."""
    v = solved.vertices[0].astype(np.float64)
    return float(np.linalg.norm(v.max(axis=0) - v.min(axis=0))) or 1.0


def _heatmap(solved: Result, frames: F64) -> tuple[str, tuple[float, float, float, float]]:
    """Marker x frame residuals; missing samples in grey; the colour scale tops at the 99th
    percentile so one spike does not hide the rest (values above are drawn at the top)."""
    from matplotlib import colormaps
    from matplotlib.colors import Normalize

    r = _present(solved)
    finite = r[np.isfinite(r)]
    top = float(np.percentile(finite, 99)) if finite.size else 0.0
    # An exact solve's residuals are round-off (1e-15 cm): a scale floored at a millionth of
    # the face draws them black instead of as a noisy picture of nothing.
    top = max(top, 1e-6 * _face_size(solved))
    cmap = colormaps["magma"].with_extremes(bad="#9a9a9a")
    n = r.shape[1]
    fig = _figure(11, max(3.0, min(0.12 * n + 1.2, 16.0)))
    ax = fig.add_subplot()
    im = ax.imshow(
        r.T,
        aspect="auto",
        interpolation="nearest",
        cmap=cmap,
        norm=Normalize(0.0, top if top > 0 else 1.0),
        extent=(frames[0] - 0.5, frames[-1] + 0.5, n - 0.5, -0.5),
    )
    if n <= 150:
        ax.set_yticks(range(n), solved.marker_names, fontsize=max(4, min(8, 600 // max(n, 1))))
    ax.set_xlabel("time code (frame)")
    ax.set_ylabel("marker")
    ax.set_title("marker residual per frame (grey: missing)")
    cb = fig.colorbar(im, ax=ax, extend="max", pad=0.01)
    cb.set_label(f"residual{_unit(solved.units)}; top = 99th percentile")
    uri = _png(fig)
    # Where the cells are in the picture (after the layout ran): the page maps a click to them.
    x0, y0, w, h = ax.get_position().bounds
    return uri, (x0, 1.0 - y0 - h, w, h)


def _per_frame(solved: Result, frames: F64) -> str:
    r = _present(solved)
    fig = _figure(11, 3.4)
    ax = fig.add_subplot()
    with np.errstate(all="ignore"):
        ax.plot(frames, np.nanmedian(r, axis=1), lw=1, label="median over markers")
        ax.plot(frames, np.nanmax(r, axis=1), lw=1, label="largest marker")
    ax.set_xlabel("time code (frame)")
    ax.set_ylabel(f"residual{_unit(solved.units)}")
    ax2 = ax.twinx()
    ax2.plot(frames, solved.missing.sum(axis=1), lw=1, color="#888", label="missing markers")
    ax2.set_ylabel("missing markers (count)")
    lines = ax.get_lines() + ax2.get_lines()
    ax.legend(lines, [ln.get_label() for ln in lines], loc="upper right", fontsize=8)
    ax.set_title("residuals and dropouts per frame")
    return _png(fig)


def _jaw(solved: Result, frames: F64) -> str | None:
    if solved.jaw_theta is None:
        return None
    t = np.asarray(solved.jaw_theta, dtype=np.float64)
    fig = _figure(11, 3.0)
    ax = fig.add_subplot()
    ax.plot(frames, np.degrees(t[:, 0]), lw=1, label="open (degrees)")
    ax.plot(frames, np.degrees(t[:, 1]), lw=1, label="lateral (degrees)")
    ax.set_xlabel("time code (frame)")
    ax.set_ylabel("rotation (degrees)")
    ax2 = ax.twinx()
    ax2.plot(frames, t[:, 2], lw=1, color="#2a2", label=f"forward{_unit(solved.units)}")
    ax2.set_ylabel(f"forward translation{_unit(solved.units)}")
    lines = ax.get_lines() + ax2.get_lines()
    ax.legend(lines, [ln.get_label() for ln in lines], loc="upper right", fontsize=8)
    ax.set_title("jaw pose")
    return _png(fig)


def _comparison_figures(solved: Result, cmp: Comparison, frames: F64) -> tuple[str, str]:
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    from lgi.review.render import draw_mesh

    fig = _figure(11, 3.0)
    ax = fig.add_subplot()
    ax.plot(frames, cmp.per_frame_mean, lw=1, label="mean over vertices")
    ax.plot(frames, cmp.per_frame_max, lw=1, label="largest vertex")
    ax.set_xlabel("time code (frame)")
    ax.set_ylabel(f"distance{_unit(solved.units)}")
    ax.set_title(f"difference to {cmp.label} per frame")
    ax.legend(fontsize=8)
    per_frame = _png(fig)
    fig = _figure(7, 4.2)
    axes = fig.subplots(1, 2)
    top = float(np.percentile(cmp.per_vertex_mean, 99.5)) or 1.0
    norm, cmap = Normalize(0.0, top), colormaps["viridis"]
    rest = solved.vertices[0].astype(np.float64)
    tris = solved.topology.triangles()
    for ax, yaw in zip(axes, (0.0, 35.0), strict=True):
        draw_mesh(ax, rest, tris, cmp.per_vertex_mean, norm, cmap, yaw)
    cb = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=axes, extend="max", shrink=0.8)
    cb.set_label(f"mean distance over frames{_unit(solved.units)}")
    fig.suptitle(f"difference to {cmp.label} per vertex (drawn on the first frame)")
    return per_frame, _png(fig)


def _heatmap_tag(solved: Result, frames: F64, viewer_url: str | None) -> str:
    """The heatmap picture with what a click needs: the cells' box (fractions of the picture,
    from its top left), the time codes and the marker names; `_PICK_JS` reads them."""
    uri, (left, top, width, height) = _heatmap(solved, frames)
    names = html.escape(json.dumps(list(solved.marker_names)))
    return (
        f"<img id=heatmap alt='marker by frame residual heatmap' src='{uri}' "
        f"data-box='{left:.6f},{top:.6f},{width:.6f},{height:.6f}' "
        f"data-start='{solved.start}' data-frames='{len(frames)}' data-markers='{names}'"
        + (f" data-viewer='{html.escape(viewer_url)}'" if viewer_url else "")
        + " style='cursor:crosshair'>"
    )


_PICK_JS = """
<script>
const img = document.getElementById('heatmap');
if (img) img.addEventListener('click', (e) => {
  const r = img.getBoundingClientRect();
  const [l, t, w, h] = img.dataset.box.split(',').map(Number);
  const fx = ((e.clientX - r.left) / r.width - l) / w;
  const fy = ((e.clientY - r.top) / r.height - t) / h;
  if (fx < 0 || fx >= 1 || fy < 0 || fy >= 1) return;
  const names = JSON.parse(img.dataset.markers);
  const code = Number(img.dataset.start) + Math.floor(fx * Number(img.dataset.frames));
  const marker = names[Math.floor(fy * names.length)];
  document.getElementById('heat-pick').textContent = `${marker}, time code ${code}`;
  if (img.dataset.viewer) location.href = `${img.dataset.viewer}#frame=${code}`;
});
</script>
"""


def _seek_link(viewer_url: str | None, code: int) -> str:
    if viewer_url is None:
        return str(code)
    return f"<a href='{html.escape(viewer_url)}#frame={code}'>{code}</a>"


def _fmt(x: float, units: str | None) -> str:
    if not np.isfinite(x):
        return "-"
    return f"{x:.4g}{' ' + units if units else ''}"


_CSS = """
body{font-family:system-ui,sans-serif;margin:24px;max-width:1150px;color:#222}
table{border-collapse:collapse;margin:8px 0 18px}td,th{border:1px solid #ccc;padding:3px 8px;
text-align:right}th{background:#f2f2f2}td:first-child,th:first-child{text-align:left}
img{max-width:100%}h2{margin-top:28px;border-bottom:1px solid #ddd}.note{color:#555}
"""


def render_report(
    solved: Result,
    *,
    source: str,
    reference: Result | None = None,
    reference_label: str = "reference",
    take_noise: float | None = None,
    findings: Sequence[str] = (),
    viewer_url: str | None = None,
) -> str:
    """The report's HTML for `solved` (read from `source`); `reference` adds the difference
    sections; `take_noise` is the take's estimated marker noise (sigma per coordinate, model
    units); `findings` are lines about bad markers (label swaps, spikes) to list; with `viewer_url`
    (`lgi view`'s page), each worst frame links to the viewer at that frame."""
    nf, nb = solved.bundle_residuals.shape
    if nf == 0:
        raise InputError(f"{source}: the solved take has no frames")
    u = solved.units
    frames = solved.start + np.arange(nf, dtype=np.float64)
    stats = marker_stats(solved)
    r = _present(solved)
    present = r[np.isfinite(r)]
    med = float(np.median(present)) if present.size else float("nan")
    esc = html.escape
    rate = f"{solved.fps:g} frames per second" if solved.fps else "frame rate unknown"
    dur = f", {nf / solved.fps:.2f} s" if solved.fps else ""
    body: list[str] = [
        f"<h1>lgi report: {esc(os.path.basename(source))}</h1>",
        f"<p class=note>{esc(source)}</p>",
        "<table>",
        f"<tr><th>frames</th><td>{nf} (time codes {solved.start} to {solved.start + nf - 1}, "
        f"{rate}{dur})</td></tr>",
        f"<tr><th>mesh</th><td>{solved.vertices.shape[1]} vertices, "
        f"{solved.topology.num_faces} faces</td></tr>",
        f"<tr><th>markers</th><td>{nb}</td></tr>",
        f"<tr><th>units</th><td>{esc(u or 'not given')}</td></tr>",
        "<tr><th>solved with</th><td>"
        + esc(
            solved.settings.describe(u, solved.start)
            if solved.settings is not None
            else "not recorded (a file written before lgi kept it, or not by lgi solve)"
        )
        + "</td></tr>",
        f"<tr><th>missing samples</th><td>{int(solved.missing.sum())} of {nf * nb} "
        f"({100 * solved.missing.mean():.2f} %)</td></tr>",
        f"<tr><th>residual median / 95th percentile / max</th><td>{_fmt(med, u)} / "
        + (
            f"{_fmt(float(np.percentile(present, 95)), u)} / {_fmt(float(present.max()), u)}"
            if present.size
            else "- / -"
        )
        + "</td></tr>",
        "<tr><th>marker noise (sigma per coordinate)</th><td>"
        + (
            f"{_fmt(take_noise, u)} estimated from the take's frame-to-frame jitter"
            if take_noise is not None
            else "not estimated (give the take with --take)"
        )
        + (
            f"; the residuals' median implies {_fmt(med / _CHI3_MEDIAN, u)} if they were "
            "isotropic Gaussian noise"
            if np.isfinite(med) and med > 0
            else ""
        )
        + "</td></tr>",
        "</table>",
        "<h2>Findings</h2>",
    ]
    fixed = [] if solved.settings is None else solved.settings.repair_lines(solved.start)
    if fixed:
        body += [
            "<p>Repaired before the solve (the take file is untouched):</p>",
            "<ul class=repaired>",
            *(f"<li>{esc(line)}</li>" for line in fixed),
            "</ul>",
        ]
    if findings:
        body += ["<ul>", *(f"<li>{esc(f)}</li>" for f in findings), "</ul>"]
    else:
        body.append("<p>No markers were flagged.</p>")
    body += [
        "<h2>Residuals</h2>",
        "<p class=note>A marker's residual is its distance to the solved surface (with "
        "<code>--marker-noise</code>, the correction the solve applied to it).</p>",
        _heatmap_tag(solved, frames, viewer_url),
        "<p class=note id=heat-pick>Click a cell: its marker and time code"
        + (", and the viewer opens at that frame." if viewer_url else ".")
        + "</p>",
        f"<img alt='residuals per frame' src='{_per_frame(solved, frames)}'>",
    ]
    order = worst_markers(stats, WORST_SHOWN)
    body += [
        "<h2>Worst markers</h2>",
        "<p class=note>Ranked by their largest residual.</p>",
        f"<table><tr><th>marker</th><th>median{_unit(u)}</th><th>95th pct{_unit(u)}</th>"
        f"<th>max{_unit(u)}</th><th>at time code</th><th>missing</th>"
        "<th>longest gap (frames)</th></tr>",
    ]
    for b in order:
        wf = int(stats.worst_frame[b])
        body.append(
            f"<tr><td>{esc(stats.names[b])}</td><td>{_fmt(stats.median[b], None)}</td>"
            f"<td>{_fmt(stats.p95[b], None)}</td><td>{_fmt(stats.max[b], None)}</td>"
            f"<td>{'-' if wf < 0 else solved.start + wf}</td>"
            f"<td>{100 * stats.missing[b]:.1f} %</td><td>{stats.longest_gap[b]}</td></tr>"
        )
    body.append("</table>")
    body += [
        "<h2>Worst frames</h2>",
        f"<table><tr><th>time code</th><th>largest residual{_unit(u)}</th><th>marker</th>"
        "<th>missing markers</th></tr>",
    ]
    for w in worst_frames(solved, WORST_SHOWN):
        code = solved.start + w.frame
        body.append(
            f"<tr id='frame-{code}'><td>{_seek_link(viewer_url, code)}</td>"
            f"<td>{_fmt(w.residual, None)}</td><td>{esc(stats.names[w.marker])}</td>"
            f"<td>{int(solved.missing[w.frame].sum())}</td></tr>"
        )
    body.append("</table>")
    body += [
        "<h2>Where the surface jumps</h2>",
        "<p class=note>The frames where some vertex leaves the path of the frames either side "
        "most (its second difference in time): where to watch the take for a pop. Fast motion "
        "jumps too.</p>",
        f"<table><tr><th>time code</th><th>jump{_unit(u)}</th><th>vertex</th>"
        "<th>markers near it</th></tr>",
    ]
    for j in surface_jumps(solved, WORST_SHOWN):
        code = solved.start + j.frame
        body.append(
            f"<tr id='jump-{code}'><td>{_seek_link(viewer_url, code)}</td>"
            f"<td>{_fmt(j.size, None)}</td><td>{j.vertex}</td>"
            f"<td>{esc(', '.join(j.markers)) or '-'}</td></tr>"
        )
    body.append("</table>")
    jaw = _jaw(solved, frames)
    if jaw is not None:
        body += ["<h2>Jaw</h2>", f"<img alt='jaw pose over time' src='{jaw}'>"]
    if reference is not None:
        cmp = compare(solved, reference, reference_label)
        per_frame, per_vertex = _comparison_figures(solved, cmp, frames)
        body += [
            f"<h2>Difference to {esc(reference_label)}</h2>",
            f"<p>Mean vertex distance over all frames {_fmt(float(cmp.per_frame_mean.mean()), u)}"
            f"; largest {_fmt(float(cmp.per_frame_max.max()), u)} at time code "
            f"{solved.start + int(np.argmax(cmp.per_frame_max))}.</p>",
            f"<img alt='difference per frame' src='{per_frame}'>",
            f"<img alt='difference per vertex' src='{per_vertex}'>",
        ]
    return (
        "<!DOCTYPE html><html lang=en><head><meta charset=utf-8>"
        f"<title>lgi report: {esc(os.path.basename(source))}</title><style>{_CSS}</style>"
        "</head><body>" + "\n".join(body) + _PICK_JS + "</body></html>\n"
    )


USD_SUFFIXES = (".usd", ".usda", ".usdc")


def read_solved(path: str | os.PathLike[str]) -> Result:
    """A solved take from a `.npz` (`read_result_npz`) or a USD point cache `lgi solve` wrote
    (`lgi.io.usd.read_usd_cache`: no missing flags, no marker positions)."""
    if Path(path).suffix.lower() in USD_SUFFIXES:
        from lgi.io.usd import read_usd_cache

        return read_usd_cache(path)
    return read_result_npz(path)


def write_report(
    out: str | os.PathLike[str],
    solved_path: str | os.PathLike[str],
    *,
    reference_path: str | os.PathLike[str] | None = None,
    take_noise: float | None = None,
    findings: Sequence[str] = (),
) -> Path:
    """Reads a solved take (and a reference to compare with) and writes the report to `out`
    whole or not at all."""
    from concurrent.futures import ThreadPoolExecutor

    # Two compressed solves are mostly zlib time, which runs without the GIL: read side by side.
    with ThreadPoolExecutor(max_workers=2) as pool:
        solved_job = pool.submit(read_solved, solved_path)
        reference_job = None if reference_path is None else pool.submit(read_solved, reference_path)
        solved = solved_job.result()
        reference = None if reference_job is None else reference_job.result()
    from lgi.solve.diagnose import finding_lines

    found = finding_lines(solved)
    text = render_report(
        solved,
        source=os.fspath(solved_path),
        reference=reference,
        reference_label=os.path.basename(os.fspath(reference_path or "")),
        take_noise=take_noise,
        findings=[*found, *findings],
    )
    target = Path(out)
    with atomic_path(target) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return target
