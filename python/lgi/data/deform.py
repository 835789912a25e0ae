"""Deformation gradients on a triangle mesh and the Poisson solve that turns per-triangle
gradients back into positions: the one machinery behind ARAP in-betweens (`lgi.data.augment`) and
deformation transfer onto another neutral (`lgi.solve.rig`, Sumner & Popovic 2004).

A triangle's deformation gradient is Sumner's: the 3x3 map of its two edges and its scaled
normal. The solve minimises the area-weighted squared difference between the mesh's piecewise
linear gradient and the targets (the cotangent Laplacian, factorised once per rest mesh), with
pinned vertices held at given positions; a connected part with no pin keeps the area-weighted
centroid of the given positions. scipy does the sparse factorisation (docs/architecture.md
says why it is a runtime dependency)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi.errors import InputError

F64 = NDArray[np.float64]

AREA_FLOOR = 1e-14
"""Triangles with area below this fraction of the squared bounding-box diagonal carry no
gradient (zero-area triangles have none); their vertices are solved through their neighbours."""


def _points(a: ArrayLike, v: int, what: str) -> F64:
    x = np.asarray(a, dtype=np.float64)
    if x.shape != (v, 3):
        raise InputError(f"{what}: expected shape ({v}, 3), got {x.shape}")
    if not np.isfinite(x).all():
        bad = int(np.flatnonzero(~np.isfinite(x).all(axis=1))[0])
        raise InputError(f"{what}: vertex {bad} is not finite")
    return x


def _frames(x: F64, tri: NDArray[np.int64]) -> F64:
    """(T, 3, 3): per triangle the columns edge 1, edge 2 and the normal scaled to edge
    length (Sumner & Popovic's fourth vertex), whose inverse maps rest to deformed."""
    e1 = x[tri[:, 1]] - x[tri[:, 0]]
    e2 = x[tri[:, 2]] - x[tri[:, 0]]
    n = np.cross(e1, e2)
    n = n / np.sqrt(np.maximum(np.linalg.norm(n, axis=1), 1e-300))[:, None]
    return np.stack([e1, e2, n], axis=2)


def deformation_gradients(rest: ArrayLike, deformed: ArrayLike, triangles: ArrayLike) -> F64:
    """(T, 3, 3): each triangle's deformation gradient from `rest` to `deformed` (both
    (V, 3)); the identity where the rest triangle has no area (`AREA_FLOOR`)."""
    tri = np.asarray(triangles, dtype=np.int64)
    x = np.asarray(rest, dtype=np.float64)
    frames = _frames(x, tri)
    diag = float(np.linalg.norm(x.max(axis=0) - x.min(axis=0)))
    # det of the rest frame = |e1 x e2|^1.5; below the floor the frame cannot be inverted.
    ok = np.abs(np.linalg.det(frames)) > (2 * AREA_FLOOR * diag * diag) ** 1.5
    out = np.broadcast_to(np.eye(3), (len(tri), 3, 3)).copy()
    y = _points(deformed, x.shape[0], "deformed")
    out[ok] = _frames(y, tri[ok]) @ np.linalg.inv(frames[ok])
    return out


class PoissonMesh:
    """A rest mesh prepared for gradient solves: per-triangle rest frames and gradient
    operators, and its Laplacian factorised with `pinned` vertices removed."""

    def __init__(self, rest: ArrayLike, triangles: ArrayLike, pinned: ArrayLike | None = None):
        from scipy import sparse
        from scipy.sparse import csgraph
        from scipy.sparse.linalg import splu

        tri = np.asarray(triangles, dtype=np.int64)
        x = np.asarray(rest, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != 3 or tri.ndim != 2 or tri.shape[1] != 3:
            raise InputError(
                f"rest (V, 3) and triangles (T, 3) expected, got {x.shape}, {tri.shape}"
            )
        v = x.shape[0]
        x = _points(x, v, "rest")
        if tri.size and (tri.min() < 0 or tri.max() >= v):
            raise InputError(f"triangles index vertices outside 0..{v - 1}")
        diag = float(np.linalg.norm(x.max(axis=0) - x.min(axis=0))) if v else 0.0
        e1 = x[tri[:, 1]] - x[tri[:, 0]]
        e2 = x[tri[:, 2]] - x[tri[:, 0]]
        n = np.cross(e1, e2)
        double_area = np.linalg.norm(n, axis=1)
        ok = double_area > 2 * AREA_FLOOR * diag * diag
        self.triangles = tri[ok]
        self.areas = 0.5 * double_area[ok]
        unit = n[ok] / double_area[ok, None]
        t = self.triangles
        # Gradient of each corner's hat function: unit normal x opposite edge / (2 area).
        opposite = np.stack(
            [x[t[:, 2]] - x[t[:, 1]], x[t[:, 0]] - x[t[:, 2]], x[t[:, 1]] - x[t[:, 0]]], axis=1
        )
        self.grads = np.cross(unit[:, None, :], opposite) / double_area[ok, None, None]
        self.rest_inverse = np.linalg.inv(_frames(x, t))
        self.num_vertices = v
        rows = np.repeat(t, 3, axis=1).ravel()
        cols = np.tile(t, (1, 3)).ravel()
        vals = (
            np.einsum("tid,tjd->tij", self.grads, self.grads) * self.areas[:, None, None]
        ).ravel()
        lap = sparse.csr_matrix((vals, (rows, cols)), shape=(v, v))
        mass = np.zeros(v)
        np.add.at(mass, t.ravel(), np.repeat(self.areas / 3.0, 3))
        self.mass = mass
        pin = np.zeros(v, dtype=bool) if pinned is None else np.asarray(pinned, dtype=bool).copy()
        if pin.shape != (v,):
            raise InputError(f"pinned: expected shape ({v},), got {pin.shape}")
        pin |= mass == 0.0  # in no triangle with area: nothing to solve them from
        adjacency = sparse.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(v, v))
        _, label = csgraph.connected_components(adjacency, directed=False)
        pinned_parts = np.unique(label[pin])
        floating = np.setdiff1d(np.unique(label[~pin]), pinned_parts)
        # One temporary pin per floating part (its first vertex); the part is shifted after.
        first = np.full(label.max() + 1 if v else 0, v, dtype=np.int64)
        np.minimum.at(first, label, np.arange(v))
        self._floating = [np.flatnonzero(label == c) for c in floating]
        self._anchor_pins = first[floating]
        solve_pin = pin.copy()
        solve_pin[self._anchor_pins] = True
        self.pinned = pin
        self._free = np.flatnonzero(~solve_pin)
        self._fixed = np.flatnonzero(solve_pin)
        lap = lap.tocsr()
        self._l_free_fixed = lap[self._free][:, self._fixed]
        self._factor = splu(lap[self._free][:, self._free].tocsc()) if self._free.size else None

    def gradients(self, deformed: ArrayLike) -> F64:
        """(T', 3, 3): the deformation gradient of every (non-degenerate) triangle from the
        rest mesh to `deformed` (V, 3)."""
        x = _points(deformed, self.num_vertices, "deformed")
        return np.asarray(_frames(x, self.triangles) @ self.rest_inverse)

    def solve(self, gradients: ArrayLike, anchor: ArrayLike) -> F64:
        """Positions (V, 3) whose triangles' gradients best match `gradients` (T', 3, 3)
        in the area-weighted least-squares sense; pinned vertices are `anchor`'s, and each
        part without pins is placed at `anchor`'s area-weighted centroid of that part."""
        g = np.asarray(gradients, dtype=np.float64)
        if g.shape != (len(self.triangles), 3, 3) or not np.isfinite(g).all():
            raise InputError(
                f"gradients: expected finite ({len(self.triangles)}, 3, 3), got {g.shape}"
            )
        a = _points(anchor, self.num_vertices, "anchor")
        b = np.zeros((self.num_vertices, 3))
        # Normal equations' right side: sum over triangles of area * F * grad(hat_i).
        contrib = np.einsum("tcd,tid->tic", g, self.grads) * self.areas[:, None, None]
        np.add.at(b, self.triangles.ravel(), contrib.reshape(-1, 3))
        out = a.copy()
        if self._factor is not None:
            rhs = b[self._free] - self._l_free_fixed @ a[self._fixed]
            out[self._free] = self._factor.solve(rhs)
        for part in self._floating:
            w = self.mass[part]
            shift = (w @ a[part] - w @ out[part]) / w.sum()
            out[part] += shift
        return out


def polar(gradients: ArrayLike) -> tuple[F64, F64]:
    """Polar decomposition F = R S of (N, 3, 3) matrices: rotations R (det +1) and symmetric
    S, from the SVD (a reflection is folded into S's smallest direction)."""
    f = np.asarray(gradients, dtype=np.float64)
    u, _, vt = np.linalg.svd(f)
    d = np.sign(np.linalg.det(u @ vt))
    d[d == 0] = 1.0
    u[:, :, 2] *= d[:, None]
    r = u @ vt
    s = np.transpose(r, (0, 2, 1)) @ f
    return r, 0.5 * (s + np.transpose(s, (0, 2, 1)))


def rotation_log(r: ArrayLike) -> F64:
    """(N, 3) rotation vectors (axis times angle in radians) of (N, 3, 3) rotations."""
    from scipy.spatial.transform import Rotation

    return np.asarray(Rotation.from_matrix(np.asarray(r)).as_rotvec())


def rotation_exp(v: ArrayLike) -> F64:
    """(N, 3, 3) rotations of (N, 3) rotation vectors."""
    from scipy.spatial.transform import Rotation

    return np.asarray(Rotation.from_rotvec(np.asarray(v)).as_matrix())


class Polar:
    """A deformation's gradients split for blending: rotation vectors (T', 3) and stretches
    (T', 3, 3)."""

    def __init__(self, gradients: ArrayLike) -> None:
        r, s = polar(gradients)
        self.log_rotation = rotation_log(r)
        self.stretch = s


def blend(terms: Sequence[tuple[Polar, float]]) -> F64:
    """Gradients (T', 3, 3) of the weighted combination of deformations: rotations blended
    in the log (so half a rotation is a rotation by half the angle, not a shrink) and
    stretches linearly about the identity: exp(sum w_k log R_k) (I + sum w_k (S_k - I))."""
    if not terms:
        raise InputError("blend: no deformations given")
    log_r = sum(w * p.log_rotation for p, w in terms)
    eye = np.eye(3)
    s = eye + sum(w * (p.stretch - eye) for p, w in terms)
    return rotation_exp(np.asarray(log_r)) @ np.asarray(s)
