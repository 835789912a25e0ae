"""Synthetic capture with real motion: the ground truth of the capture protocol.

Real ARKit curves (`lgi.io.livelink.read_livelinkface`) drive a dataset's shapes; the jaw's
rigid part is a true rotation about a hinge fitted from the dataset's jaw-open shape (a linear
rig moves the chin along a chord; a real jaw turns), the non-rigid rest of that shape stays
linear; markers are sampled on the result (`marker_samples`, as every protocol samples them),
with Gaussian noise and dropouts; and a fraction of the shapes can be held out from what the
methods see (the actor performs expressions nobody scanned). The meshes a linear rig produces
are not real scans: results on this truth say how methods cope with real motion curves, noise
and missing shapes, not with real skin.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

import lgi._lgi as _lgi
from lgi.data.dataset import Dataset, without_shapes
from lgi.errors import InputError
from lgi.lab.sample import dropout_mask
from lgi.solve.jaw import fit_rigid, rotation_axis_angle

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

__all__ = [
    "CaptureTake",
    "HingeJaw",
    "NonlinearTruth",
    "box_diagonal",
    "capture_truth",
    "departure",
    "make_capture",
    "marker_samples",
    "random_layout",
]


def box_diagonal(points: F64) -> float:
    """The bounding-box diagonal of `points` (N, 3): the size the protocols measure against."""
    return float(np.linalg.norm(np.ptp(points, axis=0)))


def _samples(dataset: Dataset, markers: ArrayLike, tolerance: float = 0.02) -> _lgi.RbfInterpolator:
    neutral = np.asarray(dataset.neutral)
    return _lgi.RbfInterpolator.from_dataset(
        dataset.core, markers, tolerance * box_diagonal(neutral)
    )


def _on_meshes(rbf: _lgi.RbfInterpolator, meshes: F64) -> F64:
    return np.einsum("fbjd,bj->fbd", meshes[:, rbf.sample_vertices], rbf.sample_weights)


def marker_samples(dataset: Dataset, markers: ArrayLike, meshes: ArrayLike) -> F64:
    """(F, B, 3) markers (rest positions `markers` (B, 3) on the neutral) on meshes (F, V, 3):
    barycentric on each marker's closest neutral triangle, as the protocols sample them."""
    return _on_meshes(_samples(dataset, markers), np.asarray(meshes, dtype=np.float64))


def _rotation(axis: F64, angle: float) -> F64:
    """Rodrigues: rotation by `angle` about the unit `axis`."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


@dataclass(frozen=True)
class HingeJaw:
    """A jaw-open shape split into a rotation about a hinge and a linear remainder:
    `s(v) = w(v) (R x0(v) + t - x0(v)) + r(v)`, with `R` the rotation by `angle` about `axis`
    through `pivot`."""

    shape: int
    """Index of the jaw-open shape in the dataset."""
    axis: F64
    """(3,) unit hinge axis."""
    angle: float
    """Opening of the shape (rad)."""
    pivot: F64
    """(3,) a point on the hinge."""
    weights: F64
    """(V,) how much of each vertex's motion is the jaw's rotation, 0..1."""
    remainder: F64
    """(V, 3) the shape's non-rigid rest."""

    @classmethod
    def fit(cls, dataset: Dataset, rigid: ArrayLike, shape: str = "jawOpen") -> HingeJaw:
        """Fits the hinge to the vertices `rigid` (indices of vertices the jaw carries rigidly,
        e.g. ICT's lower teeth) of the dataset's shape named `shape`."""
        if shape not in dataset.names:
            raise InputError(f"the dataset has no shape named {shape!r} to fit a jaw hinge to")
        k = dataset.names.index(shape)
        x0 = np.asarray(dataset.neutral, dtype=np.float64)
        s = np.asarray(dataset.shapes[k], dtype=np.float64)
        idx = np.asarray(rigid, dtype=np.int64)
        if idx.ndim != 1 or idx.size < 3 or idx.min() < 0 or idx.max() >= x0.shape[0]:
            raise InputError("rigid: expected at least 3 vertex indices of the neutral")
        r, t = fit_rigid(x0[idx], x0[idx] + s[idx])
        axis, angle = rotation_axis_angle(r)
        # The pivot: the point on the axis that the motion moves least ((I - R) p = t in the
        # plane normal to the axis, least squares).
        pivot = np.linalg.lstsq(np.eye(3) - r, t - axis * (axis @ t), rcond=None)[0]
        pivot = pivot - axis * (axis @ (pivot - x0[idx].mean(axis=0)))
        rigid_motion = x0 @ r.T + t - x0
        n2 = np.einsum("vd,vd->v", rigid_motion, rigid_motion)
        w = np.where(n2 > 1e-12, np.einsum("vd,vd->v", s, rigid_motion) / np.maximum(n2, 1e-300), 0)
        w = np.clip(w, 0.0, 1.0)
        return cls(
            shape=k,
            axis=axis,
            angle=float(angle),
            pivot=pivot,
            weights=w,
            remainder=s - w[:, None] * rigid_motion,
        )


def capture_truth(dataset: Dataset, weights: ArrayLike, jaw: HingeJaw | None) -> F64:
    """(F, V, 3) meshes for shape weights (F, S): linear in every shape but the jaw's rotation,
    which turns each vertex by its weight's share of the jaw-open weight times the hinge angle,
    about the hinge, after the linear part."""
    w = np.asarray(weights, dtype=np.float64)
    if w.ndim != 2 or w.shape[1] != dataset.num_shapes:
        raise InputError(f"weights: expected shape (F, {dataset.num_shapes}), got {w.shape}")
    x0 = np.asarray(dataset.neutral, dtype=np.float64)
    shapes = np.asarray(dataset.shapes)
    lin = w.copy()
    if jaw is not None:
        lin[:, jaw.shape] = 0.0
    out = x0[None] + np.einsum("fk,kvd->fvd", lin, shapes, optimize=True)
    if jaw is None:
        return out
    for f in range(w.shape[0]):
        a = w[f, jaw.shape]
        if a == 0.0:
            continue
        x = out[f] + a * jaw.remainder
        turned = (x - jaw.pivot) @ _rotation(jaw.axis, a * jaw.angle).T + jaw.pivot
        out[f] = x + jaw.weights[:, None] * (turned - x)
    return out


class NonlinearTruth:
    """A truth that does not combine linearly: each frame blends the shapes' per-triangle
    deformation gradients, rotations in the log and stretches linearly (`lgi.data.deform.blend`,
    the ARAP in-betweens' rule, `lgi.data.augment`), and a Poisson solve on the neutral turns them
    into positions, holding the vertices no shape moves and placing parts without such
    vertices (the lower teeth, the eyes) at the linear blend's centroid. A rotating part
    keeps its size where the linear sum shrinks it, and simultaneous shapes compose their
    rotations instead of adding their displacements; the jaw turns through its shape's
    rotations (no separate hinge). `departure` says how far it is from the linear rig."""

    def __init__(self, dataset: Dataset) -> None:
        from lgi.data.augment import still_vertices
        from lgi.data.deform import PoissonMesh, Polar

        self.neutral = np.asarray(dataset.neutral, dtype=np.float64)
        self.shapes = np.asarray(dataset.shapes)
        self._mesh = PoissonMesh(self.neutral, dataset.triangles, still_vertices(dataset.core))
        self._polars = [
            Polar(self._mesh.gradients(self.neutral + k.astype(np.float64))) for k in self.shapes
        ]

    @property
    def num_shapes(self) -> int:
        return int(self.shapes.shape[0])

    def linear(self, weights: ArrayLike) -> F64:
        """(F, V, 3) the linear rig's meshes for weights (F, S)."""
        w = self._weights(weights)
        return self.neutral[None] + np.einsum("fk,kvd->fvd", w, self.shapes, optimize=True)

    def meshes(self, weights: ArrayLike) -> F64:
        """(F, V, 3) the nonlinear truth's meshes for weights (F, S)."""
        from lgi.data.deform import blend

        w = self._weights(weights)
        lin = self.linear(w)
        out = np.empty_like(lin)
        for f in range(w.shape[0]):
            terms = [(self._polars[k], float(w[f, k])) for k in np.flatnonzero(w[f])]
            if not terms:
                out[f] = self.neutral
                continue
            out[f] = self._mesh.solve(blend(terms), lin[f])
        return out

    def _weights(self, weights: ArrayLike) -> F64:
        w = np.asarray(weights, dtype=np.float64)
        if w.ndim != 2 or w.shape[1] != self.num_shapes or not np.isfinite(w).all():
            raise InputError(f"weights: expected finite (F, {self.num_shapes}), got {w.shape}")
        return w


def departure(truth: ArrayLike, linear: ArrayLike, region: ArrayLike | None = None) -> float:
    """Mean distance between a truth's meshes and the linear rig's (F, V, 3) over `region`."""
    idx = slice(None) if region is None else np.asarray(region)
    t, lin = np.asarray(truth), np.asarray(linear)
    return float(np.linalg.norm(t[:, idx] - lin[:, idx], axis=2).mean())


def random_layout(dataset: Dataset, count: int, seed: int, vertices: ArrayLike) -> F64:
    """(count, 3) marker rest positions spread over the triangles whose corners all lie in
    `vertices`: farthest-point sampling from area-weighted random surface points, like a
    marker artist spacing dots evenly."""
    if count < 4:
        raise InputError(f"count must be >= 4 markers, got {count}")
    rng = np.random.default_rng(seed)
    x0 = np.asarray(dataset.neutral, dtype=np.float64)
    tri = np.asarray(dataset.triangles, dtype=np.int64)
    inside = np.zeros(x0.shape[0], dtype=bool)
    inside[np.asarray(vertices, dtype=np.int64)] = True
    tri = tri[inside[tri].all(axis=1)]
    if tri.shape[0] == 0:
        raise InputError("vertices: no triangle lies inside the given vertices")
    a, b, c = x0[tri[:, 0]], x0[tri[:, 1]], x0[tri[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    n = 30 * count
    pick = rng.choice(tri.shape[0], size=n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    cand = a[pick] + u[:, None] * (b[pick] - a[pick]) + v[:, None] * (c[pick] - a[pick])
    chosen = [int(rng.integers(n))]
    dist = np.linalg.norm(cand - cand[chosen[0]], axis=1)
    for _ in range(count - 1):
        j = int(np.argmax(dist))
        chosen.append(j)
        dist = np.minimum(dist, np.linalg.norm(cand - cand[j], axis=1))
    return cand[chosen]


@dataclass(frozen=True)
class CaptureTake:
    """One capture-protocol take."""

    frames: F64
    """(F, B, 3) markers: truth + noise, NaN rows where dropped."""
    truth: F64
    """(F, V, 3) the meshes the markers were sampled on."""
    weights: F64
    """(F, S) the shape weights that made each frame (full dataset)."""
    dataset: Dataset
    """What the methods may use: the dataset without the held-out shapes."""
    held_out: list[str]
    """Names of the shapes the methods do not see."""
    jaw_open: NDArray[np.bool_]
    """(F,) frames whose jaw-open weight is at least 0.3."""


def make_capture(
    dataset: Dataset,
    weights: ArrayLike,
    markers: ArrayLike,
    *,
    sigma: float,
    dropout: float,
    holdout: float,
    seed: int,
    jaw: HingeJaw | None,
    keep: Sequence[str] = ("jawOpen",),
    nonlinear: NonlinearTruth | None = None,
) -> CaptureTake:
    """A capture take from shape weights (F, S) on `dataset` with markers at rest `markers`
    (B, 3): Gaussian noise of `sigma` (data units) per coordinate, a `dropout` fraction of
    marker samples lost in runs of 2 to 8 frames, and a `holdout` fraction of the shapes (never
    those named in `keep`) removed from the dataset the methods get. Seeded: the same
    arguments give the same take. With `nonlinear` the truth is its meshes (the jaw turning
    through its shape's rotations) instead of `capture_truth`'s."""
    if not (np.isfinite(sigma) and sigma >= 0):
        raise InputError(f"sigma must be >= 0, got {sigma}")
    if not (0 <= dropout < 1 and 0 <= holdout < 1):
        raise InputError(f"dropout and holdout must be in [0, 1), got {dropout}, {holdout}")
    rng = np.random.default_rng(seed)
    w = np.asarray(weights, dtype=np.float64)
    truth = nonlinear.meshes(w) if nonlinear is not None else capture_truth(dataset, w, jaw)
    frames = marker_samples(dataset, markers, truth)
    frames = frames + rng.normal(0.0, sigma, size=frames.shape)
    frames[dropout_mask(frames.shape[0], frames.shape[1], dropout, rng)] = np.nan
    names = list(dataset.names)
    candidates = [i for i, n in enumerate(names) if n not in keep]
    drop = sorted(
        int(i) for i in rng.choice(candidates, size=round(holdout * len(names)), replace=False)
    )
    open_col = names.index("jawOpen") if "jawOpen" in names else None
    jaw_open = w[:, open_col] >= 0.3 if open_col is not None else np.zeros(w.shape[0], dtype=bool)
    return CaptureTake(
        frames=frames,
        truth=truth,
        weights=w,
        dataset=without_shapes(dataset, drop) if drop else dataset,
        held_out=[names[i] for i in drop],
        jaw_open=jaw_open,
    )
