"""`lgi build`: a model file from a neutral and its shapes (OBJ, glTF, `.npz`), a named marker
layout and a JSON `BuildConfig`."""

from __future__ import annotations

import json
import os
import re
import time
from pathlib import Path

import numpy as np

from lgi._lgi import BuildConfig
from lgi.app.files import Say, _silent, existing_file, ready_output
from lgi.data.dataset import Dataset
from lgi.errors import InputError, MarkerError
from lgi.io import takes
from lgi.solve.model import Model


def read_dataset(neutral: str, shapes: str) -> Dataset:
    """NEUTRAL (.obj with SHAPES a folder of OBJs or a glob; .gltf/.glb/.npz holding its
    shapes, SHAPES then '-' or the same file)."""
    n = existing_file(neutral, "NEUTRAL")
    suffix = n.suffix.lower()
    if suffix in (".gltf", ".glb", ".npz"):
        if shapes not in ("-", neutral) and Path(shapes) != n:
            raise InputError(
                f"SHAPES {shapes}: a {suffix} neutral holds its shapes "
                f"({'morph targets' if suffix != '.npz' else 'the shapes array'}); pass '-'"
            )
        if suffix == ".npz":
            return Dataset.from_npz(n)
        return Dataset.from_gltf(n)
    if suffix != ".obj":
        raise InputError(f"NEUTRAL {neutral}: expected .obj, .gltf, .glb or .npz")
    if shapes == "-":
        return Dataset.from_obj(n)
    s = Path(shapes)
    if s.is_dir():
        files = sorted(p for p in s.iterdir() if p.suffix.lower() == ".obj")
        if not files:
            raise InputError(f"SHAPES {shapes}: the folder holds no .obj files")
        return Dataset.from_obj(n, files)
    if s.suffix.lower() in (".gltf", ".glb"):
        raise InputError(
            f"SHAPES {shapes}: glTF morph targets come with their own neutral; "
            f"pass the glTF as NEUTRAL and '-' as SHAPES"
        )
    if not any(c in shapes for c in "*?["):
        if not s.exists():
            raise InputError(f"SHAPES {shapes}: no such folder or file (or a glob pattern)")
        return Dataset.from_obj(n, [s])
    return Dataset.from_obj(n, shapes)


def read_config(path: str | None) -> BuildConfig | None:
    """`--config`: a JSON object of `BuildConfig` fields (None: the defaults)."""
    if path is None:
        return None
    p = existing_file(path, "--config")
    try:
        fields = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(f"--config {path}: not a JSON file: {e}") from None
    if not isinstance(fields, dict):
        raise InputError(f"--config {path}: expected a JSON object of BuildConfig fields")
    known = BuildConfig().to_dict()
    unknown = sorted(set(fields) - set(known))
    if unknown:
        raise InputError(
            f"--config {path}: unknown fields {unknown} (BuildConfig has {', '.join(known)})"
        )
    try:
        return BuildConfig(**fields)
    except InputError as e:
        raise InputError(f"--config {path}: {e}") from None


def build_file(
    neutral: str | os.PathLike[str],
    shapes: str,
    markers: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    config: str | os.PathLike[str] | None = None,
    jaw: str = "auto",
    units: str | None = None,
    force: bool = False,
    say: Say = _silent,
) -> Path:
    """`lgi build`: a model file `out` from `neutral` and `shapes` (`read_dataset`), the
    layout CSV `markers` (`lgi.io.takes.read_layout`) and a JSON `config`; `jaw` is
    `Model.build`'s: "auto" (a rig from the jaw shapes when the dataset has `jawOpen`) or
    "none". The model keeps the layout's names and
    `units`. Returns `out`."""
    if jaw not in ("auto", "none"):
        raise InputError(f"--jaw {jaw!r}: expected 'auto' or 'none'")
    dest = ready_output(
        out, neutral, shapes, markers, *([config] if config is not None else []), force=force
    )
    cfg = read_config(None if config is None else os.fspath(config))
    layout = takes.read_layout(existing_file(os.fspath(markers), "MARKERS"))
    t0 = time.perf_counter()
    data = read_dataset(os.fspath(neutral), shapes)
    say(
        f"read the neutral ({data.num_vertices} vertices) and {data.num_shapes} shapes "
        f"({time.perf_counter() - t0:.1f} s)"
    )
    t0 = time.perf_counter()
    say(f"building the model for {len(layout.names)} markers ...")
    try:
        model = Model.build(
            data,
            layout.positions,
            cfg,
            jaw="auto" if jaw == "auto" else None,
            marker_names=layout.names,
            units=units,
        )
    except MarkerError as e:
        # The core counts markers; the user knows them by name.
        found = re.match(r"marker (\d+)", str(e))
        name = f" ({layout.names[int(found.group(1))]!r})" if found else ""
        raise MarkerError(f"MARKERS {os.fspath(markers)}: {e}{name}") from None
    model.save(dest)
    rig = model.jaw_rig
    say(
        f"built in {time.perf_counter() - t0:.1f} s, "
        + ("without a jaw rig" if rig is None else f"jaw pivot {np.round(rig.pivot, 3).tolist()}")
    )
    return dest
