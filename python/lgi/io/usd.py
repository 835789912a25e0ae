"""USD point caches out: `UsdCache` (chunk by chunk) and `write_usd` write one `UsdGeom.Mesh`
with the neutral's source polygons, UVs as the `st` primvar and time-sampled points, so a DCC
opens the solved take. `new_stage` and `define_usd_mesh` are shared with the USD rig writer
(`lgi.io.rig`)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from lgi.errors import FileWriteError, InputError
from lgi.io.atomic import temporary_beside
from lgi.io.paths import output_file
from lgi.io.result import Result
from lgi.io.served import is_a
from lgi.io.settings import SolveSettings
from lgi.io.topology import Topology, topology, vertex_frames
from lgi.io.units import METERS_PER_UNIT, normalize_unit

if TYPE_CHECKING:
    from lgi.data.dataset import Dataset
    from lgi.solve.model import Model

__all__ = ["UsdCache", "define_usd_mesh", "new_stage", "read_usd_cache", "write_usd"]


def new_stage(usd: Any, sdf: Any, path: Path) -> Any:
    """A new stage whose root layer will be saved to `path` (saving it is faster than
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


def save_stage(stage: Any, tmp: Path, target: Path) -> None:
    """Saves a stage created on the temporary `tmp` (`lgi.io.atomic.temporary_beside`) and
    renames it onto `target`; on any failure the temporary is removed and the target left as
    it was."""
    try:
        try:
            saved = stage.GetRootLayer().Save()
        except Exception as e:  # pxr's Tf.ErrorException: a full disk, a vanished folder
            raise FileWriteError(
                f"USD output {target}: could not be written: {_pxr_words(e)}"
            ) from None
        if not saved:
            raise FileWriteError(f"USD output {target}: could not be written")
        try:
            os.replace(tmp, target)
        except OSError as e:
            raise FileWriteError(
                f"USD output {target}: could not be written: {e.strerror}"
            ) from None
    finally:
        Path(tmp).unlink(missing_ok=True)


def _pxr_words(e: Exception) -> str:
    """The useful end of a pxr error ('Permission denied', 'No space left on device'), not its
    C++ function names and source lines."""
    text = str(e)
    for known in ("Permission denied", "No space left on device", "Read-only file system"):
        if known.lower() in text.lower():
            return known.lower()
    return text.strip().splitlines()[-1] if text.strip() else "unknown reason"


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
    `lgi:headTranslation`, double3: capture = R rest + t, `lgi.capture.stabilize.align`)."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        topo: Topology,
        *,
        fps: float,
        units: str | None = None,
        start: int = 0,
        up: str = "y",
        marker_names: list[str] | None = None,
        settings: SolveSettings | None = None,
    ) -> None:
        try:
            from pxr import Gf, Sdf, Usd, UsdGeom, Vt
        except ImportError:  # pragma: no cover - usd-core is a dependency
            raise InputError(
                "writing USD needs the usd-core package (pip install usd-core)"
            ) from None
        if not np.isfinite(fps) or fps <= 0:
            raise InputError(f"fps must be a positive number, got {fps}")
        self._path = output_file(path, "USD output")
        if self._path.suffix.lower() not in (".usd", ".usdc", ".usda"):
            raise InputError(f"USD output {self._path}: the suffix must be .usd, .usdc or .usda")
        self._Usd, self._Vt, self._Gf = Usd, Vt, Gf
        self._topo = topo
        self._next = int(start)
        self._start = int(start)
        # Written under a temporary name and renamed at `close`: an interrupted or failed
        # write leaves nothing at the final path.
        self._tmp = temporary_beside(self._path)
        stage = new_stage(Usd, Sdf, self._tmp)
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if up == "z" else UsdGeom.Tokens.y)
        if units is not None:
            UsdGeom.SetStageMetersPerUnit(stage, METERS_PER_UNIT[normalize_unit(units, "units")])
        stage.SetTimeCodesPerSecond(float(fps))
        stage.SetFramesPerSecond(float(fps))
        root = UsdGeom.Xform.Define(stage, "/Face")
        stage.SetDefaultPrim(root.GetPrim())
        mesh = define_usd_mesh(stage, "/Face/Mesh", topo)
        self._stage, self._mesh = stage, mesh
        self._points = mesh.GetPointsAttr()
        if marker_names:  # what `lgi:markerResidual`'s entries are (read_usd_cache)
            mesh.GetPrim().CreateAttribute(
                "lgi:markerNames", Sdf.ValueTypeNames.StringArray, custom=True
            ).Set(Vt.StringArray(list(marker_names)))
        if settings is not None:  # how the take was solved (read_usd_cache, lgi report)
            self.record(settings)
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
        v = vertex_frames(vertices, self._topo.num_vertices, "UsdCache.add")
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

    def record(self, settings: SolveSettings) -> None:
        """Records how the take was solved (`lgi:solveSettings`, read back by
        `read_usd_cache`), replacing what was recorded before."""
        from pxr import Sdf

        self._mesh.GetPrim().CreateAttribute(
            "lgi:solveSettings", Sdf.ValueTypeNames.String, custom=True
        ).Set(settings.to_json())

    def close(self) -> Path:
        """Writes the file (the frames added so far) and returns its path."""
        if self._next == self._start:
            raise InputError(f"USD output {self._path}: no frames were added")
        self._stage.SetStartTimeCode(self._start)
        self._stage.SetEndTimeCode(self._next - 1)
        save_stage(self._stage, self._tmp, self._path)
        return self._path

    def discard(self) -> None:
        """Drops the frames: nothing is written (after a failure or an interrupt)."""
        self._tmp.unlink(missing_ok=True)

    def __enter__(self) -> UsdCache:
        return self

    def __exit__(self, exc_type: object, *_: object) -> None:
        if exc_type is None:
            self.close()
        else:
            self.discard()


def solve_settings(prim: Any, path: str) -> SolveSettings | None:
    """The `lgi:solveSettings` a mesh prim of a cache `lgi solve` wrote keeps (None when it has
    none); `InputError` naming `path` for a damaged record."""
    attr = prim.GetAttribute("lgi:solveSettings")
    if not attr or not attr.Get():
        return None
    return SolveSettings.from_json(str(attr.Get()), f"{path}: lgi:solveSettings")


def stage_units(stage: Any) -> str | None:
    """The unit name of a USD stage's authored `metersPerUnit` ('cm', 'mm', ...), None when it
    is not authored or names no unit lgi knows."""
    from pxr import UsdGeom

    if not stage.HasAuthoredMetadata("metersPerUnit"):
        return None
    mpu = UsdGeom.GetStageMetersPerUnit(stage)
    return next((u for u, m in METERS_PER_UNIT.items() if abs(m - mpu) <= 1e-9 * m), None)


def read_usd_cache(path: str | os.PathLike[str]) -> Result:
    """A USD point cache `lgi solve` wrote, as a solved take (`lgi report`, `lgi view`): the
    mesh's time-sampled points, faces and UVs, `lgi:markerResidual` (which it must have),
    `lgi:markerNames` (else `m000`, ...), `lgi:jawTheta`, the rate, first time code and unit.
    A USD cache keeps no missing-marker flags and no marker positions."""
    from pxr import Usd, UsdGeom

    p = os.fspath(path)
    if not os.path.isfile(p):
        raise InputError(f"{p}: no such USD file")
    try:
        stage = Usd.Stage.Open(p)
    except Exception:  # pxr's Tf.ErrorException for unreadable layers
        stage = None
    if stage is None:
        raise InputError(f"{p}: not a readable USD file")
    prim = stage.GetPrimAtPath("/Face/Mesh")
    if not prim or not prim.IsA(UsdGeom.Mesh):
        prim = next((q for q in stage.Traverse() if q.IsA(UsdGeom.Mesh)), None)
    if prim is None:
        raise InputError(f"{p}: holds no mesh")
    mesh = UsdGeom.Mesh(prim)
    times = mesh.GetPointsAttr().GetTimeSamples()
    res_attr = prim.GetAttribute("lgi:markerResidual")
    if not times or not res_attr or not res_attr.GetTimeSamples():
        raise InputError(
            f"{p}: not a solved take: a point cache written by lgi solve has time-sampled "
            "points and lgi:markerResidual"
        )
    vertices = np.array([np.asarray(mesh.GetPointsAttr().Get(t)) for t in times], np.float32)
    residuals = np.array([np.asarray(res_attr.Get(t), dtype=np.float64) for t in times])
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(), dtype=np.int64)
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(), dtype=np.int64)
    st = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st")
    uvs = uv_idx = None
    if st and st.IsIndexed():
        uvs = np.asarray(st.Get(), dtype=np.float64)
        uv_idx = np.asarray(st.GetIndices(), dtype=np.int64)
    names_attr = prim.GetAttribute("lgi:markerNames")
    names = list(names_attr.Get()) if names_attr and names_attr.Get() else []
    if len(names) != residuals.shape[1]:
        names = [f"m{k:03d}" for k in range(residuals.shape[1])]
    jaw_attr = prim.GetAttribute("lgi:jawTheta")
    jaw = (
        np.array([np.asarray(jaw_attr.Get(t), dtype=np.float64) for t in times])
        if jaw_attr and jaw_attr.GetTimeSamples()
        else None
    )
    return Result(
        vertices=vertices,
        bundle_residuals=residuals,
        missing=np.zeros(residuals.shape, dtype=bool),
        marker_names=names,
        fps=float(stage.GetTimeCodesPerSecond()),
        start=int(times[0]),
        units=stage_units(stage),
        topology=Topology(vertices.shape[1], counts, indices, uvs, uv_idx),
        jaw_theta=jaw,
        settings=solve_settings(prim, p),
    )


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
    from lgi._lgi import SolveResult

    if is_a(source, "lgi.solve.model.Model"):
        model = cast("Model", source)
        units = model.units if units is None else units
        source = model.dataset
    t = source if isinstance(source, Topology) else topology(cast("Dataset", source))
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
