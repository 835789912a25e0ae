"""A closed test mesh with closed-form facts (volume, rotations) for the ARAP and
deformation-transfer tests."""

from __future__ import annotations

import numpy as np


def ellipsoid(n: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """A closed, outward-oriented ellipsoid (semi-axes 3, 2, 1) centred at (4, 1, 0): a UV
    sphere with one vertex at each pole."""
    rows = []
    for i in range(1, n):
        th = np.pi * i / n
        for j in range(2 * n):
            ph = np.pi * j / n
            rows.append([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])
    pts = np.array([[0.0, 0.0, 1.0], *rows, [0.0, 0.0, -1.0]])
    ring = lambda i, j: 1 + (i - 1) * 2 * n + (j % (2 * n))  # noqa: E731
    tris = []
    for j in range(2 * n):
        tris.append([0, ring(1, j), ring(1, j + 1)])
        tris.append([len(pts) - 1, ring(n - 1, j + 1), ring(n - 1, j)])
    for i in range(1, n - 1):
        for j in range(2 * n):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1)
            tris += [[a, c, b], [b, c, d]]
    return pts * [3.0, 2.0, 1.0] + [4.0, 1.0, 0.0], np.array(tris)


def volume(x: np.ndarray, tris: np.ndarray) -> float:
    """Enclosed volume (divergence theorem: signed tets against the origin)."""
    return float(
        np.einsum("ij,ij->i", x[tris[:, 0]], np.cross(x[tris[:, 1]], x[tris[:, 2]])).sum() / 6
    )


def rot_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
