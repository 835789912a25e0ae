"""Results out: point caches a DCC opens. A USD point cache (`UsdCache`, `write_usd`: one
`UsdGeom.Mesh` with the neutral's source polygons, UVs as the `st` primvar, time-sampled
points), an OBJ sequence with the same polygons (`write_obj_sequence`), a solved take as
`.npz` (`write_result_npz` / `read_result_npz`, which `lgi export` converts), and single OBJs.

Faces are the neutral's own (quads and n-gons as its OBJ had them, `Dataset.polygons`); a
dataset without them (arrays, glTF, `.npz`) exports its triangles.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from lgi._lgi import Dataset
from lgi.errors import InputError
from lgi.takes import METERS_PER_UNIT, normalize_unit

if TYPE_CHECKING:
    from lgi.model import Model

I64 = NDArray[np.int64]
F64 = NDArray[np.float64]

__all__ = [
    "RESULT_NPZ_KEYS",
    "Result",
    "Topology",
    "UsdCache",
    "read_result_npz",
    "topology",
    "write_obj",
    "write_obj_sequence",
    "write_result_npz",
    "write_sequence_npz",
    "write_usd",
]


@dataclass(frozen=True)
class Topology:
    """Faces of the exported mesh: `counts` (P,) corners per face, `indices` (sum counts,)
    vertex per corner, and optionally `uvs` (U, 2) with `uv_indices` (one per corner)."""

    num_vertices: int
    counts: I64
    indices: I64
    uvs: F64 | None = None
    uv_indices: I64 | None = None

    @property
    def num_faces(self) -> int:
        return int(self.counts.shape[0])


def topology(dataset: Dataset) -> Topology:
    """The dataset neutral's source polygons (or its triangles when it has none) and UVs."""
    polys = dataset.polygons
    has_uv = np.asarray(dataset.uv_triangles).size > 0
    if polys is not None:
        counts, indices, uv_idx = polys
        return Topology(
            dataset.num_vertices,
            counts,
            indices,
            dataset.uvs if has_uv else None,
            uv_idx if has_uv else None,
        )
    tris = np.asarray(dataset.triangles, dtype=np.int64)
    return Topology(
        dataset.num_vertices,
        np.full(tris.shape[0], 3, dtype=np.int64),
        tris.ravel(),
        dataset.uvs if has_uv else None,
        np.asarray(dataset.uv_triangles, dtype=np.int64).ravel() if has_uv else None,
    )


def _frames(vertices: Any, num_vertices: int, what: str) -> NDArray[np.floating[Any]]:
    """`vertices` as (F, V, 3) floats (a (V, 3) mesh gives F = 1), checked finite."""
    v = np.asarray(vertices)
    if v.ndim == 2:
        v = v[None]
    if v.ndim != 3 or v.shape[1:] != (num_vertices, 3) or v.dtype.kind != "f":
        raise InputError(
            f"{what}: expected float vertices (F, {num_vertices}, 3), got {v.dtype} {v.shape}"
        )
    if not np.isfinite(v).all():
        raise InputError(f"{what}: vertices are not all finite")
    return v


def _out_path(path: str | os.PathLike[str], what: str) -> Path:
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{what} {p}: is a folder, expected a file path")
    if not p.parent.is_dir():
        raise InputError(f"{what} {p}: the folder {p.parent} does not exist")
    return p


def _new_stage(usd: Any, sdf: Any, path: Path) -> Any:
    """A new stage whose root layer will be saved to `path` (Save is ~2.5x faster than
    exporting an in-memory layer). A layer of that path already open in this process (an
    earlier cache, a stage a caller holds) is emptied and reused: USD keeps one per path."""
    layer = sdf.Layer.Find(str(path))
    if layer is not None:
        layer.Clear()
        return usd.Stage.Open(layer)
    try:
        return usd.Stage.CreateNew(str(path))
    except Exception as e:  # pxr raises Tf.ErrorException (a RuntimeError) for I/O failures
        raise InputError(f"USD output {path}: cannot be created: {e}") from None


def define_usd_mesh(stage: Any, prim_path: str, topo: Topology) -> Any:
    """A `UsdGeom.Mesh` at `prim_path` with `topo`'s faces (subdivisionScheme none: the
    points are the result, not a cage) and its UVs as the face-varying indexed primvar `st`;
    no points yet."""
    from pxr import Sdf, UsdGeom, Vt

    mesh = UsdGeom.Mesh.Define(stage, prim_path)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(topo.counts.astype(np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(topo.indices.astype(np.int32)))
    if topo.uvs is not None and topo.uv_indices is not None:
        st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
            "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying
        )
        st.Set(Vt.Vec2fArray.FromNumpy(np.asarray(topo.uvs, dtype=np.float32)))
        st.SetIndices(Vt.IntArray.FromNumpy(topo.uv_indices.astype(np.int32)))
    return mesh


class UsdCache:
    """A USD point cache written chunk by chunk: `add(vertices)` appends frames (time codes
    `start`, `start + 1`, ...), `close()` writes the file (its format by suffix: `.usd`/`.usdc`
    binary crate, `.usda` text). The stage: default prim `/Face` (Xform) holding the
    `UsdGeom.Mesh` `/Face/Mesh` (subdivisionScheme none: the points are the result, not a
    cage), UVs as the face-varying indexed primvar `st`, `timeCodesPerSecond` = `fps`,
    `metersPerUnit` from `units` (left at USD's default when None), Y up. Optional per-frame
    attributes on the mesh: `lgi:jawTheta` (float3: open, lateral, forward),
    `lgi:markerResidual` (float[] per marker), and the head transform when known
    (`lgi:headRotation`, matrix3d with the rotation's rows as its rows, and
    `lgi:headTranslation`, double3: capture = R rest + t, `lgi.stabilize.align`)."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        topo: Topology,
        *,
        fps: float,
        units: str | None = None,
        start: int = 0,
    ) -> None:
        try:
            from pxr import Gf, Sdf, Usd, UsdGeom, Vt
        except ImportError:  # pragma: no cover - usd-core is a dependency
            raise InputError(
                "writing USD needs the usd-core package (pip install usd-core)"
            ) from None
        if not np.isfinite(fps) or fps <= 0:
            raise InputError(f"fps must be a positive number, got {fps}")
        self._path = _out_path(path, "USD output")
        if self._path.suffix.lower() not in (".usd", ".usdc", ".usda"):
            raise InputError(f"USD output {self._path}: the suffix must be .usd, .usdc or .usda")
        self._Usd, self._Vt, self._Gf = Usd, Vt, Gf
        self._topo = topo
        self._next = int(start)
        self._start = int(start)
        stage = _new_stage(Usd, Sdf, self._path)
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
        if units is not None:
            UsdGeom.SetStageMetersPerUnit(stage, METERS_PER_UNIT[normalize_unit(units, "units")])
        stage.SetTimeCodesPerSecond(float(fps))
        stage.SetFramesPerSecond(float(fps))
        root = UsdGeom.Xform.Define(stage, "/Face")
        stage.SetDefaultPrim(root.GetPrim())
        mesh = define_usd_mesh(stage, "/Face/Mesh", topo)
        self._stage, self._mesh = stage, mesh
        self._points = mesh.GetPointsAttr()
        self._extent = mesh.CreateExtentAttr()
        self._jaw = None
        self._residual = None
        self._head: tuple[Any, Any] | None = None
        self._sdf = Sdf

    @property
    def num_frames(self) -> int:
        return self._next - self._start

    def add(
        self,
        vertices: Any,
        *,
        jaw_theta: Any | None = None,
        marker_residuals: Any | None = None,
        head_rotations: Any | None = None,
        head_translations: Any | None = None,
    ) -> None:
        """Appends frames (F, V, 3) (or one (V, 3) mesh), with optional (F, 3) jaw poses,
        (F, B) marker residuals and the head's (F, 3, 3) rotations and (F, 3) translations."""
        v = _frames(vertices, self._topo.num_vertices, "UsdCache.add")
        n = v.shape[0]
        jaw = None if jaw_theta is None else np.asarray(jaw_theta, dtype=np.float64)
        if jaw is not None and jaw.shape != (n, 3):
            raise InputError(f"UsdCache.add: jaw_theta must be ({n}, 3), got {jaw.shape}")
        res = None if marker_residuals is None else np.asarray(marker_residuals, dtype=np.float64)
        if res is not None and (res.ndim != 2 or res.shape[0] != n):
            raise InputError(f"UsdCache.add: marker_residuals must be ({n}, B), got {res.shape}")
        rot = None if head_rotations is None else np.asarray(head_rotations, dtype=np.float64)
        shift = None if head_translations is None else np.asarray(head_translations, dtype=float)
        if (rot is None) != (shift is None) or (
            rot is not None
            and shift is not None
            and (rot.shape != (n, 3, 3) or shift.shape != (n, 3))
        ):
            raise InputError(
                f"UsdCache.add: the head transform needs rotations ({n}, 3, 3) and "
                f"translations ({n}, 3) together"
            )
        Usd, Vt, Gf, Sdf = self._Usd, self._Vt, self._Gf, self._sdf
        if rot is not None and self._head is None:
            prim = self._mesh.GetPrim()
            self._head = (
                prim.CreateAttribute("lgi:headRotation", Sdf.ValueTypeNames.Matrix3d),
                prim.CreateAttribute("lgi:headTranslation", Sdf.ValueTypeNames.Double3),
            )
        if jaw is not None and self._jaw is None:
            self._jaw = self._mesh.GetPrim().CreateAttribute(
                "lgi:jawTheta", Sdf.ValueTypeNames.Float3
            )
        if res is not None and self._residual is None:
            self._residual = self._mesh.GetPrim().CreateAttribute(
                "lgi:markerResidual", Sdf.ValueTypeNames.FloatArray
            )
        for i in range(n):
            t = Usd.TimeCode(self._next)
            p = np.ascontiguousarray(v[i], dtype=np.float32)
            self._points.Set(Vt.Vec3fArray.FromNumpy(p), t)
            # Reduced over a (3, V) copy: numpy's axis-0 reduce of (V, 3) is ~15x slower.
            pt = np.ascontiguousarray(p.T)
            lo, hi = pt.min(axis=1), pt.max(axis=1)
            self._extent.Set(
                Vt.Vec3fArray([Gf.Vec3f(*map(float, lo)), Gf.Vec3f(*map(float, hi))]), t
            )
            if jaw is not None and self._jaw is not None:
                self._jaw.Set(Gf.Vec3f(*map(float, jaw[i])), t)
            if res is not None and self._residual is not None:
                self._residual.Set(Vt.FloatArray.FromNumpy(res[i].astype(np.float32)), t)
            if rot is not None and shift is not None and self._head is not None:
                self._head[0].Set(Gf.Matrix3d(*map(float, rot[i].ravel())), t)
                self._head[1].Set(Gf.Vec3d(*map(float, shift[i])), t)
            self._next += 1

    def close(self) -> Path:
        """Writes the file (the frames added so far) and returns its path."""
        if self._next == self._start:
            raise InputError(f"USD output {self._path}: no frames were added")
        self._stage.SetStartTimeCode(self._start)
        self._stage.SetEndTimeCode(self._next - 1)
        try:
            saved = self._stage.GetRootLayer().Save()
        except Exception as e:  # pxr's Tf.ErrorException: a full disk, a vanished folder
            raise InputError(f"USD output {self._path}: could not be written: {e}") from None
        if not saved:
            raise InputError(f"USD output {self._path}: could not be written")
        return self._path

    def __enter__(self) -> UsdCache:
        return self

    def __exit__(self, exc_type: object, *_: object) -> None:
        if exc_type is None:
            self.close()


def write_usd(
    path: str | os.PathLike[str],
    source: Topology | Dataset | Model,
    frames: Any,
    *,
    fps: float,
    units: str | None = None,
    start: int = 0,
    jaw_theta: Any | None = None,
) -> Path:
    """Writes a USD point cache (`UsdCache`). `source` gives the faces: a `Topology`, a
    dataset (`topology`), or a model (its dataset's; `units` then default to the model's).
    `frames`: vertices (F, V, 3), a `SolveResult` (its vertices, jaw poses and marker
    residuals), or an iterable of (F_i, V, 3) chunks."""
    from lgi.model import Model, SolveResult

    if isinstance(source, Model):
        units = source.units if units is None else units
        source = source.dataset
    t = source if isinstance(source, Topology) else topology(source)
    cache = UsdCache(path, t, fps=fps, units=units, start=start)
    if isinstance(frames, SolveResult):
        cache.add(
            frames.vertices, jaw_theta=frames.jaw_theta, marker_residuals=frames.bundle_residuals
        )
    elif isinstance(frames, np.ndarray):
        cache.add(frames, jaw_theta=jaw_theta)
    else:
        for chunk in frames:
            cache.add(chunk)
    return cache.close()


def _face_lines(topo: Topology) -> str:
    """The `vt` and `f` lines of `topo` (1-based), the same for every frame."""
    ends = np.cumsum(topo.counts)
    starts = ends - topo.counts
    idx = (topo.indices + 1).astype(str)
    lines: list[str] = []
    if topo.uvs is not None and topo.uv_indices is not None:
        lines += [f"vt {a:.9g} {b:.9g}" for a, b in np.asarray(topo.uvs)]
        uvi = (topo.uv_indices + 1).astype(str)
        corners = np.char.add(np.char.add(idx, "/"), uvi)
    else:
        corners = idx
    lines += ["f " + " ".join(corners[s:e]) for s, e in zip(starts, ends, strict=True)]
    return "\n".join(lines) + "\n"


def write_obj_sequence(
    folder: str | os.PathLike[str],
    topo: Topology | Dataset,
    vertices: Any,
    *,
    name: str = "frame",
    start: int = 0,
    digits: int = 4,
) -> list[Path]:
    """Writes one OBJ per frame into `folder` (created), `{name}.{frame:0{digits}d}.obj` from
    frame `start`, each with the source polygons and UVs; returns the paths."""
    t = topo if isinstance(topo, Topology) else topology(topo)
    v = _frames(vertices, t.num_vertices, "write_obj_sequence")
    out = Path(folder)
    if out.exists() and not out.is_dir():
        raise InputError(f"OBJ sequence output {out}: is a file, expected a folder")
    out.mkdir(parents=True, exist_ok=True)
    faces = _face_lines(t)
    template = "v %.9g %.9g %.9g\n" * t.num_vertices
    paths = []
    for i in range(v.shape[0]):
        p = out / f"{name}.{start + i:0{digits}d}.obj"
        p.write_text("# written by lgi\n" + template % tuple(v[i].ravel().tolist()) + faces)
        paths.append(p)
    return paths


def write_obj(
    path: str | os.PathLike[str],
    vertices: NDArray[np.float64],
    triangles: NDArray[np.int64],
    uvs: NDArray[np.float64] | None = None,
    uv_triangles: NDArray[np.int64] | None = None,
) -> None:
    """Writes one triangle mesh as OBJ (`v`, optional `vt`, `f v/vt`), 1-based indices."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64) + 1
    lines = ["# written by lgi", *(f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in v)]
    if uvs is not None and uv_triangles is not None and len(uv_triangles) == len(t):
        lines += (f"vt {a:.9g} {b:.9g}" for a, b in np.asarray(uvs))
        ut = np.asarray(uv_triangles, dtype=np.int64) + 1
        lines += (f"f {a}/{d} {b}/{e} {c}/{f}" for (a, b, c), (d, e, f) in zip(t, ut, strict=True))
    else:
        lines += (f"f {a} {b} {c}" for a, b, c in t)
    Path(path).write_text("\n".join(lines) + "\n")


def write_sequence_npz(path: str | os.PathLike[str], **arrays: NDArray[np.generic]) -> None:
    """Writes named arrays (e.g. `vertices` (F, V, 3), `bundle_residuals` (F, B)) to `.npz`."""
    named: dict[str, Any] = dict(arrays)
    np.savez_compressed(Path(path), **named)


RESULT_NPZ_KEYS = (
    "vertices",
    "bundle_residuals",
    "missing",
    "marker_names",
    "fps",
    "start",
    "units",
    "face_counts",
    "face_indices",
    "uvs",
    "uv_indices",
    "jaw_theta",
)
"""Arrays of a solved take `.npz` (`write_result_npz`): `vertices` (F, V, 3) float32,
`bundle_residuals` (F, B) float, `missing` (F, B) bool, `marker_names` (B,) str, `fps` (NaN
when unknown), `start` (time code of the first frame), `units` ('' when unknown), the faces
(`face_counts`, `face_indices`, and `uvs`/`uv_indices`, empty without UVs), and `jaw_theta`
(F, 3; absent without a jaw)."""


@dataclass(frozen=True)
class Result:
    """A solved take read back (`read_result_npz`)."""

    vertices: NDArray[np.float32]
    bundle_residuals: F64
    missing: NDArray[np.bool_]
    marker_names: list[str]
    fps: float | None
    start: int
    units: str | None
    topology: Topology
    jaw_theta: F64 | None = None


def write_result_npz(
    path: str | os.PathLike[str],
    topo: Topology,
    vertices: Any,
    bundle_residuals: Any,
    missing: Any,
    marker_names: list[str],
    *,
    fps: float | None,
    start: int = 0,
    units: str | None = None,
    jaw_theta: Any | None = None,
) -> Path:
    """Writes a solved take (`RESULT_NPZ_KEYS`) that `read_result_npz` and `lgi export` read."""
    p = _out_path(path, "npz output")
    v = _frames(vertices, topo.num_vertices, "write_result_npz")
    arrays: dict[str, Any] = {
        "vertices": v.astype(np.float32),
        "bundle_residuals": np.asarray(bundle_residuals, dtype=np.float64),
        "missing": np.asarray(missing, dtype=bool),
        "marker_names": np.array(marker_names, dtype=str),
        "fps": np.float64(np.nan if fps is None else fps),
        "start": np.int64(start),
        "units": np.str_(units or ""),
        "face_counts": topo.counts,
        "face_indices": topo.indices,
        "uvs": np.zeros((0, 2)) if topo.uvs is None else np.asarray(topo.uvs),
        "uv_indices": np.zeros(0, np.int64) if topo.uv_indices is None else topo.uv_indices,
    }
    if jaw_theta is not None:
        arrays["jaw_theta"] = np.asarray(jaw_theta, dtype=np.float64)
    with open(p, "wb") as fh:  # a file object: numpy would append '.npz' to another suffix
        np.savez_compressed(fh, **arrays)
    return p


def read_result_npz(path: str | os.PathLike[str]) -> Result:
    """Reads a solved take written by `write_result_npz`; `InputError` naming the file and
    the array for anything else."""
    p = os.fspath(path)
    if not os.path.isfile(p):
        raise InputError(f"{p}: no such result file")
    try:
        with np.load(p, allow_pickle=False) as z:
            if not isinstance(z, np.lib.npyio.NpzFile):  # pragma: no cover - .npy given
                raise InputError(f"{p}: not an .npz archive")
            absent = [k for k in RESULT_NPZ_KEYS[:-1] if k not in z.files]
            if absent:
                raise InputError(
                    f"{p}: not a solved take (written by lgi solve -o *.npz): missing {absent}"
                )
            a = {k: z[k] for k in z.files}
    except InputError:
        raise
    except Exception as e:
        raise InputError(f"{p}: not a readable .npz archive: {e}") from None
    v = a["vertices"]
    counts, indices = a["face_counts"].astype(np.int64), a["face_indices"].astype(np.int64)
    if v.ndim != 3 or v.shape[2] != 3:
        raise InputError(f"{p}: 'vertices' must be (F, V, 3), got {v.shape}")
    nv = v.shape[1]
    if counts.sum() != indices.size or (
        indices.size and (indices.min() < 0 or indices.max() >= nv)
    ):
        raise InputError(
            f"{p}: 'face_counts'/'face_indices' do not describe faces of {nv} vertices"
        )
    has_uv = a["uv_indices"].size > 0
    topo = Topology(
        nv,
        counts,
        indices,
        a["uvs"].astype(np.float64) if has_uv else None,
        a["uv_indices"].astype(np.int64) if has_uv else None,
    )
    fps = float(a["fps"])
    units = str(a["units"]) or None
    return Result(
        vertices=v,
        bundle_residuals=a["bundle_residuals"],
        missing=a["missing"],
        marker_names=[str(x) for x in a["marker_names"]],
        fps=fps if np.isfinite(fps) else None,
        start=int(a["start"]),
        units=units,
        topology=topo,
        jaw_theta=a.get("jaw_theta"),
    )
