"""What Blender does with lgi's outputs (an optional check: `pip install bpy`, Blender as a
Python module). Usage: python scripts/measure_blender.py Y_UP.usd Z_UP_METRES.usd TAKE.pc2
FIRST_FRAME.obj: imports each USD with Blender's default options and prints the mesh's size in
Blender units, the scene's frame rate and range; applies the PC2 with a Mesh Cache modifier to
the OBJ and prints how far the evaluated vertices are from the cache's."""

from __future__ import annotations

import struct
import sys

import bpy
import numpy as np


def reset() -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)


def evaluated(obj) -> np.ndarray:  # type: ignore[no-untyped-def]
    dg = bpy.context.evaluated_depsgraph_get()
    mesh = obj.evaluated_get(dg).to_mesh()
    co = np.empty(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", co)
    return (np.asarray(obj.matrix_world) @ np.c_[co.reshape(-1, 3), np.ones(len(co) // 3)].T).T[
        :, :3
    ]


def usd(path: str) -> None:
    reset()
    bpy.ops.wm.usd_import(filepath=path)
    s = bpy.context.scene
    obj = next(o for o in bpy.data.objects if o.type == "MESH")
    v = evaluated(obj)
    size = v.max(axis=0) - v.min(axis=0)
    print(
        f"{path}: Blender {bpy.app.version_string}: mesh size (x, y, z) {np.round(size, 4)}; "
        f"scene fps {s.render.fps}/{s.render.fps_base:g}, frames {s.frame_start}-{s.frame_end}"
    )


def pc2(cache: str, obj_path: str) -> None:
    reset()
    bpy.ops.wm.obj_import(filepath=obj_path, forward_axis="NEGATIVE_Z", up_axis="Y")
    obj = bpy.context.selected_objects[0]
    mod = obj.modifiers.new("cache", "MESH_CACHE")  # default options
    mod.cache_format = "PC2"
    mod.filepath = cache
    data = open(cache, "rb").read()
    _, _, n, start, _, frames = struct.unpack("<12siiffi", data[:32])
    want = np.frombuffer(data, "<f4", offset=32).reshape(frames, n, 3).astype(np.float64)
    # The OBJ importer turned Y up into Blender's Z up; the cache's points turned the same way.
    want = np.stack([want[..., 0], -want[..., 2], want[..., 1]], axis=-1)
    scene_frame = int(start) + frames // 2
    bpy.context.scene.frame_set(scene_frame)
    got = evaluated(obj)
    gaps = {k: float(np.abs(got - want[k]).max()) for k in range(frames)}
    shown = min(gaps, key=gaps.get)
    print(
        f"{cache}: Mesh Cache modifier, default options: scene frame {scene_frame} shows the "
        f"cache's sample {shown} (time code {int(start) + shown}) to {gaps[shown]:.3g}; the "
        f"file's start frame is {start:g}; modifier Frame Start {mod.frame_start:g}"
    )


if __name__ == "__main__":
    y_up, z_up, cache, first = sys.argv[1:5]
    usd(y_up)
    usd(z_up)
    pc2(cache, first)
