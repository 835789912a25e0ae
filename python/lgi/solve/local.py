"""Local fits (beyond the paper): each bundle's piece is the blendshape fit of the markers
around it instead of one of its tets or the frame's global fit.

A dataset of whole-face scans rarely holds the whole frame being solved, but around one marker
some blend of the scans usually matches: the global fit has to trade the mouth against the
brows, a fit of one neighbourhood does not. Bundle b's piece is the box-penalised fit (the
global fit's ridge and penalty, relative to its own matrix) of the markers weighted by the
Gaussian of their rest distance from b, `LOCAL_LENGTH` median marker spacings long (markers
beyond `WINDOW_REACH` lengths left out).
It fits the solve's noise-aware targets in the jaw's unskinned space, each window starting
from its fit of the frame before (a call's first frame: the frame's global fit). The pieces'
weights are blended over the mesh by the sewing weights (a vertex's weights are its bundles'
weights, weighted like their pieces; mapped onto the scans' shape basis where there is one),
the blend is skinned by the frame's jaw pose, and what it misses at the present markers is
interpolated biharmonically (phi(r) = r with a linear polynomial, the residual corrective's
rule), so the surface passes through every present target. `lgi.plan.local.estimate_local_fits`
reads from a take's own markers whether to use them. docs/concepts.md explains it;
docs/results.md measures it against the strongest peers."""

from __future__ import annotations

import warnings
import weakref
from typing import TYPE_CHECKING, Protocol

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

import lgi._lgi as _lgi
from lgi.errors import InputError
from lgi.solve.detail import surface_interpolator
from lgi.solve.options import UNBOUNDED

if TYPE_CHECKING:
    from lgi._lgi import SolveResult
    from lgi.solve.model import Model

F64 = NDArray[np.float64]

__all__ = ["FITS_CHUNK", "UNBOUNDED", "LocalPieces", "Solution", "local_pieces"]


class Solution(Protocol):
    """What local fits read of a noise-aware solve: a `SolveResult`, or the left-out readings'
    rows of one (`lgi.plan.readings.Solved`)."""

    @property
    def bundle_positions(self) -> NDArray[np.float64]: ...
    @property
    def missing(self) -> NDArray[np.bool_]: ...
    @property
    def fit_weights(self) -> NDArray[np.float64] | None: ...
    @property
    def jaw_theta(self) -> NDArray[np.float64] | None: ...


FITS_CHUNK = 16
"""Frames whose local fits (and then whose blend) one call to the core makes (a few hundred
ms at most: Ctrl-C is seen between calls)."""

SURFACE_CHUNK = 64
"""Frames whose surface one call to the core makes (~0.2 s on ICT): the corrective's matrix
(V x B doubles, 34 MB on ICT at 160 markers) is read from memory once a call, so a call
covers more frames than a fit's; each frame's surface is the same bits in any chunk."""


class LocalPieces:
    """A model's local fits and what blends them over its mesh (made once per model by
    `local_pieces`)."""

    def __init__(self, model: Model) -> None:
        if model.jaw_bins is not None:
            raise InputError(
                "local fits: the model has jaw bins (each bin fits its own re-posed shapes); "
                "build it without jaw_bins"
            )
        data = model.dataset
        self.neutral = np.asarray(data.neutral, dtype=np.float64)
        shapes = np.asarray(data.shapes)
        self.rig = model.jaw_rig
        self.bundle_jaw: F64 | None = None
        jaw = model.core.jaw()
        theta = None
        if self.rig is not None and jaw is not None:
            theta = np.asarray(jaw["shape_theta"], dtype=np.float64)
            self.bundle_jaw = np.asarray(jaw["bundle_weights"], dtype=np.float64)
        # Each shape without its own jaw pose, (S, V, 3) float32 like the dataset, filled
        # shape by shape (no second copy of every shape at once).
        s_count, v_count = len(shapes), self.neutral.shape[0]
        unskinned = np.empty((s_count, v_count, 3), dtype=np.float32)
        for k in range(s_count):
            if self.rig is not None and theta is not None:
                unskinned[k] = self.rig.unskin_displacements(self.neutral, shapes[k], theta[k])
            else:
                unskinned[k] = shapes[k]
        del shapes
        # Scans of one face are often combinations of fewer of them (the core's shape basis,
        # exact to a relative rms of 1e-6): blending the basis shapes with each bundle's
        # weights mapped onto them is the same surface at a fraction of the work (160 of
        # 2,000 scans in the scans protocol). `basis_map` (S, q) maps weights onto them.
        found = _lgi.shape_basis(unskinned.reshape(s_count, -1))
        self.basis_map: F64 | None = None
        used = np.arange(s_count)
        if found is not None:
            used, self.basis_map = found
        # (V, 3, q) float32: a vertex's blend reads its weights against contiguous memory (4x
        # faster than (q, V, 3)).
        self.shapes = np.empty((v_count, 3, len(used)), dtype=np.float32)
        for j, shape in enumerate(used):
            self.shapes[:, :, j] = unskinned[shape]
        surf = model.core.bundle_surface_points()
        tris = np.asarray(data.triangles, dtype=np.int64)[np.asarray(surf["triangles"])]
        bary = np.asarray(surf["barycentrics"], dtype=np.float64)
        # The bundles' rest positions, by the core's one definition of a bundle on a mesh.
        self.rest = model.core.bundle_positions(self.neutral[None])[0]
        at = np.einsum("sbjd,bj->bds", unskinned[:, tris], bary, dtype=np.float64)
        a = at.reshape(3 * model.num_bundles, s_count)
        del unskinned
        # Kept (3B x S doubles: 6 MB at 2,000 scans) for the windows' fits, made when asked for.
        self._a = a
        self._fits_made: dict[tuple[bool, float], _lgi.LocalFits] = {}
        sw = model.core.sew_weights()
        v, b = self.neutral.shape[0], model.num_bundles
        sewing = sp.csr_matrix((sw["data"], sw["indices"], sw["indptr"]), shape=(v, b))
        self._sew_rows = _csr_rows(sewing)
        # The model's one biharmonic interpolation over the mesh (the steady pass's too): made
        # once per model, not again here.
        self.corrective = surface_interpolator(model)
        # Blend, skinning, corrective and the markers measured, frame by frame in the core.
        self._surface = _lgi.LocalSurface(
            self.neutral, self.shapes, *self._sew_rows, self.rig, self.corrective, model.core
        )
        # The same surface at the bundles only (`at_bundles`): the vertices of their triangles,
        # their sewing rows and shapes, and the corrective over them (its centres and samples
        # are these vertices', so it is the same interpolant evaluated at fewer points).
        corners = np.unique(tris)
        self._corners = corners
        self._corner_tris = np.searchsorted(corners, tris)
        self._corner_bary = bary
        self._corner_sew_rows = _csr_rows(sewing[corners])
        self._corner_shapes = np.ascontiguousarray(self.shapes[corners])
        self._corner_jaw = None if self.rig is None else np.asarray(self.rig.weights)[corners]
        self._corner_corrective = _lgi.RbfInterpolator(
            self.neutral[corners], self._corner_tris, bary
        )
        self._bundles_matrix: F64 | None = None

    def fits_for(self, bounded: bool, lengths: float = _lgi.LOCAL_LENGTH) -> _lgi.LocalFits:
        """The windows' fits with weights held to [0, 1] (`bounded`) or not (`UNBOUNDED`: the
        same ridge, no penalty), the windows `lengths` median marker spacings long."""
        key = (bounded, float(lengths))
        made = self._fits_made.get(key)
        if made is None:
            penalty = _lgi.FIT_PENALTY if bounded else 0.0
            made = _lgi.LocalFits(self._a, self.rest, _lgi.FIT_L2, penalty, lengths)
            self._fits_made[key] = made
        return made

    def _fits(
        self, res: Solution, bounded: bool, lengths: float = _lgi.LOCAL_LENGTH
    ) -> tuple[F64, F64, F64 | None]:
        """The solve's targets (F, B, 3; NaN: missing), each frame's local weights per bundle
        (F, B, q: over the shape basis where there is one; `bounded`: held to [0, 1]) and the
        jaw poses."""
        if res.fit_weights is None:
            raise InputError("local fits need the solve's global fit: solve with marker_noise")
        missing = np.asarray(res.missing)
        targets = np.where(missing[..., None], np.nan, np.asarray(res.bundle_positions))
        theta = None if res.jaw_theta is None else np.asarray(res.jaw_theta, dtype=np.float64)
        unskinned = targets
        if self.rig is not None and theta is not None:
            unskinned = self.rig.unskin(np.nan_to_num(targets), theta, weights=self.bundle_jaw)
            unskinned[missing] = np.nan
        starts = np.asarray(res.fit_weights, dtype=np.float64)
        disp = unskinned - self.rest[None]
        lacking = np.flatnonzero(missing.any(axis=1)) if not bounded else np.empty(0, int)
        if lacking.size:
            # An unbounded window that loses a marker extrapolates its fit to that marker's
            # place unchecked (a dropped marker moved the surface by up to 7 cm there on the
            # scans protocol, docs/results.md): its rows take the frame's global fit instead,
            # as the take prior's reading refills them. Bounded windows keep the box instead.
            fitted = (starts[lacking] @ self._a.T).reshape(lacking.size, -1, 3)
            gone = missing[lacking][..., None]
            disp[lacking] = np.where(gone, fitted, disp[lacking])
        # A chunk of frames per call, so Ctrl-C (seen between calls) stops a long take at once.
        # Each chunk's weights go onto the basis shapes as they come: the take's weights over
        # every shape (F x B x S: 184 MB at 1,200 frames of 120 scans) are never held at once.
        fits = self.fits_for(bounded, lengths)
        parts: list[F64] = []
        kept = 0
        for a in range(0, disp.shape[0], FITS_CHUNK):
            w, k = fits.solve(disp[a : a + FITS_CHUNK], starts[a : a + FITS_CHUNK])
            parts.append(w if self.basis_map is None else w @ self.basis_map)
            kept += k
        weights = np.concatenate(parts)
        if kept:
            warnings.warn(
                f"local fits: {kept} of {weights.shape[0] * weights.shape[1]} bundle fits had no "
                "marker of their window present or did not converge, and kept the frame's "
                "global fit",
                stacklevel=4,
            )
        return targets, weights, theta

    def _posed(self, blend: F64, theta: F64 | None, jaw: F64 | None) -> F64:
        """`blend` (F, N, 3) skinned by the frames' jaw poses (`jaw`: the N points' weights,
        None: every vertex's)."""
        if theta is None or self.rig is None:
            return blend
        return self.rig.skin(blend, theta, weights=jaw)

    def surface(
        self,
        res: SolveResult,
        out: F64 | None = None,
        *,
        bounded: bool = True,
        lengths: float = _lgi.LOCAL_LENGTH,
    ) -> F64:
        """The local fits' surface (F, V, 3) of a noise-aware solve `res` (its targets, jaw
        poses and global fits), into `out` when given; `bounded` and `lengths`: as
        `fits_for`."""
        return self.surface_and_markers(res, out, bounded=bounded, lengths=lengths)[0]

    def surface_and_markers(
        self,
        res: SolveResult,
        out: F64 | None = None,
        *,
        bounded: bool = True,
        lengths: float = _lgi.LOCAL_LENGTH,
    ) -> tuple[F64, F64]:
        """`surface` and the markers' positions on it (F, B, 3), measured as
        `Model.bundle_positions` measures them. Each chunk of frames is one call to the core
        (`_lgi.LocalSurface`: blend, jaw pose, corrective and positions, with no frame-sized
        array in between; Ctrl-C is seen between calls)."""
        f = np.asarray(res.missing).shape[0]
        v, b = self.neutral.shape[0], self.rest.shape[0]
        if out is None:
            out = np.empty((f, v, 3))
        if f == 0:
            return out, np.empty((0, b, 3))
        targets, weights, theta = self._fits(res, bounded, lengths)
        return out, self._surface_chunks(weights, targets, out, theta, corrective=True)

    def _surface_chunks(
        self, weights: F64, targets: F64, out: F64, theta: F64 | None, *, corrective: bool
    ) -> F64:
        """The surface of every frame into `out`, `SURFACE_CHUNK` frames a call to the core
        (`_lgi.LocalSurface.surface`, `corrective` as there): the markers' positions on it."""
        positions = np.empty((out.shape[0], self.rest.shape[0], 3))
        for a in range(0, out.shape[0], SURFACE_CHUNK):
            part = slice(a, a + SURFACE_CHUNK)
            positions[part] = self._surface.surface(
                weights[part],
                targets[part],
                out[part],
                None if theta is None else theta[part],
                corrective=corrective,
            )
        return positions

    def posed_and_misses(
        self, res: SolveResult, out: F64, *, bounded: bool = True
    ) -> tuple[F64, F64, F64]:
        """`surface_and_markers` without the corrective's pass over the mesh, for a caller
        that adds it itself (`lgi.solve.steady`, which adds a corrective of its own anyway):
        `out` holds the posed blend; returned with the markers' positions on the whole
        surface (the blend plus the corrective, measured at the bundles: the same to
        round-off) and the misses (F, B, 3) whose interpolation over the mesh
        (`surface_interpolator`, the same interpolant) is the corrective."""
        f = np.asarray(res.missing).shape[0]
        b = self.rest.shape[0]
        if f == 0:
            return out, np.empty((0, b, 3)), np.empty((0, b, 3))
        targets, weights, theta = self._fits(res, bounded)
        on_blend = self._surface_chunks(weights, targets, out, theta, corrective=False)
        misses = targets - on_blend
        # (B, B) @ (F, B, 3): one matrix product a frame (20 x faster than the einsum's loop).
        return out, on_blend + self._at_bundles_matrix() @ misses, misses

    def _at_bundles_matrix(self) -> F64:
        """(B, B): the corrective of unit misses measured at the bundles."""
        if self._bundles_matrix is None:
            rows = np.asarray(self._corner_corrective.matrix)  # (corners, B)
            self._bundles_matrix = np.einsum(
                "bjk,bj->bk", rows[self._corner_tris], self._corner_bary
            )
        return self._bundles_matrix

    def at_bundles(self, res: Solution, *, bounded: bool = True) -> F64:
        """Every bundle's position (F, B, 3) on the local fits' surface of `res`: the same
        values as `surface` sampled at the bundles (to round-off), made on the bundles'
        triangles' vertices only (what `estimate_local_fits` compares)."""
        b = self.rest.shape[0]
        if np.asarray(res.missing).shape[0] == 0:
            return np.empty((0, b, 3))
        targets, weights, theta = self._fits(res, bounded)
        neutral = self.neutral[self._corners]
        blend = _blend(neutral, self._corner_shapes, self._corner_sew_rows, weights)
        posed = self._posed(blend, theta, self._corner_jaw)

        def sampled(values: F64) -> F64:
            return np.einsum("fbjd,bj->fbd", values[:, self._corner_tris], self._corner_bary)

        on_blend = sampled(posed)
        return on_blend + sampled(self._corner_corrective.interpolate(targets - on_blend))


def _csr_rows(sewing: sp.csr_matrix) -> tuple[NDArray[np.int64], NDArray[np.int64], F64]:
    """Sewing weights as the core's blend reads them: CSR rows, int64 indices."""
    return (
        np.ascontiguousarray(sewing.indptr, dtype=np.int64),
        np.ascontiguousarray(sewing.indices, dtype=np.int64),
        np.ascontiguousarray(sewing.data, dtype=np.float64),
    )


def _blend(
    neutral: F64,
    shapes: NDArray[np.float32],
    rows: tuple[NDArray[np.int64], NDArray[np.int64], F64],
    weights: F64,
) -> F64:
    """The core's blend (`_lgi.blend_local`) of `weights` (F, B, q) over `neutral`'s vertices,
    a chunk of frames per call (Ctrl-C is seen between calls)."""
    blend = np.empty((weights.shape[0], *neutral.shape))
    for a in range(0, weights.shape[0], FITS_CHUNK):
        blend[a : a + FITS_CHUNK] = _lgi.blend_local(
            neutral, shapes, *rows, weights[a : a + FITS_CHUNK]
        )
    return blend


# Per model (made on first use, dropped with the model).
_PIECES: weakref.WeakKeyDictionary[Model, LocalPieces] = weakref.WeakKeyDictionary()


def local_pieces(model: Model) -> LocalPieces:
    """The model's `LocalPieces` (made on first use, kept while the model lives)."""
    made = _PIECES.get(model)
    if made is None:
        made = LocalPieces(model)
        _PIECES[model] = made
    return made
