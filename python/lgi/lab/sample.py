"""The shipped sample: a synthetic face, its expression shapes, a marker layout and a performance.

Everything is generated from a seed by this module and the face it is made on
(`lgi.lab.face`; no external data), so `lgi demo` and the tests always have a dataset with holes
(mouth, eyes), real jaw rotation and expression-only folds. This module adds the markers, the
performance and its ground truth, and the sample as an `lgi.Dataset` (`sample_dataset`).

Conventions: centimetres, +y up, +z forward (like ICT). "Left" is the character's left, +x.

How the ground truth of the performance is made (per frame f, weights w = truth_weights[f]):

    theta_f   = sum over jaw shapes k of  w_k * shape_jaw_theta[k]
    pre_f     = neutral + sum over non-jaw k of ( w_k * (shapes[k] - wrinkles[k])
                                                  + w_k ** 1.5 * wrinkles[k] )
    truth[f]  = pre_f + jaw_weights * (T(theta_f)(pre_f) - pre_f)      (jaw skinning, LBS)

with T(theta)(p) = R_y(theta[1]) @ R_x(theta[0]) @ (p - jaw_pivot) + jaw_pivot + (0, 0, theta[2]),
computed by the core's skinning (`lgi.solve.jaw.JawRig.skin` with the identity frame).
`shapes` and `wrinkles` enter promoted from their float32 storage, so the truth is reproducible
from the saved arrays. The jaw shapes themselves are `T(shape_jaw_theta[k])` applied with full
LBS to the neutral: a weight of 1 reproduces the shape, a weight of 0.5 is a rotation by half the
angle (not half the displacement), and the fine folds (`wrinkles`) grow like w**1.5, so no frame
is in the linear span of the shapes.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

import lgi._lgi as _lgi
from lgi.data.dataset import Dataset
from lgi.errors import DatasetError, DatasetFileError, InputError
from lgi.io.atomic import atomic_path
from lgi.lab.face import (
    EYE_A,
    EYE_B,
    EYE_CX,
    EYE_CY,
    HALF_HEIGHT,
    HALF_WIDTH,
    JAW_PIVOT,
    JAW_SHAPES,
    MOUTH_Y,
    Face,
    build_face,
    expression_fields,
    lowerness,
)
from lgi.solve.jaw import JawRig

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

__all__ = [
    "Sample",
    "describe",
    "dropout_mask",
    "load_sample",
    "make_sample",
    "sample_dataset",
    "save_sample",
]

_WRINKLE_POWER = 1.5
_MIN_RESOLUTION = 40
# About 0.83 r^2 vertices: 800 rows are ~530,000 vertices, beyond any test or demo.
_MAX_RESOLUTION = 800


@dataclass(frozen=True, eq=False, repr=False)
class Sample:
    """A complete synthetic capture: dataset, markers, performance and its ground truth.

    See the module documentation for exactly how `truth` is made from `truth_weights`.
    """

    neutral: F64
    """(V, 3) neutral vertex positions, cm, +y up, +z forward."""
    triangles: I64
    """(T, 3) vertex indices, counter-clockwise seen from the front (+z)."""
    uvs: F64
    """(U, 2) texture coordinates: a planar projection of the face (one chart)."""
    uv_triangles: I64
    """(T, 3) uv indices per triangle corner (equal to `triangles`: one uv per vertex)."""
    shapes: NDArray[np.float32]
    """(S, V, 3) displacements of each expression shape from the neutral."""
    names: list[str]
    """S ARKit-style shape names."""
    markers_rest: F64
    """(B, 3) marker positions on the neutral surface."""
    marker_names: list[str]
    """B marker names."""
    performance: F64
    """(F, B, 3) captured marker positions: truth + Gaussian noise, NaN rows where dropped."""
    truth: F64
    """(F, V, 3) ground-truth meshes of the performance (no noise)."""
    truth_weights: F64
    """(F, S) shape weights that made each frame (jaw shapes act through `jaw_theta`)."""
    jaw_theta: F64
    """(F, 3) true jaw parameters per frame: open angle (rad), lateral angle (rad), forward (cm)."""
    jaw_pivot: F64
    """(3,) centre of the jaw rotation."""
    jaw_weights: F64
    """(V,) jaw skinning weight of each vertex in [0, 1] (1 on chin and lower lip)."""
    shape_jaw_theta: F64
    """(S, 3) jaw parameters of each shape (zero for shapes that are not jaw shapes)."""
    seed: int
    """The seed the sample was made from."""
    marker_triangles: I64
    """(B,) triangle of the neutral each marker was placed on."""
    marker_barycentrics: F64
    """(B, 3) barycentric coordinates of each marker in its triangle."""
    wrinkles: NDArray[np.float32]
    """(S, V, 3) the fine-fold part of each shape (included in `shapes`), grows like w**1.5."""

    def __repr__(self) -> str:
        return (
            f"Sample(seed={self.seed}, vertices={self.num_vertices}, shapes={self.num_shapes}, "
            f"markers={self.num_markers}, frames={self.num_frames})"
        )

    @property
    def num_vertices(self) -> int:
        """Number of vertices V."""
        return int(self.neutral.shape[0])

    @property
    def num_shapes(self) -> int:
        """Number of expression shapes S."""
        return int(self.shapes.shape[0])

    @property
    def num_markers(self) -> int:
        """Number of markers B."""
        return int(self.markers_rest.shape[0])

    @property
    def num_frames(self) -> int:
        """Number of performance frames F."""
        return int(self.performance.shape[0])


# --------------------------------------------------------------------------------------------
# Markers.


def _marker_layout() -> tuple[list[str], F64]:
    """About 100 named marker positions (x, y) on the face, designed off the holes."""
    ym = MOUTH_Y
    ex, ey, ea, eb = EYE_CX, EYE_CY, EYE_A, EYE_B
    # fmt: off
    centre: list[tuple[str, float, float]] = [
        ("foreheadC1", 0.0, 7.2), ("foreheadC2", 0.0, 6.3), ("foreheadC3", 0.0, 5.4),
        ("glabella", 0.0, 3.95), ("noseBridge", 0.0, 2.5), ("noseRidge", 0.0, 1.3),
        ("noseTip", 0.0, -0.3), ("philtrum", 0.0, ym + 0.95), ("upperLipC", 0.0, ym + 0.25),
        ("lowerLipC", 0.0, ym - 0.3), ("lowerLipBelowC", 0.0, ym - 1.0),
        ("chinTop", 0.0, -5.4), ("chinC", 0.0, -6.6), ("chinBottom", 0.0, -7.5),
    ]
    sided: list[tuple[str, float, float]] = [
        ("forehead1", 1.8, 7.2), ("forehead2", 3.6, 7.2), ("forehead3", 1.8, 6.3),
        ("forehead4", 3.6, 6.3), ("forehead5", 5.2, 6.0), ("forehead6", 1.8, 5.4),
        ("forehead7", 3.6, 5.4),
        ("brow1", 0.9, 4.2), ("brow2", 2.0, 4.35), ("brow3", 3.1, 4.45), ("brow4", 4.2, 4.35),
        ("lidUpper", ex, ey + eb + 0.35), ("lidLower", ex, ey - eb - 0.35),
        ("eyeInner", ex - ea - 0.35, ey), ("eyeOuter", ex + ea + 0.35, ey),
        ("crowsFoot1", ex + ea + 1.0, ey + 0.3), ("crowsFoot2", ex + ea + 0.9, ey - 0.6),
        ("lidLowerInner", ex - 0.8, ey - eb - 0.5), ("lidLowerOuter", ex + 0.8, ey - eb - 0.5),
        ("noseSide", 0.9, 0.8), ("nostril", 1.1, -0.9),
        ("cheek1", 2.8, 0.6), ("cheek2", 4.2, 0.8), ("cheek3", 5.6, 1.2), ("cheek4", 3.6, -0.9),
        ("cheek5", 5.0, -0.6), ("cheek6", 6.3, -0.3), ("cheek7", 3.4, -2.4),
        ("cheek8", 4.6, -2.4), ("cheek9", 5.9, -2.2),
        ("nasolabial1", 2.0, -1.9), ("nasolabial2", 2.6, -3.0),
        ("upperLip1", 0.8, ym + 0.25), ("upperLip2", 1.6, ym + 0.22),
        ("upperLipTop", 1.0, ym + 0.9),
        ("mouthCorner", 2.65, ym),
        ("lowerLip1", 0.8, ym - 0.3), ("lowerLip2", 1.6, ym - 0.28),
        ("lowerLipBelow", 1.2, ym - 1.0),
        ("chin1", 1.3, -5.6), ("chin2", 1.6, -6.9),
        ("jaw1", 3.6, -5.2), ("jaw2", 5.0, -4.4), ("jaw3", 6.3, -3.6), ("jaw4", 4.3, -6.6),
        ("jaw5", 3.0, -7.4),
    ]
    # fmt: on
    names = [n for n, _, _ in centre]
    pts = [(x, y) for _, x, y in centre]
    for name, x, y in sided:
        names += [name + "_L", name + "_R"]
        pts += [(x, y), (-x, y)]
    return names, np.array(pts, dtype=np.float64)


def _locate_2d(points: F64, positions: F64, triangles: I64) -> tuple[I64, F64]:
    """Triangle and barycentrics of each (x, y) point in the height field's xy projection.

    Returns triangle -1 for a point over a hole or outside the patch.
    """
    a = positions[triangles[:, 0], :2]
    b = positions[triangles[:, 1], :2]
    c = positions[triangles[:, 2], :2]
    e1, e2 = b - a, c - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    tri = np.full(points.shape[0], -1, dtype=np.int64)
    bary = np.zeros((points.shape[0], 3))
    for i, p in enumerate(points):
        r = p - a
        l1 = (r[:, 0] * e2[:, 1] - r[:, 1] * e2[:, 0]) / det
        l2 = (e1[:, 0] * r[:, 1] - e1[:, 1] * r[:, 0]) / det
        l0 = 1.0 - l1 - l2
        inside = np.nonzero((l0 >= 0) & (l1 >= 0) & (l2 >= 0))[0]
        if inside.size:
            t = int(inside[0])
            tri[i] = t
            bary[i] = (l0[t], l1[t], l2[t])
    return tri, bary


def _place_markers(face: Face, rng: np.random.Generator) -> tuple[list[str], I64, F64]:
    names, pts = _marker_layout()
    jitter = np.clip(rng.normal(0.0, 0.04, pts.shape), -0.08, 0.08)
    tri, bary = _locate_2d(pts + jitter, face.positions, face.triangles)
    missing = tri < 0
    if missing.any():  # a jitter that fell off the surface: use the designed position
        tri_m, bary_m = _locate_2d(pts[missing], face.positions, face.triangles)
        tri[missing], bary[missing] = tri_m, bary_m
    if (tri < 0).any():
        raise AssertionError("marker layout has a point off the face")  # a bug, not user input
    return names, tri, bary


# --------------------------------------------------------------------------------------------
# Performance.


def _weight_curves(names: list[str], num_frames: int, rng: np.random.Generator) -> F64:
    """Smooth, sparse shape-weight curves: sums of sin^2 pulses, rest pose for 4 frames."""
    s = len(names)
    w = np.zeros((num_frames, s))
    index = {n: k for k, n in enumerate(names)}
    frames = np.arange(num_frames, dtype=np.float64)
    first = 4

    def pulse(k: int, start: float, duration: float, amp: float) -> None:
        t = (frames - start) / duration
        w[:, k] += amp * np.where((t > 0) & (t < 1), np.sin(np.pi * t) ** 2, 0.0)

    def random_start(duration: float) -> float:
        return float(rng.uniform(first, max(first, num_frames - duration)))

    # One full jaw opening (25 degrees) mid-performance, other openings at random.
    duration = min(30.0, max(num_frames - first - 1.0, 2.0))
    peak_start = min(0.6 * num_frames, num_frames - 1.0) - duration / 2.0
    pulse(index["jawOpen"], max(peak_start, float(first)), duration, 1.0)
    for _ in range(max(1, num_frames // 50)):
        d = float(rng.uniform(15, 40))
        pulse(index["jawOpen"], random_start(d), d, float(rng.uniform(0.2, 0.7)))
    for name in ("jawLeft", "jawRight", "jawForward"):
        if rng.uniform() < 0.8:
            d = float(rng.uniform(20, 45))
            pulse(index[name], random_start(d), d, float(rng.uniform(0.3, 0.8)))
    others = [k for k, n in enumerate(names) if n not in JAW_SHAPES]
    for _ in range(max(1, num_frames // 8)):
        k = int(rng.choice(others))
        d = float(rng.uniform(15, 45))
        start = random_start(d)
        amp = float(rng.uniform(0.3, 1.0))
        pulse(k, start, d, amp)
        name = names[k]
        mirror = (
            name[:-4] + "Right"
            if name.endswith("Left")
            else name[:-5] + "Left"
            if name.endswith("Right")
            else None
        )
        if mirror is not None and mirror in index and rng.uniform() < 0.5:
            pulse(index[mirror], start + rng.uniform(-2, 2), d, amp * float(rng.uniform(0.6, 1)))
    w[:first] = 0.0
    return np.clip(w, 0.0, 1.0)


def dropout_mask(
    num_frames: int, num_markers: int, fraction: float, rng: np.random.Generator
) -> NDArray[np.bool_]:
    """(F, B) mask of lost markers, in runs of 2 to 8 frames; frame 0 is always complete."""
    mask = np.zeros((num_frames, num_markers), dtype=bool)
    target = round(fraction * num_frames * num_markers)
    if num_frames < 2 or target <= 0:
        return mask
    while int(mask.sum()) < target:
        b = int(rng.integers(num_markers))
        length = int(rng.integers(2, 9))
        start = int(rng.integers(1, num_frames))
        mask[start : start + length, b] = True
    return mask


def _truth(
    neutral: F64,
    shapes: F64,
    wrinkles: F64,
    weights: F64,
    jaw: NDArray[np.bool_],
    shape_theta: F64,
    pivot: F64,
    jaw_weights: F64,
) -> tuple[F64, F64]:
    """Ground-truth meshes (F, V, 3) and jaw parameters (F, 3); see the module documentation."""
    f, v = weights.shape[0], neutral.shape[0]
    wn = weights[:, ~jaw]
    smooth = (shapes[~jaw] - wrinkles[~jaw]).reshape(-1, v * 3)
    detail = wrinkles[~jaw].reshape(-1, v * 3)
    pre = neutral.reshape(1, -1) + wn @ smooth + (wn**_WRINKLE_POWER) @ detail
    pre = pre.reshape(f, v, 3)
    theta = weights[:, jaw] @ shape_theta[jaw]
    return JawRig(pivot, jaw_weights).skin(pre, theta), theta


# --------------------------------------------------------------------------------------------
# Public API.


def make_sample(
    seed: int = 0,
    resolution: int = 120,
    num_frames: int = 150,
    noise_mm: float = 0.2,
    dropout: float = 0.02,
) -> Sample:
    """Generate the sample deterministically from `seed`.

    `resolution` is the number of vertex rows over the 16 cm of the face (default 120: about
    12,000 vertices); `noise_mm` the standard deviation of the marker noise per coordinate in
    millimetres; `dropout` the fraction of (frame, marker) entries lost (NaN), in short runs.
    """
    resolution = _lgi.check_count(resolution, "resolution")
    if not _MIN_RESOLUTION <= resolution <= _MAX_RESOLUTION:
        raise InputError(
            f"resolution must be an integer from {_MIN_RESOLUTION} to {_MAX_RESOLUTION}, "
            f"got {resolution}"
        )
    if int(num_frames) != num_frames or num_frames < 1:
        raise InputError(f"num_frames must be a positive integer, got {num_frames}")
    if not np.isfinite(noise_mm) or noise_mm < 0:
        raise InputError(f"noise_mm must be finite and >= 0, got {noise_mm}")
    if not np.isfinite(dropout) or not 0 <= dropout < 0.5:
        raise InputError(f"dropout must be in [0, 0.5), got {dropout}")
    rng = np.random.default_rng(seed)
    face = build_face(int(resolution))
    neutral = face.positions
    pivot = np.array(JAW_PIVOT)
    jaw_weights = lowerness(face, growth=1.0, rise=2.0, corner=1.6, cap=2.0)

    expr_names, fields = expression_fields(face)
    names = list(JAW_SHAPES) + expr_names
    s, v = len(names), neutral.shape[0]
    shapes = np.zeros((s, v, 3), dtype=np.float32)
    wrinkles = np.zeros((s, v, 3), dtype=np.float32)
    shape_theta = np.zeros((s, 3))
    rig = JawRig(pivot, jaw_weights)
    for k, params in enumerate(JAW_SHAPES.values()):
        shape_theta[k] = params
        shapes[k] = rig.skin(neutral, shape_theta[k]) - neutral
    for k, (smooth, detail) in enumerate(fields, start=len(JAW_SHAPES)):
        shapes[k] = smooth + detail
        wrinkles[k] = detail
    jaw = np.zeros(s, dtype=bool)
    jaw[: len(JAW_SHAPES)] = True

    marker_names, marker_tri, marker_bary = _place_markers(face, rng)
    corners = face.triangles[marker_tri]
    markers_rest = np.einsum("bc,bcd->bd", marker_bary, neutral[corners])

    weights = _weight_curves(names, int(num_frames), rng)
    truth, theta = _truth(
        neutral,
        shapes.astype(np.float64),
        wrinkles.astype(np.float64),
        weights,
        jaw,
        shape_theta,
        pivot,
        jaw_weights,
    )
    clean = np.einsum("bc,fbcd->fbd", marker_bary, truth[:, corners])
    performance = clean + rng.normal(0.0, noise_mm / 10.0, clean.shape)
    lost = dropout_mask(int(num_frames), len(marker_names), dropout, rng)
    performance[lost] = np.nan

    uvs = np.stack(
        [
            (neutral[:, 0] + HALF_WIDTH) / (2 * HALF_WIDTH),
            (neutral[:, 1] + HALF_HEIGHT) / (2 * HALF_HEIGHT),
        ],
        axis=1,
    )
    return Sample(
        neutral=neutral,
        triangles=face.triangles,
        uvs=uvs,
        uv_triangles=face.triangles.copy(),
        shapes=shapes,
        names=names,
        markers_rest=markers_rest,
        marker_names=marker_names,
        performance=performance,
        truth=truth,
        truth_weights=weights,
        jaw_theta=theta,
        jaw_pivot=pivot,
        jaw_weights=jaw_weights,
        shape_jaw_theta=shape_theta,
        seed=int(seed),
        marker_triangles=marker_tri,
        marker_barycentrics=marker_bary,
        wrinkles=wrinkles,
    )


_ARRAY_FIELDS = (
    "neutral",
    "triangles",
    "uvs",
    "uv_triangles",
    "shapes",
    "markers_rest",
    "performance",
    "truth",
    "truth_weights",
    "jaw_theta",
    "jaw_pivot",
    "jaw_weights",
    "shape_jaw_theta",
    "marker_triangles",
    "marker_barycentrics",
    "wrinkles",
)
_FORMAT = "lgi-sample-1"


def save_sample(sample: Sample, path: str | Path) -> None:
    """Write the sample to a compressed `.npz` (no pickled objects)."""
    payload: dict[str, Any] = {name: np.asarray(getattr(sample, name)) for name in _ARRAY_FIELDS}
    payload["format"] = np.array(_FORMAT)
    payload["names"] = np.array(sample.names, dtype=np.str_)
    payload["marker_names"] = np.array(sample.marker_names, dtype=np.str_)
    payload["seed"] = np.array(sample.seed, dtype=np.int64)
    target = Path(path)
    if target.suffix != ".npz":  # numpy's own rule for a file name without the suffix
        target = target.with_name(target.name + ".npz")
    with atomic_path(target) as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, **payload)


def load_sample(path: str | Path) -> Sample:
    """Read a sample written by `save_sample`."""
    p = Path(path)
    try:
        z = np.load(p, allow_pickle=False)
    except FileNotFoundError as e:
        raise DatasetFileError(f"{p}: sample file not found") from e
    except (OSError, ValueError) as e:
        raise DatasetError(f"{p}: not a readable .npz sample ({e})") from e
    with z:
        wanted = (*_ARRAY_FIELDS, "format", "names", "marker_names", "seed")
        missing = [k for k in wanted if k not in z.files]
        if missing:
            raise DatasetError(f"{p}: not an lgi sample, missing {', '.join(missing)}")
        if str(z["format"]) != _FORMAT:
            raise DatasetError(f"{p}: unsupported sample format {str(z['format'])!r}")
        arrays = {name: z[name] for name in _ARRAY_FIELDS}
        return Sample(
            names=[str(n) for n in z["names"]],
            marker_names=[str(n) for n in z["marker_names"]],
            seed=int(z["seed"]),
            **arrays,
        )


def describe(sample: Sample) -> str:
    """A short multi-line summary of the sample."""
    lo, hi = sample.neutral.min(axis=0), sample.neutral.max(axis=0)
    size = hi - lo
    lost = np.isnan(sample.performance).any(axis=2)
    open_deg = np.rad2deg(sample.jaw_theta[:, 0].max()) if sample.num_frames else 0.0
    return "\n".join(
        [
            f"lgi sample (seed {sample.seed})",
            f"  vertices   {sample.num_vertices}",
            f"  triangles  {sample.triangles.shape[0]}",
            f"  shapes     {sample.num_shapes}",
            f"  markers    {sample.num_markers}",
            f"  frames     {sample.num_frames} (jaw opens up to {open_deg:.1f} deg)",
            f"  dropouts   {int(lost.sum())} of {lost.size} marker samples "
            f"({100.0 * lost.mean():.1f}%)"
            if lost.size
            else "  dropouts   0",
            f"  size       {size[0]:.1f} x {size[1]:.1f} x {size[2]:.1f} cm (w x h x d)",
        ]
    )


def sample_dataset(sample: Sample) -> Dataset:
    """The dataset of a generated sample (`make_sample`): neutral, UVs and shapes."""
    return Dataset.from_arrays(
        sample.neutral,
        sample.triangles,
        sample.shapes,
        names=sample.names,
        uvs=sample.uvs,
        uv_triangles=sample.uv_triangles,
    )
