"""Mesh-quality measures of a deformed mesh against its rest mesh, the figures that show
blendshape artefacts: triangle area and edge-length distortion, flipped triangles, the volume a
patch of surface encloses with a fixed point (its local volume change), and triangle pairs
that cross each other (self-intersections, e.g. where lips pass through one another)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

__all__ = [
    "area_ratios",
    "cone_volume",
    "edge_ratios",
    "edges",
    "flipped",
    "self_intersections",
]


def _normals(x: F64, tris: I64) -> F64:
    return np.cross(x[tris[:, 1]] - x[tris[:, 0]], x[tris[:, 2]] - x[tris[:, 0]])


def area_ratios(rest: ArrayLike, deformed: ArrayLike, triangles: ArrayLike) -> F64:
    """(T,) each triangle's area on `deformed` over its area on `rest`."""
    tris = np.asarray(triangles, dtype=np.int64)
    a0 = np.linalg.norm(_normals(np.asarray(rest, np.float64), tris), axis=1)
    a1 = np.linalg.norm(_normals(np.asarray(deformed, np.float64), tris), axis=1)
    return np.asarray(a1 / np.maximum(a0, 1e-300))


def flipped(rest: ArrayLike, deformed: ArrayLike, triangles: ArrayLike) -> NDArray[np.bool_]:
    """(T,) True where a triangle's normal turned by more than 90 degrees."""
    tris = np.asarray(triangles, dtype=np.int64)
    n0 = _normals(np.asarray(rest, np.float64), tris)
    n1 = _normals(np.asarray(deformed, np.float64), tris)
    return np.asarray(np.einsum("ij,ij->i", n0, n1) < 0)


def edges(triangles: ArrayLike) -> I64:
    """(E, 2) the unique edges of a triangle list (smaller vertex first)."""
    tris = np.asarray(triangles, dtype=np.int64)
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    return np.asarray(np.unique(np.sort(e, axis=1), axis=0))


def edge_ratios(rest: ArrayLike, deformed: ArrayLike, triangles: ArrayLike) -> F64:
    """(E,) each edge's length on `deformed` over its length on `rest` (`edges` order)."""
    e = edges(triangles)
    x0, x1 = np.asarray(rest, np.float64), np.asarray(deformed, np.float64)
    l0 = np.linalg.norm(x0[e[:, 1]] - x0[e[:, 0]], axis=1)
    l1 = np.linalg.norm(x1[e[:, 1]] - x1[e[:, 0]], axis=1)
    return np.asarray(l1 / np.maximum(l0, 1e-300))


def cone_volume(points: ArrayLike, triangles: ArrayLike, apex: ArrayLike) -> float:
    """Signed volume of the cone from `apex` over the triangles (the enclosed volume for a
    closed, outward-oriented surface, whatever the apex): a patch's local volume."""
    x = np.asarray(points, np.float64) - np.asarray(apex, np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    return float(np.einsum("ij,ij->i", x[t[:, 0]], np.cross(x[t[:, 1]], x[t[:, 2]])).sum() / 6)


def self_intersections(points: ArrayLike, triangles: ArrayLike, chunk: int = 20000) -> I64:
    """(K, 2) pairs of triangles (i < j, sharing no vertex) that cross: an edge of one passes
    through the other (Moller-Trumbore on segments), after a bounding-box test."""
    x = np.asarray(points, np.float64)
    tris = np.asarray(triangles, dtype=np.int64)
    lo, hi = x[tris].min(axis=1), x[tris].max(axis=1)
    n = len(tris)
    found: list[I64] = []
    # Candidate pairs by overlapping boxes, i < j, in row blocks to bound memory.
    block = max(1, chunk // max(1, n))
    for start in range(0, n, block):
        rows = np.arange(start, min(n, start + block))
        overlap = (lo[rows, None] <= hi[None]).all(axis=2) & (hi[rows, None] >= lo[None]).all(
            axis=2
        )
        i, j = np.nonzero(overlap)
        i = rows[i]
        keep = i < j
        i, j = i[keep], j[keep]
        shared = (tris[i][:, :, None] == tris[j][:, None, :]).any(axis=(1, 2))
        i, j = i[~shared], j[~shared]
        if i.size == 0:
            continue
        hit = _edges_cross(x, tris[i], tris[j]) | _edges_cross(x, tris[j], tris[i])
        found.append(np.stack([i[hit], j[hit]], axis=1))
    return np.concatenate(found) if found else np.zeros((0, 2), dtype=np.int64)


def _edges_cross(x: F64, a: I64, b: I64) -> NDArray[np.bool_]:
    """(P,) whether an edge of triangle a[p] crosses triangle b[p]."""
    v0, v1, v2 = x[b[:, 0]], x[b[:, 1]], x[b[:, 2]]
    e1, e2 = v1 - v0, v2 - v0
    out = np.zeros(len(a), dtype=bool)
    for s, t in ((0, 1), (1, 2), (2, 0)):
        p, q = x[a[:, s]], x[a[:, t]]
        d = q - p
        h = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, h)
        ok = np.abs(det) > 1e-18
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        sv = p - v0
        u = inv * np.einsum("ij,ij->i", sv, h)
        qv = np.cross(sv, e1)
        v = inv * np.einsum("ij,ij->i", d, qv)
        tt = inv * np.einsum("ij,ij->i", e2, qv)
        out |= ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (tt >= 0) & (tt <= 1)
    return out
