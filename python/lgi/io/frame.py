"""The frame an output is written in: a length unit (or a plain scale) and an up axis. lgi
solves in the model's unit, Y up; a pipeline may want metres, or Z up (Blender, Unreal,
3ds Max). `OutputFrame` maps points, lengths and the head transform into it; the USD writer
also records it (`metersPerUnit`, `upAxis`). PC2, MDD and OBJ carry no such fields: the
numbers themselves are converted."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lgi.errors import InputError
from lgi.io.units import normalize_unit, unit_scale

__all__ = ["UP_AXES", "OutputFrame", "output_frame"]

UP_AXES = ("y", "z")

SOLVED_NPZ = "a solved .npz stays in the model's frame (lgi export converts it)"
DATASET_NPZ = "a dataset .npz stays in the model's frame"

# Y up to Z up, a rotation about X by +90 degrees: (x, y, z) -> (x, -z, y); a face looking
# down +Z (Y up) looks down -Y (Z up), as Blender's and Unreal's importers turn Y-up files.
_Y_TO_Z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@dataclass(frozen=True)
class OutputFrame:
    scale: float = 1.0
    """Model coordinates times this are the output's."""
    units: str | None = None
    """The output's unit (None: unknown, as the model's)."""
    up: str = "y"

    @property
    def identity(self) -> bool:
        return self.scale == 1.0 and self.up == "y"

    def check_writer(self, kind: str, where: str, npz: str = SOLVED_NPZ) -> None:
        """Refuses a frame the writer `kind` cannot carry: any but the model's for an npz
        (`npz` says which: a solved take or a dataset), Z up for glTF (Y up by its spec)."""
        if kind == "npz" and not self.identity:
            raise InputError(
                f"--units, --scale and --up apply to USD, OBJ, PC2 and MDD outputs; {npz}"
            )
        if kind == "gltf" and self.up != "y":
            raise InputError(f"{where}: glTF is Y up by its specification; --up z is for USD")

    def points(self, p: NDArray[np.floating]) -> NDArray[np.float64]:
        """(…, 3) points in the output's frame."""
        q = np.asarray(p, dtype=np.float64) * self.scale
        return q @ _Y_TO_Z.T if self.up == "z" else q

    def lengths(self, d: NDArray[np.floating]) -> NDArray[np.float64]:
        return np.asarray(d, dtype=np.float64) * self.scale

    def rotations(self, r: NDArray[np.floating]) -> NDArray[np.float64]:
        """(…, 3, 3) rotations of model space, as rotations of the output's."""
        q = np.asarray(r, dtype=np.float64)
        return np.asarray(_Y_TO_Z @ q @ _Y_TO_Z.T) if self.up == "z" else q


def output_frame(
    model_units: str | None,
    *,
    units: str | None = None,
    scale: float | None = None,
    up: str = "y",
) -> OutputFrame:
    """`--units U` (converted from the model's unit, which must be known), or `--scale S`
    (the output's unit is then not known: USD gets no `metersPerUnit`), and `--up y|z`."""
    if up not in UP_AXES:
        raise InputError(f"--up {up!r}: expected y or z")
    if units is not None and scale is not None:
        raise InputError("--units and --scale: give one")
    if units is not None:
        u = normalize_unit(units, "--units")
        if not model_units:
            raise InputError(
                f"--units {units}: the model has no unit to convert from (lgi build --units)"
            )
        return OutputFrame(unit_scale(model_units, u), u, up)
    if scale is not None:
        if not (np.isfinite(scale) and scale > 0):
            raise InputError(f"--scale {scale}: must be a positive number")
        return OutputFrame(float(scale), None if scale != 1.0 else model_units, up)
    return OutputFrame(1.0, model_units, up)
