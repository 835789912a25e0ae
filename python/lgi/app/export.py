"""Files made from files: `lgi export` (a solved `.npz` written again, in another format, frame
range or frame) and `lgi rig` (an actor's rig from a template rig, solved through the model)."""

from __future__ import annotations

import os
from pathlib import Path

from lgi.app.build import read_dataset
from lgi.app.files import (
    Say,
    _silent,
    existing_file,
    frame_range,
    frame_rate,
    not_an_input,
    output_kind,
    ready_output,
)
from lgi.app.write import write_output
from lgi.errors import InputError
from lgi.io.frame import DATASET_NPZ, output_frame
from lgi.io.paths import output_file
from lgi.io.result import read_result_npz
from lgi.solve.model import Model
from lgi.solve.options import SolveOptions


def export_file(
    result: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    frames: str | None = None,
    fps: float | None = None,
    force: bool = False,
    units: str | None = None,
    scale: float | None = None,
    up: str = "y",
    quiet: bool = False,
) -> tuple[Path, int]:
    """`lgi export`: a solved `.npz` (`lgi solve -o x.npz`) written again by `out`'s suffix,
    optionally a frame range (`--frames A:B`) at another rate. Returns the path written and
    the frame count."""
    not_an_input(output_file(os.fspath(out), "--out"), result)
    kind = output_kind(os.fspath(out))
    src = existing_file(os.fspath(result), "RESULT")
    dest = ready_output(out, src, force=force)
    r = read_result_npz(src)
    frame = output_frame(r.units, units=units, scale=scale, up=up)
    rng = frame_range(frames, r.vertices.shape[0])
    written = write_output(
        kind,
        dest,
        r.topology,
        r.vertices[rng],
        residuals=r.bundle_residuals[rng],
        missing=r.missing[rng],
        names=r.marker_names,
        fps=frame_rate(fps, r.fps, kind),
        start=r.start + rng.start,
        units=r.units,
        jaw_theta=None if r.jaw_theta is None else r.jaw_theta[rng],
        markers=None if r.markers is None else r.markers[rng],
        frame=frame,
        quiet=quiet,
        settings=r.settings,
    )
    return written, int(r.vertices[rng].shape[0])


RIG_OUTPUTS = (".usd", ".usdc", ".usda", ".gltf", ".glb", ".npz")
"""`lgi rig --out` suffixes: a USD blendshape rig, glTF morph targets or a dataset `.npz`."""


def rig_file(
    model: str | os.PathLike[str],
    neutral: str,
    shapes: str,
    out: str | os.PathLike[str],
    *,
    combine: list[str] | None = None,
    noise: str | None = None,
    force: bool = False,
    units: str | None = None,
    scale: float | None = None,
    up: str = "y",
    quiet: bool = False,
    say: Say = _silent,
) -> tuple[Path, int]:
    """`lgi rig`: the actor rig of MODEL from the template NEUTRAL + SHAPES (`read_dataset`;
    `lgi.solve.rig.actor_rig`), each `combine` entry ('A+B[+C]', template shape names) adding a
    corrective, written by `out`'s suffix (`RIG_OUTPUTS`: `lgi.io.rig.write_usd_rig`,
    `write_gltf_rig`, or `Dataset.to_npz`). `noise`: `--marker-noise` as a number or
    'none' ('auto' has no take to look at). Returns the path and the number of shapes."""
    from lgi.io.rig import write_gltf_rig, write_usd_rig
    from lgi.solve import rig

    dest = output_file(os.fspath(out), "--out")
    suffix = dest.suffix.lower()
    if suffix not in RIG_OUTPUTS:
        raise InputError(
            f"--out {dest}: unknown rig format {suffix or '(no suffix)'!r}; use "
            ".usd/.usdc/.usda (UsdSkel blendshapes), .gltf/.glb (morph targets) or .npz"
        )
    ready_output(dest, model, neutral, *([] if shapes == "-" else [shapes]), force=force)
    if noise == "auto":
        raise InputError("--marker-noise auto: a rig has no take to estimate it from")
    given = SolveOptions(marker_noise=noise, cli=True).marker_noise
    sigma = None if given is None else float(given)
    m = Model.load(existing_file(os.fspath(model), "MODEL"))
    frame = output_frame(m.units, units=units, scale=scale, up=up)
    rig_kind = {".npz": "npz", ".gltf": "gltf", ".glb": "gltf"}.get(suffix, "usd")
    frame.check_writer(rig_kind, f"--out {dest}", npz=DATASET_NPZ)
    template = read_dataset(neutral, shapes)
    combos = []
    for spec in combine or []:
        names = spec.split("+")
        if len(names) < 2 or any(not n for n in names):
            raise InputError(f"--combine {spec!r}: expected template shape names joined by '+'")
        combos.append(names)
    say(f"template: {template.num_shapes} shapes, {len(combos)} combinations")
    try:
        result = rig.actor_rig(m, template, combos, marker_noise=sigma, quiet=quiet)
    except InputError as e:
        raise InputError(f"--combine: {e}" if str(e).startswith("combination") else str(e)) from e
    if suffix in (".gltf", ".glb"):
        write_gltf_rig(dest, result, frame=frame)
    elif suffix == ".npz":
        result.to_npz(dest)
    else:
        write_usd_rig(dest, result, units=m.units, frame=frame)
    return dest, result.num_shapes
