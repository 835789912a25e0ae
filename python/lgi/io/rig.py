"""Blendshape rigs out, so a DCC or engine loads them: glTF 2.0 morph targets
(`write_gltf_rig`: `.gltf` with the buffer embedded, or binary `.glb`) and USD blendshapes
(`write_usd_rig`: `UsdSkel.BlendShape` prims bound to the mesh under a `SkelRoot`). Every
shape of the dataset becomes a target with its name; a corrective (`lgi.solve.rig`) is a target
like any other, its combination recorded beside it."""

from __future__ import annotations

import base64
import json
import os
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from lgi.errors import FileWriteError, InputError
from lgi.io.atomic import atomic_path, temporary_beside
from lgi.io.frame import OutputFrame
from lgi.io.paths import output_file
from lgi.io.served import is_a
from lgi.io.topology import topology
from lgi.io.units import METERS_PER_UNIT, normalize_unit
from lgi.io.usd import define_usd_mesh, new_stage, save_stage

if TYPE_CHECKING:
    from lgi.data.dataset import Dataset

__all__ = ["RigAnimation", "gltf_vertices", "write_gltf_rig", "write_usd_rig"]

CORRECTIVE_PREFIX = "corrective_"
"""Correctives are named `corrective_` + the combination's shape names joined by `_`: how a rig
file tells a corrective from a shape (`lgi.solve.rig` names them)."""

_FLOAT, _UINT = 5126, 5125  # glTF componentType codes
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


def _checked(
    dataset: Dataset, frame: OutputFrame | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float32]]:
    """The neutral and the shapes' offsets, in `frame` (scaled and turned; offsets are
    vectors, so they take the same linear map as the points)."""
    if not is_a(dataset, "lgi.data.dataset.Dataset"):
        raise InputError(f"expected an lgi.Dataset, got {type(dataset).__name__}")
    if dataset.num_shapes == 0:
        raise InputError("the dataset has no shapes to export as blendshapes")
    neutral, shapes = np.asarray(dataset.neutral), np.asarray(dataset.shapes, dtype=np.float32)
    if frame is not None and not frame.identity:
        neutral = frame.points(neutral)
        shapes = frame.points(shapes).astype(np.float32)
    return neutral, shapes


def gltf_vertices(dataset: Dataset) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The glTF vertices: `source` (N,), the dataset vertex of each (vertices are split where
    a UV seam gives one vertex several UVs; N = V without UVs), and `triangles` (T, 3) over
    them."""
    tris = np.asarray(dataset.triangles, dtype=np.int64)
    uv_tris = np.asarray(dataset.uv_triangles, dtype=np.int64)
    if uv_tris.size == 0:
        return np.arange(dataset.num_vertices), tris
    pairs = np.stack([tris.ravel(), uv_tris.ravel()], axis=1)
    unique, inverse = np.unique(pairs, axis=0, return_inverse=True)
    return unique[:, 0], inverse.reshape(-1, 3)


def write_gltf_rig(
    path: str | os.PathLike[str], dataset: Dataset, *, frame: OutputFrame | None = None
) -> Path:
    """Writes the neutral as one glTF mesh (triangles; TEXCOORD_0 when the dataset has UVs,
    vertices split at seams: `gltf_vertices`) with every shape as a morph target (POSITION
    displacements), names in `mesh.extras.targetNames`, all weights 0. `.glb`: binary;
    `.gltf`: JSON with the buffer as a base64 data URI. `Dataset.from_gltf` reads it back."""
    out = output_file(path, "glTF output")
    suffix = out.suffix.lower()
    if suffix not in (".gltf", ".glb"):
        raise InputError(f"glTF output {out}: the suffix must be .gltf or .glb")
    if frame is not None:
        frame.check_writer("gltf", f"glTF output {path}")
    neutral, shapes = _checked(dataset, frame)
    source, tris = gltf_vertices(dataset)
    blobs: list[bytes] = []
    views: list[dict[str, Any]] = []
    accessors: list[dict[str, Any]] = []

    def add(array: NDArray[Any], kind: str, component: int, target: int | None) -> int:
        data = np.ascontiguousarray(array).tobytes()
        offset = sum(len(b) for b in blobs)
        blobs.append(data + b"\0" * (-len(data) % 4))
        view: dict[str, Any] = {"buffer": 0, "byteOffset": offset, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        views.append(view)
        acc: dict[str, Any] = {
            "bufferView": len(views) - 1,
            "componentType": component,
            "count": int(array.shape[0]),
            "type": kind,
        }
        if kind == "VEC3":  # POSITION accessors (targets too) must carry their bounds
            acc["min"] = [float(v) for v in array.min(axis=0)]
            acc["max"] = [float(v) for v in array.max(axis=0)]
        accessors.append(acc)
        return len(accessors) - 1

    attributes = {
        "POSITION": add(neutral[source].astype(np.float32), "VEC3", _FLOAT, _ARRAY_BUFFER)
    }
    if np.asarray(dataset.uv_triangles).size:
        uv_source = np.zeros(len(source), dtype=np.int64)
        uv_source[tris.ravel()] = np.asarray(dataset.uv_triangles).ravel()
        uvs = np.asarray(dataset.uvs)[uv_source].astype(np.float32)
        uvs[:, 1] = 1.0 - uvs[:, 1]  # glTF's v runs down the image, OBJ's up
        attributes["TEXCOORD_0"] = add(uvs, "VEC2", _FLOAT, _ARRAY_BUFFER)
    indices = add(tris.astype(np.uint32).ravel(), "SCALAR", _UINT, _ELEMENT_ARRAY_BUFFER)
    targets = [{"POSITION": add(s[source], "VEC3", _FLOAT, _ARRAY_BUFFER)} for s in shapes]
    blob = b"".join(blobs)
    buffer: dict[str, Any] = {"byteLength": len(blob)}
    if suffix == ".gltf":
        buffer["uri"] = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
    doc = {
        "asset": {"version": "2.0", "generator": "lgi"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "face"}],
        "meshes": [
            {
                "name": "face",
                "primitives": [
                    {"attributes": attributes, "indices": indices, "mode": 4, "targets": targets}
                ],
                "weights": [0.0] * len(targets),
                "extras": {"targetNames": list(dataset.names)},
            }
        ],
        "buffers": [buffer],
        "bufferViews": views,
        "accessors": accessors,
    }
    text = json.dumps(doc, separators=(",", ":")).encode()
    try:
        if suffix == ".gltf":
            with atomic_path(out) as tmp:
                tmp.write_bytes(text)
        else:
            text += b" " * (-len(text) % 4)
            chunks = (
                struct.pack("<II", len(text), 0x4E4F534A)
                + text
                + struct.pack("<II", len(blob), 0x004E4942)
                + blob
            )
            with atomic_path(out) as tmp:
                tmp.write_bytes(struct.pack("<III", 0x46546C67, 2, 12 + len(chunks)) + chunks)
    except OSError as e:
        raise FileWriteError(f"glTF output {out}: cannot be written: {e}") from None
    return out


def _combination(name: str, names: list[str]) -> list[str] | None:
    """The shapes a corrective's name combines, when they are the dataset's (`lgi.solve.rig`)."""
    if not name.startswith(CORRECTIVE_PREFIX):
        return None
    rest = name[len(CORRECTIVE_PREFIX) :]
    # Shape names may hold '_': match the longest dataset names from the left.
    out: list[str] = []
    while rest:
        match = max(
            (n for n in names if rest == n or rest.startswith(n + "_")), key=len, default=None
        )
        if match is None:
            return None
        out.append(match)
        rest = rest[len(match) + 1 :]
    return out if len(out) >= 2 else None


@dataclass(frozen=True)
class RigAnimation:
    """Time-sampled blend-shape weights for `write_usd_rig`: (F, S) `weights` in the
    dataset's shape order, from time code `start` at `fps`, and optionally (F, 3) `jaw_theta`."""

    weights: np.ndarray
    fps: float
    start: int = 0
    jaw_theta: np.ndarray | None = None


def _animate(stage: Any, anim: Any, weights_attr: Any, a: RigAnimation, count: int) -> None:
    from pxr import Gf, Sdf, Usd, Vt

    w = np.asarray(a.weights, dtype=np.float32)
    if w.ndim != 2 or w.shape[1] != count:
        raise InputError(f"rig animation: weights must be (F, {count}), got {w.shape}")
    jaw = None if a.jaw_theta is None else np.asarray(a.jaw_theta, dtype=np.float64)
    jaw_attr = None
    if jaw is not None:
        jaw_attr = anim.GetPrim().CreateAttribute(
            "lgi:jawTheta", Sdf.ValueTypeNames.Float3, custom=True
        )
    for f in range(w.shape[0]):
        t = Usd.TimeCode(a.start + f)
        weights_attr.Set(Vt.FloatArray.FromNumpy(np.ascontiguousarray(w[f])), t)
        if jaw_attr is not None and jaw is not None:
            jaw_attr.Set(Gf.Vec3f(*map(float, jaw[f])), t)
    stage.SetTimeCodesPerSecond(float(a.fps))
    stage.SetFramesPerSecond(float(a.fps))
    stage.SetStartTimeCode(a.start)
    stage.SetEndTimeCode(a.start + w.shape[0] - 1)


def _usd_name(name: str, taken: set[str]) -> str:
    """A valid, unique USD prim name for a shape name."""
    from pxr import Tf

    base = Tf.MakeValidIdentifier(name)
    out, i = base, 1
    while out in taken:
        out, i = f"{base}_{i}", i + 1
    taken.add(out)
    return out


def write_usd_rig(
    path: str | os.PathLike[str],
    dataset: Dataset,
    *,
    units: str | None = None,
    animation: RigAnimation | None = None,
    frame: OutputFrame | None = None,
) -> Path:
    """Writes the neutral and its shapes as a USD blendshape rig: `SkelRoot` `/Rig` (default
    prim) holding the `UsdGeom.Mesh` `/Rig/Face` (the neutral's source polygons, UVs as `st`)
    with `UsdSkelBindingAPI` (`skel:blendShapes`: the shape names, `skel:blendShapeTargets`:
    one `UsdSkel.BlendShape` per shape under the mesh, offsets only where the shape moves a
    vertex, with `pointIndices`), a `Skeleton` `/Rig/Skel` without joints and its
    `SkelAnimation` `/Rig/Skel/Weights` (every weight 0), so a DCC has the channels. A
    corrective's prim carries `lgi:combination` (the shapes it corrects). `units` as in
    `lgi.io.usd.write_usd`. With `animation`, the weights are time-sampled curves (time codes
    `start`, `start + 1`, ... at `fps`) and the jaw pose, when given, is `lgi:jawTheta` (float3:
    open, lateral in radians, forward) on the animation prim."""
    from pxr import Sdf, Usd, UsdGeom, UsdSkel, Vt

    out = output_file(path, "USD output")
    if out.suffix.lower() not in (".usd", ".usdc", ".usda"):
        raise InputError(f"USD output {out}: the suffix must be .usd, .usdc or .usda")
    neutral, shapes = _checked(dataset, frame)
    if frame is not None and not frame.identity:
        units = frame.units
    tmp = temporary_beside(out)
    stage = new_stage(Usd, Sdf, tmp)
    up_z = frame is not None and frame.up == "z"
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if up_z else UsdGeom.Tokens.y)
    if units is not None:
        UsdGeom.SetStageMetersPerUnit(stage, METERS_PER_UNIT[normalize_unit(units, "units")])
    root = UsdSkel.Root.Define(stage, "/Rig")
    stage.SetDefaultPrim(root.GetPrim())
    mesh = define_usd_mesh(stage, "/Rig/Face", topology(dataset))
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(neutral.astype(np.float32)))
    mesh.CreateExtentAttr(
        Vt.Vec3fArray.FromNumpy(np.stack([neutral.min(0), neutral.max(0)]).astype(np.float32))
    )
    names = list(dataset.names)
    taken: set[str] = set()
    tokens, targets = [], []
    for name, s in zip(names, shapes, strict=True):
        prim_name = _usd_name(name, taken)
        bs = UsdSkel.BlendShape.Define(stage, f"/Rig/Face/{prim_name}")
        moved = np.flatnonzero(np.any(s != 0, axis=1))
        bs.CreateOffsetsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(s[moved])))
        bs.CreatePointIndicesAttr(Vt.IntArray.FromNumpy(moved.astype(np.int32)))
        combo = _combination(name, names)
        if combo is not None:
            bs.GetPrim().CreateAttribute(
                "lgi:combination", Sdf.ValueTypeNames.StringArray, custom=True
            ).Set(Vt.StringArray(combo))
        tokens.append(prim_name)
        targets.append(bs.GetPath())
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateBlendShapesAttr(Vt.TokenArray(tokens))
    binding.CreateBlendShapeTargetsRel().SetTargets(targets)
    skel = UsdSkel.Skeleton.Define(stage, "/Rig/Skel")
    anim = UsdSkel.Animation.Define(stage, "/Rig/Skel/Weights")
    anim.CreateBlendShapesAttr(Vt.TokenArray(tokens))
    weights_attr = anim.CreateBlendShapeWeightsAttr(Vt.FloatArray(len(tokens)))
    if animation is not None:
        _animate(stage, anim, weights_attr, animation, len(tokens))
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    save_stage(stage, tmp, out)
    return out
