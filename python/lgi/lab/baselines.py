"""Baselines for evaluating LGI, with the same `solve(frames) -> SolveResult` API as `lgi.Model`.

- `DisplacementInterpolation`: marker displacements from rest spread over the mesh by a 3D
  biharmonic RBF (phi(r) = r plus a linear polynomial). Chosen because it is the simplest smooth
  interpolant that is exact at the markers and reproduces rigid/affine motion, and it is the
  standard "marker-driven deformation" baseline (as in Bhat et al. 2013-style pipelines before a
  learned or example-based correction). Linear in the data, so the V x B matrix is computed once.
- `BlendshapeFit`: per frame, box-penalised least-squares blendshape weights (the standard
  production solve), solved exactly by an active-set iteration in the Rust core.
- `FitJaw`: the same fit with the jaw as a joint (lgi's own weights and jaw pose, the blend of
  jaw-unskinned shapes skinned by the pose): the peer a production rig solve gives, differing
  from LGI only in the local geometry.
- `FitJawResidual`: `FitJaw` plus a smoothing thin-plate spline of its marker residuals, the
  smoothing chosen per take by leaving markers out (the production method before LGI).
- `LgiRbf`: LGI's per-bundle local geometry choices spread with normalised Gaussian weights over
  UV distance (no Sibson sewing), plus an RBF correction of the residuals so every marker is
  interpolated: isolates what LGI's sewing contributes.

Each baseline has one name: the class name here, with `label` the name in result tables (and
`lgi.lab.evaluate`'s method keys). The Rust kernels behind them are named for what they compute
(`RbfInterpolator`, `BlendshapeSolver`, in `lgi_core::baselines` and `lgi._lgi` alike).

Every result's `Choices` holds -1 shapes and 0 weights where the method has no choice
(`DisplacementInterpolation`, `BlendshapeFit`, `FitJaw`); `LgiRbf` reports LGI's choices.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

import lgi._lgi as _lgi
from lgi._lgi import BuildConfig, Choices, SolveResult
from lgi.data.dataset import Dataset
from lgi.errors import InputError
from lgi.solve.model import Model

F64 = NDArray[np.float64]

__all__ = [
    "BlendshapeFit",
    "DisplacementInterpolation",
    "FitJaw",
    "FitJawResidual",
    "FitJawUnbounded",
    "FitJawUnboundedResidual",
    "LgiRbf",
    "ridge_weights",
    "vertex_uvs",
]


def _diagonal(points: F64) -> float:
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def _frames(frames: ArrayLike, surface: _Surface) -> F64:
    """Frames as (F, B, 3) float64, checked by the same rules as `Model.solve` (shape, no
    infinities, magnitudes within `lgi._lgi.MAGNITUDE_LIMIT` face sizes, 3 markers present)."""
    b = surface.num_bundles
    arr = np.asarray(frames, dtype=np.float64)
    if arr.ndim == 2:
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[1:] != (b, 3):
        raise InputError(f"frames: expected shape (F, {b}, 3), got {arr.shape}")
    _lgi.check_marker_frames(arr, surface.markers_rest, surface.diagonal)
    return arr


class _Surface:
    """The markers' rest surface points on the neutral (shared by all baselines)."""

    def __init__(self, dataset: Dataset, markers_rest: ArrayLike, surface_tolerance: float):
        if not isinstance(dataset, Dataset):
            raise InputError(f"dataset: expected lgi.Dataset, got {type(dataset).__name__}")
        self.dataset = dataset
        self.neutral = np.asarray(dataset.neutral, dtype=np.float64)
        self.diagonal = _diagonal(self.neutral)
        markers = np.asarray(markers_rest)
        if not np.issubdtype(markers.dtype, np.floating):
            raise InputError(f"markers_rest: expected a float array, got dtype {markers.dtype}")
        self.markers_rest = np.asarray(markers, dtype=np.float64)
        self.rbf = _lgi.RbfInterpolator.from_dataset(
            dataset.core, markers, float(surface_tolerance) * self.diagonal
        )
        self.sv = self.rbf.sample_vertices
        self.sw = self.rbf.sample_weights
        self.rest = self.sample(self.neutral[None])[0]

    @property
    def num_bundles(self) -> int:
        return int(self.sv.shape[0])

    def sample(self, meshes: F64) -> F64:
        """Marker surface positions (F, B, 3) on meshes (F, V, 3)."""
        return np.einsum("fbjd,bj->fbd", meshes[:, self.sv], self.sw)

    def result(self, vertices: F64, frames: F64, choices: Choices | None = None) -> SolveResult:
        missing: NDArray[np.bool_] = np.asarray(np.isnan(frames).any(axis=2))
        pos = self.sample(vertices)
        res = np.where(missing, 0.0, np.linalg.norm(np.nan_to_num(frames - pos), axis=2))
        f, b = missing.shape
        if choices is None:
            choices = Choices(
                shapes=np.full((f, b, 4), -1, dtype=np.int64),
                weights=np.zeros((f, b, 4)),
                tets=np.full((f, b), -1, dtype=np.int64),
                projected=np.zeros((f, b), dtype=bool),
            )
        return SolveResult(
            vertices=vertices,
            bundle_residuals=res,
            bundle_positions=pos,
            missing=missing,
            choices=choices,
        )


class DisplacementInterpolation:
    """Biharmonic RBF interpolation of the markers' displacements from rest.

    phi(r) = r in 3D (the biharmonic kernel) with a linear polynomial: simple, smooth (minimises
    bending energy), exact at the markers and exact for affine motion; the standard baseline.
    Each marker's constraint is sampled like the mesh samples it (barycentric on its triangle),
    so the output passes through every present marker exactly. Missing markers (NaN) are
    refitted without them (the factorisation is cached per missing set)."""

    label: ClassVar[str] = "displacement interpolation"

    def __init__(
        self, dataset: Dataset, markers_rest: ArrayLike, surface_tolerance: float = 0.02
    ) -> None:
        self._s = _Surface(dataset, markers_rest, surface_tolerance)

    @property
    def num_bundles(self) -> int:
        return self._s.num_bundles

    @property
    def matrix(self) -> F64:
        """(V, B) interpolation matrix (all markers present)."""
        return self._s.rbf.matrix

    def solve(self, frames: ArrayLike, *, quiet: bool = False, **_: Any) -> SolveResult:
        """Frames (F, B, 3) (NaN rows missing) -> meshes through the markers."""
        fr = _frames(frames, self._s)
        disp = self._s.rbf.interpolate(fr - self._s.rest[None])
        return self._s.result(self._s.neutral[None] + disp, fr)


class BlendshapeFit:
    """Per-frame blendshape weights: min |A w - (t - p0)|^2 + l2 |w|^2
    + penalty * sum(min(w, 0)^2 + max(w - 1, 0)^2), A (3B x S) the shapes' displacements at the
    markers. `l2` and `penalty` are relative to the mean diagonal of A^T A. Missing markers drop
    their rows. Output: x0 + sum_k w_k s_k."""

    label: ClassVar[str] = "blendshape fit"

    def __init__(
        self,
        dataset: Dataset,
        markers_rest: ArrayLike,
        penalty: float = _lgi.FIT_PENALTY,
        l2: float = _lgi.FIT_L2,
        surface_tolerance: float = 0.02,
    ) -> None:
        self._s = _Surface(dataset, markers_rest, surface_tolerance)
        if dataset.num_shapes == 0:
            raise InputError("BlendshapeFit needs a dataset with shapes")
        self._shapes = np.asarray(dataset.shapes, dtype=np.float64)  # (S, V, 3)
        at = self._s.sample(self._shapes)  # (S, B, 3)
        self.a: F64 = at.reshape(at.shape[0], -1).T.copy()
        scale = float(np.mean(np.sum(self.a**2, axis=0))) or 1.0
        if not (np.isfinite(l2) and l2 >= 0 and np.isfinite(penalty) and penalty >= 0):
            raise InputError(f"l2 ({l2}) and penalty ({penalty}) must be non-negative")
        self._solver = _lgi.BlendshapeSolver(self.a, l2 * scale, penalty * scale)
        self.last_weights: F64 | None = None
        self.last_iterations: NDArray[np.int64] | None = None

    @property
    def num_bundles(self) -> int:
        return self._s.num_bundles

    @property
    def solver(self) -> _lgi.BlendshapeSolver:
        return self._solver

    def weights(self, frames: ArrayLike) -> F64:
        """(F, S) fitted weights."""
        fr = _frames(frames, self._s)
        target = (fr - self._s.rest[None]).reshape(fr.shape[0], -1)
        w, it = self._solver.solve(target)
        self.last_iterations = it
        return w

    def solve(self, frames: ArrayLike, *, quiet: bool = False, **_: Any) -> SolveResult:
        fr = _frames(frames, self._s)
        w = self.weights(fr)
        self.last_weights = w
        verts = self._s.neutral[None] + np.einsum("fk,kvd->fvd", w, self._shapes)
        return self._s.result(verts, fr)


class FitJaw:
    """The peer a production TD already has, the rig solve with the jaw turned as a joint:
    each frame's blendshape weights and jaw pose solved together, the mesh the shapes' blend
    skinned by the pose, `T(theta) (x0 + sum_k w_k u_k)`, with `u_k` shape k unskinned by its
    own pose. The weights and pose are lgi's own (the frame's global fit in the jaw's unskinned
    space, the pose refined against it: `model.solve(frames, jaw="fit", fit=True)`), so the
    only difference from lgi's result is the local geometry. Needs a model built with a jaw rig
    and without jaw bins (a binned model fits each bin's re-posed shapes)."""

    label: ClassVar[str] = "fit + jaw"

    def __init__(self, model: Model, surface_tolerance: float = 0.02) -> None:
        rig = model.jaw_rig
        jaw = model.core.jaw()
        if rig is None or jaw is None:
            raise InputError("FitJaw needs a model built with a jaw rig (Model.build(jaw=...))")
        if model.jaw_bins is not None:
            raise InputError("FitJaw: the model has jaw bins; build it without jaw_bins")
        self._model = model
        self._rig = rig
        data = model.dataset
        self._s = _Surface(data, model.markers_rest, surface_tolerance)
        x0 = self._s.neutral
        theta = np.asarray(jaw["shape_theta"], dtype=np.float64)
        shapes = np.asarray(data.shapes)
        # float32 like the dataset: (S, V, 3).
        self._unskinned = np.stack(
            [rig.unskin_displacements(x0, shapes[k], theta[k]) for k in range(len(shapes))]
        ).astype(np.float32)

    @property
    def num_bundles(self) -> int:
        return self._s.num_bundles

    def solve(self, frames: ArrayLike, *, quiet: bool = False, **_: Any) -> SolveResult:
        fr = _frames(frames, self._s)
        # The peer as a rig solve reads a take: each frame from its own markers.
        solved = self._model.solve(fr, jaw="fit", fit=True, steady=False, quiet=True)
        w, theta = solved.fit_weights, solved.jaw_theta
        if w is None or theta is None:
            raise InputError("FitJaw: the solve made no fit or no jaw pose")
        blend = self._s.neutral[None] + np.einsum("fk,kvd->fvd", w, self._unskinned)
        return self._s.result(self._rig.skin(blend, theta), fr)


def ridge_weights(a: F64, b: F64, ridge: float) -> F64:
    """argmin |a w - b|^2 + ridge |w|^2 (a: R x S): the normal equations, or with more columns
    than rows (K = 2,000 scans on 360 rows) the same solution as a^T (a a^T + ridge I)^-1 b."""
    r, s = a.shape
    if s <= r:
        return np.asarray(np.linalg.solve(a.T @ a + ridge * np.eye(s), a.T @ b))
    return np.asarray(a.T @ np.linalg.solve(a @ a.T + ridge * np.eye(r), b))


class FitJawUnbounded(FitJaw):
    """`FitJaw` with the weights not held to [0, 1]: the least-squares rig solve a dataset of
    scans (a PCA-like model, whose weights are no activations) is solved with. Each frame's
    markers, unskinned by the jaw pose `FitJaw` finds, are fitted by the unskinned shapes at the
    markers with the fit's ridge (`FIT_L2` times the matrix's mean squared column norm) and no
    bound; the blend is skinned by that pose."""

    label: ClassVar[str] = "fit + jaw (unbounded)"

    def __init__(self, model: Model, surface_tolerance: float = 0.02) -> None:
        super().__init__(model, surface_tolerance)
        jaw = model.core.jaw()
        assert jaw is not None  # FitJaw refuses a model without a jaw rig
        self._bundle_jaw = np.asarray(jaw["bundle_weights"], dtype=np.float64)
        # The shapes at the markers, rows 3b + d (B markers, 3 coordinates) by S columns.
        at = self._s.sample(self._unskinned.astype(np.float64))
        self._a = at.transpose(1, 2, 0).reshape(-1, at.shape[0])
        self._ridge = _lgi.FIT_L2 * float(np.mean(np.sum(self._a**2, axis=0)))

    def solve(self, frames: ArrayLike, *, quiet: bool = False, **_: Any) -> SolveResult:
        fr = _frames(frames, self._s)
        theta = self._model.solve(fr, jaw="fit", fit=True, steady=False, quiet=True).jaw_theta
        if theta is None:
            raise InputError("FitJawUnbounded: the solve made no jaw pose")
        unskinned = self._rig.unskin(np.nan_to_num(fr), theta, weights=self._bundle_jaw)
        disp = (unskinned - self._s.rest[None]).reshape(len(fr), -1)
        present = np.repeat(np.isfinite(fr).all(axis=2), 3, axis=1)
        s = self._a.shape[1]
        w = np.zeros((len(fr), s))
        for f in range(len(fr)):
            w[f] = ridge_weights(self._a[present[f]], disp[f, present[f]], self._ridge)
        blend = self._s.neutral[None] + np.einsum("fk,kvd->fvd", w, self._unskinned)
        return self._s.result(self._rig.skin(blend, theta), fr)


#: Smoothing candidates of `FitJawResidual`, times the median distance between markers.
RESIDUAL_SMOOTHING = (0.0, 1e-2, 3e-2, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0, 1e3)
#: Frames of a take (spread over it) whose left-out errors choose the smoothing.
SMOOTHING_FRAMES = 50


class FitJawResidual:
    """`FitJaw` followed by a corrective of its marker residuals (the production method before
    LGI, Bhat et al. 2013): each frame's residuals at the present markers spread over the mesh
    by a smoothing thin-plate spline in 3D (phi(r) = r, a linear polynomial, `lam` taken from
    the kernel's diagonal: phi is conditionally negative definite). `lam` is chosen per take
    without the truth: the candidate
    (`RESIDUAL_SMOOTHING` times the median distance between markers) with the least squared
    error at each marker left out in turn, summed over up to `SMOOTHING_FRAMES` frames
    (Rippa's closed form: the left-out error of marker i is c_i / (A^-1)_ii, A the spline's
    system). `smoothing` fixes the candidates (e.g. `[0.0]`: exact interpolation). Built on a
    `FitJaw` (its unskinned shapes and marker sampling are shared, not made again)."""

    label: ClassVar[str] = "fit + jaw + residual"

    def __init__(self, peer: FitJaw, smoothing: ArrayLike | None = None) -> None:
        self._peer = peer
        s = peer._s
        c = np.asarray(s.rbf.centres, dtype=np.float64)
        self._kbb = np.linalg.norm(c[:, None] - c[None], axis=2)
        self._pb = np.hstack([np.ones((len(c), 1)), c])
        v = s.neutral
        self._kvb = np.linalg.norm(v[:, None] - c[None], axis=2)
        self._pv = np.hstack([np.ones((len(v), 1)), v])
        off = self._kbb + np.diag(np.full(len(c), np.inf))
        spacing = float(np.median(off.min(axis=1)))
        cands = RESIDUAL_SMOOTHING if smoothing is None else smoothing
        self._candidates = [float(x) * spacing for x in np.atleast_1d(np.asarray(cands))]
        if not self._candidates or min(self._candidates) < 0:
            raise InputError("smoothing: expected one or more values >= 0")
        self.last_smoothing: float | None = None

    @property
    def num_bundles(self) -> int:
        return self._peer.num_bundles

    def _system(self, present: NDArray[np.bool_], lam: float) -> F64:
        # phi(r) = r is conditionally negative definite: smoothing subtracts lam (the
        # spline of -phi, conditionally positive definite, with lam added), never crossing
        # the kernel's spectrum.
        k = self._kbb[np.ix_(present, present)] - lam * np.eye(int(present.sum()))
        p = self._pb[present]
        n = k.shape[0]
        a = np.zeros((n + 4, n + 4))
        a[:n, :n], a[:n, n:], a[n:, :n] = k, p, p.T
        return a

    def left_out_error(self, residuals: F64, lam: float) -> float:
        """Sum over the frames (F, B, 3) of the squared error at each present marker of the
        spline fitted without it (Rippa's closed form)."""
        total = 0.0
        for r in residuals:
            present = np.isfinite(r).all(axis=1)
            n = int(present.sum())
            if n < 5:
                continue
            inv = np.linalg.inv(self._system(present, lam))
            coef = inv[:, :n] @ r[present]
            total += float(np.sum((coef[:n] / np.diag(inv)[:n, None]) ** 2))
        return total

    def solve(self, frames: ArrayLike, *, quiet: bool = False, **_: Any) -> SolveResult:
        s = self._peer._s
        fr = _frames(frames, s)
        base = self._peer.solve(fr)
        residuals = fr - base.bundle_positions
        pick = np.unique(np.linspace(0, len(fr) - 1, SMOOTHING_FRAMES).round().astype(int))
        lam = min(self._candidates, key=lambda x: self.left_out_error(residuals[pick], x))
        self.last_smoothing = lam
        vertices = np.array(base.vertices)
        for f, r in enumerate(residuals):
            present = np.isfinite(r).all(axis=1)
            n = int(present.sum())
            if n < 5:
                continue
            rhs = np.vstack([r[present], np.zeros((4, 3))])
            coef = np.linalg.solve(self._system(present, lam), rhs)
            vertices[f] += self._kvb[:, present] @ coef[:n] + self._pv @ coef[n:]
        return s.result(vertices, fr)


def vertex_uvs(dataset: Dataset) -> F64:
    """(V, 2) one UV per vertex: the UV of the first triangle corner using it (NaN if none)."""
    tri = np.asarray(dataset.triangles).reshape(-1)
    uvt = np.asarray(dataset.uv_triangles).reshape(-1)
    uvs = np.asarray(dataset.uvs, dtype=np.float64)
    if uvt.size != tri.size or uvs.size == 0:
        raise InputError("dataset has no UVs")
    out = np.full((dataset.num_vertices, 2), np.nan)
    first_vertex, first = np.unique(tri, return_index=True)
    out[first_vertex] = uvs[uvt[first]]
    return out


class FitJawUnboundedResidual(FitJawResidual):
    """`FitJawResidual` on `FitJawUnbounded`: the unbounded rig solve followed by the
    corrective of its marker residuals, its smoothing chosen the same way."""

    label: ClassVar[str] = "fit + jaw (unbounded) + residual"


class LgiRbf:
    """LGI's per-bundle choices spread by normalised Gaussian weights over UV distance, then a
    biharmonic RBF correction of the residuals so the result interpolates every marker.
    `sigma` (UV units) defaults to the mean nearest-neighbour distance between bundle UVs."""

    label: ClassVar[str] = "LGI-RBF"

    def __init__(
        self,
        dataset: Dataset,
        markers_rest: ArrayLike,
        config: BuildConfig | None = None,
        sigma: float | None = None,
    ) -> None:
        cfg = config or BuildConfig()
        self.model = Model.build(dataset, markers_rest, cfg, jaw=None)
        self._s = _Surface(dataset, markers_rest, cfg.surface_tolerance)
        self._shapes = np.asarray(dataset.shapes, dtype=np.float64)
        self._shapes_v = np.ascontiguousarray(self._shapes.transpose(1, 0, 2))  # (V, S, 3)
        buv = np.asarray(self.model.core.bundle_uvs(), dtype=np.float64)
        d = np.linalg.norm(buv[:, None] - buv[None], axis=2)
        np.fill_diagonal(d, np.inf)
        self.sigma = float(d.min(axis=1).mean()) if sigma is None else float(sigma)
        if not (np.isfinite(self.sigma) and self.sigma > 0):
            raise InputError(f"sigma must be positive, got {sigma}")
        vuv = vertex_uvs(dataset)
        dv = np.linalg.norm(vuv[:, None] - buv[None], axis=2)  # (V, B), NaN without UV
        # Vertices without a UV fall back to 3D distance to the bundles at rest, in UV scale.
        no_uv = np.isnan(dv).any(axis=1)
        if no_uv.any():
            d3 = np.linalg.norm(self._s.neutral[no_uv][:, None] - self._s.rest[None], axis=2)
            dv[no_uv] = d3 * (self.sigma / max(float(d3.min(axis=1).mean()), 1e-300))
        dv = dv - dv.min(axis=1, keepdims=True)  # shift-invariant after normalisation
        self._g = np.exp(-0.5 * (dv / self.sigma) ** 2)  # (V, B)

    @property
    def num_bundles(self) -> int:
        return self._s.num_bundles

    def solve(
        self, frames: ArrayLike, *, temporal: bool = True, steady: bool = True, quiet: bool = False
    ) -> SolveResult:
        fr = _frames(frames, self._s)
        lgi_res = self.model.solve(fr, temporal=temporal, steady=steady, quiet=quiet)
        ch = lgi_res.choices
        nf, b = fr.shape[:2]
        s = self._shapes.shape[0]
        verts = np.empty((nf, self._shapes.shape[1], 3))
        for f in range(nf):
            lam = np.zeros((b, s + 1))  # column s: the neutral (discarded)
            np.add.at(
                lam,
                (np.arange(b)[:, None], np.where(ch.shapes[f] < 0, s, ch.shapes[f])),
                ch.weights[f],
            )
            present = ~lgi_res.missing[f]
            g = self._g * present[None]
            g = g / np.maximum(g.sum(axis=1, keepdims=True), 1e-300)
            coef = g @ lam[:, :s]  # (V, S)
            verts[f] = self._s.neutral + np.matmul(coef[:, None, :], self._shapes_v)[:, 0]
        spread = self._s.sample(verts)
        corr = self._s.rbf.interpolate(fr - spread)
        return self._s.result(verts + corr, fr, choices=ch)
