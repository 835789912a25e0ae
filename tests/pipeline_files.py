"""Writes the built-in sample to disk as a TD would hand it to the CLI: a neutral OBJ with quads
(pairs of the sample's triangles that fan-split back into them), one OBJ per shape, a named
marker layout CSV, and takes written by independent libraries (ezc3d for C3D) or by hand."""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class ActorFiles:
    neutral: Path
    shapes: Path
    markers: Path
    num_polygons: int
    """Faces written to the neutral OBJ (quads and triangles)."""
    counts: NDArray[np.int64]
    """Corners of each written face, in file order."""
    names: list[str]
    """Marker names, in layout order."""


def quads_of(
    tris: NDArray[np.int64], uv_tris: NDArray[np.int64]
) -> list[tuple[list[int], list[int]]]:
    """Faces of a triangle list: consecutive pairs (a, b, c), (a, c, d) become the quad
    (a, b, c, d) when the UVs pair the same way (its fan split is the pair again)."""
    faces: list[tuple[list[int], list[int]]] = []
    k = 0
    while k < len(tris):
        if k + 1 < len(tris):
            (a, b, c), (a2, c2, d) = tris[k], tris[k + 1]
            (ua, ub, uc), (ua2, uc2, ud) = uv_tris[k], uv_tris[k + 1]
            if a == a2 and c == c2 and ua == ua2 and uc == uc2 and d not in (a, b, c):
                faces.append(([a, b, c, d], [ua, ub, uc, ud]))
                k += 2
                continue
        faces.append((list(tris[k]), list(uv_tris[k])))
        k += 1
    return faces


def write_obj_faces(
    path: Path,
    positions: NDArray[np.float64],
    uvs: NDArray[np.float64] | None,
    faces: list[tuple[list[int], list[int]]],
) -> None:
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in positions.tolist()]
    if uvs is not None:
        lines += [f"vt {u!r} {v!r}" for u, v in uvs.tolist()]
        lines += [
            "f " + " ".join(f"{i + 1}/{j + 1}" for i, j in zip(f, g, strict=True)) for f, g in faces
        ]
    else:
        lines += ["f " + " ".join(str(i + 1) for i in f) for f, _ in faces]
    path.write_text("\n".join(lines) + "\n")


def write_actor(folder: Path, sample, num_shapes: int | None = None) -> ActorFiles:  # type: ignore[no-untyped-def]
    """The sample's neutral (with quads), shapes and layout (names `sample.marker_names`) in
    `folder`."""
    folder.mkdir(parents=True, exist_ok=True)
    faces = quads_of(np.asarray(sample.triangles), np.asarray(sample.uv_triangles))
    neutral = folder / "neutral.obj"
    write_obj_faces(neutral, sample.neutral, sample.uvs, faces)
    shapes = folder / "shapes"
    shapes.mkdir(exist_ok=True)
    tri_faces = [(list(t), list(t)) for t in np.asarray(sample.triangles)]
    n = len(sample.names) if num_shapes is None else num_shapes
    for name, d in zip(sample.names[:n], sample.shapes[:n], strict=True):
        # Shape files need only the vertices; their faces are ignored (triangles here).
        write_obj_faces(shapes / f"{name}.obj", sample.neutral + d, None, tri_faces[:1])
    markers = folder / "markers.csv"
    rows = ["name,x,y,z"] + [
        f"{n},{x!r},{y!r},{z!r}"
        for n, (x, y, z) in zip(sample.marker_names, sample.markers_rest.tolist(), strict=True)
    ]
    markers.write_text("\n".join(rows) + "\n")
    counts = np.array([len(f) for f, _ in faces], dtype=np.int64)
    return ActorFiles(neutral, shapes, markers, len(faces), counts, list(sample.marker_names))


def build_actor(folder: Path, sample, num_shapes: int = 8) -> tuple[ActorFiles, Path]:  # type: ignore[no-untyped-def]
    """`write_actor`'s files in `folder` and their model `folder/actor.lgi`, built in cm
    through the CLI (`lgi build ... --units cm`)."""
    from lgi.app import cli

    actor = write_actor(folder, sample, num_shapes=num_shapes)
    model = folder / "actor.lgi"
    argv = ["build", actor.neutral, actor.shapes, actor.markers, "-o", model, "--units", "cm"]
    assert cli.main([str(a) for a in [*argv, "-q"]]) == 0
    return actor, model


def write_c3d(
    path: Path,
    frames: NDArray[np.float64],
    labels: list[str],
    fps: float,
    units: str,
    first_frame: int = 0,
) -> None:
    """A C3D take through ezc3d: `frames` (F, N, 3) already in `units`, NaN = missing
    (written with residual -1)."""
    import ezc3d

    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [fps]
    c["parameters"]["POINT"]["LABELS"]["value"] = list(labels)
    c["parameters"]["POINT"]["UNITS"]["value"] = [units]
    pts = np.ones((4, frames.shape[1], frames.shape[0]))
    pts[:3] = frames.transpose(2, 1, 0)
    c["data"]["points"] = pts
    res = np.zeros((1, frames.shape[1], frames.shape[0]))
    res[0][np.isnan(frames).any(axis=2).T] = -1.0
    c["data"]["meta_points"]["residuals"] = res
    c.write(str(path))


def lgi_cli(*args: str | Path) -> subprocess.CompletedProcess[str]:
    """Runs `lgi ARGS…` as a TD would, in a subprocess (warnings are errors)."""
    return subprocess.run(
        [sys.executable, "-m", "lgi.app.main", *map(str, args)],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONWARNINGS": "error"},
        timeout=600,
    )


def spiked_sample_take(sample, model):  # type: ignore[no-untyped-def]
    """The sample's performance with marker m010 pushed 1.5 cm out along z in frames 40-42."""
    frames = np.asarray(sample.performance).copy()
    frames[40:43, list(model.marker_names).index("m010"), 2] += 1.5
    return frames


def write_solve(  # type: ignore[no-untyped-def]
    path: Path, model, frames, noise: float | None, fps: float = 30.0, start: int = 100
) -> Path:
    """`frames` solved with `model` (noise-aware with `noise`) as a solved-take npz at `fps`
    from time code `start`, the take's markers kept, and kept as given (no repair: what a
    finding reads is in the residuals)."""
    from lgi.io.result import write_result_npz
    from lgi.io.topology import topology

    res = model.solve(frames, marker_noise=noise, repair=False, quiet=True)
    return write_result_npz(
        path,
        topology(model.dataset),
        res.vertices,
        res.bundle_residuals,
        res.missing,
        list(model.marker_names),
        fps=fps,
        start=start,
        units="cm",
        markers=frames,
    )
