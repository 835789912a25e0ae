"""Camera calibration files: OpenCV FileStorage's YAML and JSON layouts, one camera per key
prefix `cam<i>_`, so `cv2.FileStorage` reads what we write and we read what it writes
(`save_cameras`, `load_cameras`; the cameras are `lgi.capture.camera`'s)."""

from __future__ import annotations

import json
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lgi.capture.camera import Camera
from lgi.errors import InputError
from lgi.io.atomic import atomic_path
from lgi.io.paths import output_file

F64 = NDArray[np.float64]

__all__ = ["load_cameras", "save_cameras"]


_MATRICES = ("K", "D", "R", "t")


def _storage_values(cameras: Sequence[Camera]) -> dict[str, Any]:
    out: dict[str, Any] = {"camera_count": len(cameras)}
    for i, cam in enumerate(cameras):
        out[f"cam{i}_model"] = cam.model
        out[f"cam{i}_image_width"] = cam.image_size[0]
        out[f"cam{i}_image_height"] = cam.image_size[1]
        for name in _MATRICES:
            a = getattr(cam, name)
            out[f"cam{i}_{name}"] = a if a.ndim == 2 else a.reshape(-1, 1)
    return out


def _cameras_from_values(values: dict[str, Any], where: str) -> list[Camera]:
    try:
        count = int(values["camera_count"])
    except (KeyError, TypeError, ValueError):
        raise InputError(f"{where}: no integer camera_count") from None
    cams = []
    for i in range(count):
        p = f"cam{i}_"
        need = [p + k for k in ("model", "image_width", "image_height", *_MATRICES)]
        missing = [k for k in need if k not in values]
        if missing:
            raise InputError(f"{where}: camera {i}: missing {', '.join(missing)}")
        d = {k: values[p + k] for k in ("model", *_MATRICES)}
        d["image_size"] = (values[p + "image_width"], values[p + "image_height"])
        try:
            cams.append(Camera.from_dict(d))
        except InputError as e:
            raise InputError(f"{where}: camera {i}: {e}") from None
    return cams


def _yaml_scalar(v: Any) -> str:
    if isinstance(v, str):
        return v
    return repr(int(v)) if isinstance(v, (int, np.integer)) else repr(float(v))


def _write_yaml(values: dict[str, Any]) -> str:
    lines = ["%YAML:1.0", "---"]
    for k, v in values.items():
        if isinstance(v, np.ndarray):
            data = ", ".join(repr(float(x)) for x in v.ravel())
            lines += [
                f"{k}: !!opencv-matrix",
                f"   rows: {v.shape[0]}",
                f"   cols: {v.shape[1]}",
                "   dt: d",
                f"   data: [ {data} ]",
            ]
        else:
            lines.append(f"{k}: {_yaml_scalar(v)}")
    return "\n".join(lines) + "\n"


def _parse_scalar(text: str) -> Any:
    s = text.strip()
    if len(s) >= 2 and s[0] == s[-1] and s[0] in "\"'":
        return s[1:-1]
    for conv in (int, float):
        try:
            return conv(s)
        except ValueError:
            pass
    return s


def _read_yaml(text: str, where: str) -> dict[str, Any]:
    """The flat subset of OpenCV FileStorage YAML that calibrations use: `key: scalar` and
    `key: !!opencv-matrix` blocks (rows, cols, dt, data: [...] over one or more lines)."""
    values: dict[str, Any] = {}
    lines = text.splitlines()
    i = 0
    key_re = re.compile(r"^([A-Za-z_][\w]*)\s*:\s*(.*)$")
    while i < len(lines):
        raw = lines[i].split("#", 1)[0].rstrip()
        i += 1
        if not raw.strip() or raw.startswith("%YAML") or raw.strip() == "---":
            continue
        m = key_re.match(raw)
        if m is None or raw[0].isspace():
            raise InputError(f"{where}, line {i}: expected 'key: value', got {raw.strip()!r}")
        key, rest = m.group(1), m.group(2).strip()
        if rest != "!!opencv-matrix":
            values[key] = _parse_scalar(rest)
            continue
        start = i
        block: dict[str, str] = {}
        while i < len(lines) and (lines[i].startswith(" ") or not lines[i].strip()):
            sub = lines[i].strip()
            i += 1
            if not sub:
                continue
            m2 = key_re.match(sub)
            if m2 is None:
                raise InputError(f"{where}, line {i}: cannot read {sub!r} in matrix {key}")
            name, val = m2.group(1), m2.group(2)
            if name == "data":
                while "]" not in val and i < len(lines):
                    val += " " + lines[i].strip()
                    i += 1
            block[name] = val
        values[key] = _matrix_from_block(block, f"{where}, line {start}: matrix {key}")
    return values


def _matrix_from_block(block: dict[str, Any], where: str) -> F64:
    try:
        rows, cols = int(block["rows"]), int(block["cols"])
        data = block["data"]
        if isinstance(data, str):
            data = [float(x) for x in data.strip().strip("[]").split(",") if x.strip()]
        a = np.asarray(data, dtype=np.float64)
    except (KeyError, TypeError, ValueError) as e:
        raise InputError(f"{where}: needs rows, cols and numeric data ({e})") from None
    if a.size != rows * cols:
        raise InputError(f"{where}: {rows}x{cols} needs {rows * cols} values, got {a.size}")
    return a.reshape(rows, cols)


def save_cameras(path: str | os.PathLike[str], cameras: Sequence[Camera]) -> None:
    """Writes a calibration (one or more cameras) as OpenCV FileStorage YAML (`.yaml`, `.yml`)
    or JSON (`.json`): keys `camera_count` and per camera `cam<i>_model`, `cam<i>_K`,
    `cam<i>_D`, `cam<i>_R`, `cam<i>_t` (matrices), `cam<i>_image_width`, `cam<i>_image_height`."""
    if not cameras or not all(isinstance(c, Camera) for c in cameras):
        raise InputError("cameras: expected a non-empty sequence of lgi.capture.camera cameras")
    p = output_file(path, "calibration output")
    values = _storage_values(cameras)
    suffix = p.suffix.lower()
    if suffix in (".yaml", ".yml"):
        with atomic_path(p) as tmp:
            tmp.write_text(_write_yaml(values))
    elif suffix == ".json":
        out = {
            k: (
                {
                    "type_id": "opencv-matrix",
                    "rows": v.shape[0],
                    "cols": v.shape[1],
                    "dt": "d",
                    "data": v.ravel().tolist(),
                }
                if isinstance(v, np.ndarray)
                else v
            )
            for k, v in values.items()
        }
        with atomic_path(p) as tmp:
            tmp.write_text(json.dumps(out, indent=4) + "\n")
    else:
        raise InputError(f"{p}: calibration files are .yaml, .yml or .json")


def load_cameras(path: str | os.PathLike[str]) -> list[Camera]:
    """Reads what `save_cameras` (or `cv2.FileStorage` with the same keys) wrote."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as e:
        raise InputError(f"{p}: cannot read the calibration ({e.strerror})") from None
    suffix = p.suffix.lower()
    if suffix in (".yaml", ".yml"):
        values = _read_yaml(text, str(p))
    elif suffix == ".json":
        try:
            raw = json.loads(text)
        except json.JSONDecodeError as e:
            raise InputError(f"{p}, line {e.lineno}: not JSON ({e.msg})") from None
        if not isinstance(raw, dict):
            raise InputError(f"{p}: expected a JSON object at the top")
        values = {
            k: _matrix_from_block(v, f"{p}: {k}") if isinstance(v, dict) else v
            for k, v in raw.items()
        }
    else:
        raise InputError(f"{p}: calibration files are .yaml, .yml or .json")
    return _cameras_from_values(values, str(p))
