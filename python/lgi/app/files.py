"""The command line's files: inputs that must exist, outputs that must not be inputs and are
replaced only with `--force`, `--out`'s format by suffix, `--frames A:B` and `--fps`. Error
messages name the CLI's arguments (`--out`, `MODEL`)."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from lgi.errors import InputError
from lgi.io.atomic import check_writable, existing_sequence, refuse_existing
from lgi.io.paths import output_file

Say = Callable[[str], None]


def _silent(_message: str) -> None:
    pass


def existing_file(path: str, what: str) -> Path:
    """An input file that exists and is not a folder (`what` names the argument)."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"{what} {path}: no such file")
    if p.is_dir():
        raise InputError(f"{what} {path}: is a folder, expected a file")
    return p


def not_an_input(out: Path, *inputs: str | os.PathLike[str]) -> None:
    """Refuses an output path that is one of the command's inputs (nothing given is modified)."""
    for i in inputs:
        q = Path(i)
        if q.exists() and q.resolve() == out.resolve():
            raise InputError(f"--out {out}: is an input of the command ({i}); choose another path")


def ready_output(out: str | os.PathLike[str], *inputs: str | os.PathLike[str], force: bool) -> Path:
    """The checks every command makes on `--out` before any work: a file path in a folder that
    exists, not one of the command's `inputs`, not an existing file (or, for `NAME.obj`, an
    existing sequence `NAME.NNNN.obj`) unless `force`, in a folder lgi can write to (a probe
    file is made and removed: a read-only folder fails now, not after the solve)."""
    dest = output_file(os.fspath(out), "--out")
    not_an_input(dest, *inputs)
    if dest.suffix.lower() == ".obj" and not dest.exists():
        old = existing_sequence(dest.parent, dest.stem)
        if old and not force:
            raise InputError(
                f"--out {dest}: the sequence {dest.stem}.NNNN.obj exists ({len(old)} frames, "
                f"{old[0].name} to {old[-1].name}); use --force to replace it (its frames are "
                "removed, never mixed with the new ones)"
            )
    else:
        refuse_existing(dest, "--out", force)
    check_writable(dest)
    return dest


def frame_range(spec: str | None, count: int) -> slice:
    """`--frames a:b` (0-based take frames, b exclusive; either end may be left out)."""
    if spec is None:
        return slice(0, count)
    parts = spec.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        a = int(parts[0]) if parts[0].strip() else 0
        b = int(parts[1]) if parts[1].strip() else count
    except ValueError:
        raise InputError(f"--frames {spec!r}: expected START:END (e.g. 0:100)") from None
    if not 0 <= a < b <= count:
        raise InputError(
            f"--frames {spec}: the take has frames 0:{count}; START must be < END within it"
        )
    return slice(a, b)


def output_kind(path: str) -> str:
    """`--out`'s format by suffix: 'usd', 'obj' (a sequence), 'npz', 'pc2' or 'mdd'."""
    suffix = Path(path).suffix.lower()
    kinds = {".usd": "usd", ".usdc": "usd", ".usda": "usd", ".npz": "npz", ".obj": "obj"}
    kinds |= {".pc2": "pc2", ".mdd": "mdd"}
    if suffix not in kinds:
        raise InputError(
            f"--out {path}: unknown output format {suffix or '(no suffix)'!r}; "
            "use .usd/.usdc/.usda (point cache), .obj (OBJ sequence), .pc2 or .mdd (point "
            "caches for Blender's Mesh Cache, Houdini, 3ds Max) or .npz"
        )
    return kinds[suffix]


def frame_rate(given: float | None, take_fps: float | None, kind: str) -> float | None:
    """`--fps`, else the take's rate; a USD output needs one."""
    if given is not None:
        if not np.isfinite(given) or given <= 0:
            raise InputError(f"--fps {given}: must be a positive number")
        return float(given)
    if take_fps is None and kind in ("usd", "mdd"):
        raise InputError(f"the take has no frame rate; pass --fps for the {kind.upper()} times")
    return take_fps
