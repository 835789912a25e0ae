"""Rig and in-between experiments for docs/results.md (issue 19), on the ICT-FaceKit data.

1. `rig`: each ICT identity is an actor (its neutral + the ICT expression displacements, the
   FaceKit's own identity + expression composition); the generic ICT rig is the template,
   deformation-transferred to the actor (`lgi.solve.rig.on_actor`). For combinations of template
   shapes: the template rig's linear combination on the actor against LGI's reconstruction
   (`lgi.solve.rig.actor_rig`, i.e. the rig's shapes plus the corrective), with mesh-quality figures
   (`lgi.lab.quality`) on the face skin; a Fig. 8-like picture for identity 0.
2. `volume`: volume of rotating parts (lower teeth in jawOpen, eyeballs in eyeLookUp) at the
   halfway in-between, linear vs ARAP (`Dataset.augmented(method=...)`).
3. `capture`: the capture protocol's LGI cells with the dataset as is, augmented with linear
   in-betweens, and augmented with ARAP in-betweens.
4. `loo`: leave-one-out over a subset of shapes, the same three datasets (augmented inside
   each fold, so no in-between of the held-out shape leaks in).

Usage: python scripts/rig_results.py [--parts rig,volume,capture,loo] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

import lgi
from lgi.io.livelink import read_livelinkface
from lgi.lab import evaluate, ict, quality, scoring
from lgi.lab import methods as lab_methods
from lgi.lab.capture import HingeJaw, make_capture
from lgi.solve import rig

COMBINATIONS = [
    ["noseSneer_L", "mouthUpperUp_L", "cheekSquint_L"],  # Fig. 8: sneer + snarl + lip raiser
    ["noseSneer_R", "mouthUpperUp_R", "cheekSquint_R"],
    ["mouthSmile_L", "mouthSmile_R", "cheekSquint_L", "cheekSquint_R"],
    ["mouthRollUpper", "mouthRollLower"],
    ["mouthPress_L", "mouthPress_R", "mouthRollLower"],
    ["mouthPucker", "mouthFunnel"],
    ["jawOpen", "mouthFunnel", "mouthUpperUp_L", "mouthUpperUp_R"],
    ["mouthFrown_L", "mouthFrown_R", "mouthShrugLower", "mouthPress_L", "mouthPress_R"],
]
LIP_RADIUS = 1.2
"""cm: the lip region is the face skin within this distance of the 20 mouth landmarks."""
MOUTH_LANDMARKS = range(48, 68)
LOO_SHAPES = [
    "jawOpen",
    "mouthRollUpper",
    "mouthRollLower",
    "mouthFunnel",
    "mouthPucker",
    "eyeBlink_L",
    "eyeLookUp_L",
    "browInnerUp_L",
    "mouthSmile_L",
    "noseSneer_L",
    "cheekPuff_L",
    "mouthUpperUp_L",
]


def inbetween_count(dataset: lgi.Dataset) -> int:
    """Originals + in-betweens at 0.25/0.5/0.75 (+ the left/right pairs the recipes add)."""
    return 4 * dataset.num_shapes


def augmentations(dataset: lgi.Dataset) -> dict[str, lgi.Dataset]:
    n = inbetween_count(dataset)
    return {
        "as is": dataset,
        "+ linear in-betweens": dataset.augmented(n),
        "+ ARAP in-betweens": dataset.augmented(n, method="arap", quiet=True),
    }


def skin_triangles(dataset: lgi.Dataset) -> np.ndarray:
    t = np.asarray(dataset.triangles)
    return t[(t < ict.SKIN_VERTICES).all(axis=1)]


def lip_triangles(folder: Path, dataset: lgi.Dataset) -> np.ndarray:
    marks = json.loads((folder / "vertex_indices.json").read_text())["idx_to_landmark_verts"]
    x = np.asarray(dataset.neutral)
    mouth = x[[marks[i] for i in MOUTH_LANDMARKS]]
    near = np.linalg.norm(x[:, None] - mouth[None], axis=2).min(axis=1) < LIP_RADIUS
    t = skin_triangles(dataset)
    return t[near[t].all(axis=1)]


def figures(
    rest: np.ndarray, mesh: np.ndarray, skin: np.ndarray, lips: np.ndarray, moved: np.ndarray
) -> dict[str, float]:
    """Mesh-quality figures of `mesh` against `rest` on the face skin."""
    a = quality.area_ratios(rest, mesh, skin)
    e = quality.edge_ratios(rest, mesh, skin)
    region = skin[moved[skin].any(axis=1)]
    apex = rest.mean(axis=0)  # the head's centre: well inside, so cones are well shaped
    v0 = quality.cone_volume(rest, region, apex)
    v1 = quality.cone_volume(mesh, region, apex)
    return {
        "area_bad": float(((a > 2.0) | (a < 0.5)).mean() * 100),
        "area_max": float(a.max()),
        "area_min": float(a.min()),
        "edge_p99": float(np.percentile(np.abs(e - 1), 99)),
        "edge_max": float(np.abs(e - 1).max()),
        "flipped": int(quality.flipped(rest, mesh, skin).sum()),
        "volume": float((v1 / v0 - 1) * 100),
        "lips_x": len(quality.self_intersections(mesh, lips)),
    }


def part_rig(folder: Path, out_dir: Path, quiet: bool) -> list[str]:
    generic = ict.load_dataset(folder)
    markers = ict.load_markers(folder)
    skin = skin_triangles(generic)
    lips = lip_triangles(folder, generic)
    locate = lgi.Model.build(generic, markers, jaw=None)
    lines = [
        f"Face-skin triangles: {len(skin)}; lip region ({LIP_RADIUS} cm around the mouth "
        f"landmarks): {len(lips)} triangles. Per combination and actor: the template rig's "
        "linear combination on the actor vs LGI's reconstruction (paper mode: `jaw=None`, "
        "exact markers; and the recommended build with `marker_noise=0`).",
        "",
        "| combination | method | area ratio outside [0.5, 2] (% of triangles) | area ratio "
        "min / max | edge-length change p99 / max | flipped triangles | local volume change "
        "(%) | lip self-intersections | corrective = distance from the linear sum, mean on "
        "the moved skin / max (cm) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    identities = sorted((folder / "identities").glob("identity*.obj"))
    per: dict[tuple[int, str], list[dict[str, float]]] = {}
    rig_err: list[tuple[float, float]] = []
    neutral_x: list[int] = []
    picture = None
    for who in identities:
        t0 = time.perf_counter()
        neutral = lgi.Dataset.from_obj(who).neutral
        actor = lgi.Dataset.from_arrays(
            neutral,
            generic.triangles,
            generic.shapes,
            names=generic.names,
            uvs=generic.uvs,
            uv_triangles=generic.uv_triangles,
        )
        actor_markers = locate.bundle_positions(neutral)
        models = {
            "LGI (paper)": (lgi.Model.build(actor, actor_markers, jaw=None), None),
            "LGI (recommended)": (lgi.Model.build(actor, actor_markers), 0.0),
        }
        idx = [[generic.names.index(n) for n in c] for c in COMBINATIONS]
        neutral_x.append(len(quality.self_intersections(neutral, lips)))
        shapes_on = (
            rig.on_actor(
                actor, generic, generic.neutral[None] + np.asarray(generic.shapes, np.float64)
            )
            - neutral[None]
        )
        for label, (model, sigma) in models.items():
            out = rig.actor_rig(model, generic, COMBINATIONS, marker_noise=sigma, quiet=True)
            shapes = np.asarray(out.shapes, np.float64)
            s = generic.num_shapes
            if label == "LGI (paper)":
                err = np.linalg.norm(shapes[:s] - np.asarray(actor.shapes, np.float64), axis=2)
                rig_err.append((float(err[:, : ict.SKIN_VERTICES].mean()), float(err.max())))
            for c, k in enumerate(idx):
                linear = neutral + shapes_on[k].sum(axis=0)
                recon = neutral + shapes[k].sum(axis=0) + shapes[s + c]
                moved = np.linalg.norm(linear - neutral, axis=1) > 0.05
                if label == "LGI (paper)":
                    per.setdefault((c, "template rig, linear"), []).append(
                        figures(neutral, linear, skin, lips, moved)
                    )
                    if who == identities[0] and c == 0:
                        picture = (neutral, linear, recon)
                f = figures(neutral, recon, skin, lips, moved)
                gap = np.linalg.norm(recon - linear, axis=1)[: ict.SKIN_VERTICES]
                f["gap_mean"] = float(gap[moved[: ict.SKIN_VERTICES]].mean())
                f["gap_max"] = float(gap.max())
                per.setdefault((c, label), []).append(f)
        if not quiet:
            print(f"{who.stem}: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    for c, names in enumerate(COMBINATIONS):
        for label in ("template rig, linear", "LGI (paper)", "LGI (recommended)"):
            f = per[(c, label)]
            mean = {k: np.mean([x[k] for x in f]) for k in f[0]}
            lines.append(
                f"| {' + '.join(names)} | {label} | {mean['area_bad']:.2f} | "
                f"{min(x['area_min'] for x in f):.2f} / {max(x['area_max'] for x in f):.2f} | "
                f"{mean['edge_p99']:.3f} / {max(x['edge_max'] for x in f):.2f} | "
                f"{sum(x['flipped'] for x in f)} | {mean['volume']:+.2f} | "
                f"{sum(x['lips_x'] for x in f)} | "
                + (
                    f"{mean['gap_mean']:.3f} / {max(x['gap_max'] for x in f):.3f} |"
                    if "gap_mean" in mean
                    else "— |"
                )
            )
    lines += [
        "",
        f"Actors: {len(identities)} identities ({', '.join(p.stem for p in identities)}); "
        "figures are means over them, except min / max (over all) and the counts (summed). "
        "Rig shapes vs the actor's own ICT shapes (deformation transfer + LGI against the "
        "FaceKit's identity + expression sum), paper mode: mean per-vertex error on the skin "
        + ", ".join(f"{m:.4f}" for m, _ in rig_err)
        + " cm, max "
        + ", ".join(f"{x:.3f}" for _, x in rig_err)
        + " cm. The neutrals' own lip regions already hold "
        + ", ".join(str(x) for x in neutral_x)
        + " crossing triangle pairs (the closed lips touch), "
        + f"{sum(neutral_x)} in all: the self-intersection column's baseline.",
    ]
    if picture is not None:
        from lgi.lab.render import panel

        neutral, linear, recon = picture
        face = np.asarray(generic.triangles)
        face = face[(face < ict.NARROW_FACE).all(axis=1)]
        a_lin = np.abs(np.log2(np.maximum(area_per_vertex(neutral, linear, face), 1e-6)))
        a_rec = np.abs(np.log2(np.maximum(area_per_vertex(neutral, recon, face), 1e-6)))
        keep = np.unique(face)
        remap = np.full(len(neutral), -1)
        remap[keep] = np.arange(len(keep))
        panel(
            out_dir / "rig_fig8.png",
            {
                "template rig (linear sum)": linear[keep],
                "LGI reconstruction": recon[keep],
            },
            remap[face],
            {
                "template rig (linear sum)": a_lin[keep],
                "LGI reconstruction": a_rec[keep],
            },
            vmax=1.0,
            label="triangle area change, |log2 ratio|",
        )
        lines.append(
            "\n![Fig. 8-like: sneer + snarl + upper-lip raiser on identity000, linear vs LGI]"
            "(images/rig_fig8.png)"
        )
    return lines


def area_per_vertex(rest: np.ndarray, mesh: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Per vertex, the mean area ratio of its triangles (for colouring)."""
    r = quality.area_ratios(rest, mesh, tris)
    total = np.zeros(len(rest))
    count = np.zeros(len(rest))
    np.add.at(total, tris.ravel(), np.repeat(r, 3))
    np.add.at(count, tris.ravel(), 1)
    return np.asarray(np.where(count > 0, total / np.maximum(count, 1), 1.0))


def part_volume(folder: Path) -> list[str]:
    data = ict.load_dataset(folder)
    n = inbetween_count(data)
    lin, arap = data.augmented(n), data.augmented(n, method="arap", quiet=True)
    t = np.asarray(data.triangles)
    x0 = np.asarray(data.neutral)
    # ICT's eyeLook shapes move the lids, not the eyeballs: the lower teeth are its only
    # rotating rigid part (jawOpen about x, jawLeft/Right about y).
    parts = {
        f"lower teeth, {n}": (ict.lower_teeth(), n) for n in ("jawOpen", "jawLeft", "jawRight")
    }
    lines = [
        "| part | shape | linear: volume at @0.25 / @0.5 / @0.75 | ARAP: volume at @0.25 / "
        "@0.5 / @0.75 |",
        "|---|---|---|---|",
    ]
    for part, (verts, shape) in parts.items():
        part = part.split(",")[0]
        tris = t[np.isin(t, verts).all(axis=1)]
        v0 = quality.cone_volume(x0, tris, x0[verts].mean(axis=0))
        cells = []
        for ds in (lin, arap):
            vals = []
            for w in ("0.25", "0.5", "0.75"):
                y = x0 + np.asarray(ds.shapes[ds.names.index(f"{shape}@{w}")], np.float64)
                vals.append(quality.cone_volume(y, tris, y[verts].mean(axis=0)) / v0)
            cells.append(" / ".join(f"{v:.4f}" for v in vals))
        lines.append(f"| {part} | {shape} | {cells[0]} | {cells[1]} |")
    return lines


def part_capture(folder: Path, frames: int, quiet: bool) -> list[str]:
    data = ict.load_dataset(folder)
    markers = ict.load_markers(folder)
    jaw = HingeJaw.fit(data, ict.lower_teeth())
    lines = [
        "| recording | sigma (cm) | held out | dataset | shapes | lgi (paper) | "
        "lgi (recommended) | recommended, jaw-open frames |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for rec in ict.livelinkface(folder.parent):
        w = read_livelinkface(rec).for_dataset(data.names)
        w = w[:: max(1, w.shape[0] // frames)]
        for sigma in (0.0, 0.05):
            for hold in (0.0, 0.25):
                t0 = time.perf_counter()
                take = make_capture(
                    data, w, markers, sigma=sigma, dropout=0.02, holdout=hold, seed=3, jaw=jaw
                )
                for label, ds in augmentations(take.dataset).items():
                    methods = {
                        "paper": lab_methods.Recommended(
                            lgi.Model.build(ds, markers, jaw=None), None
                        ),
                        "lgi": lab_methods.Recommended(lgi.Model.build(ds, markers), sigma),
                    }
                    rows = {
                        r["method"]: r
                        for r in evaluate.capture(
                            methods, take.frames, take.truth, take.jaw_open, ict.skin()
                        )
                    }
                    lines.append(
                        f"| {rec.stem} ({take.frames.shape[0]} fr) | {sigma} | {int(hold * 100)} % "
                        f"| {label} | {ds.num_shapes} | {rows['paper']['mean']:.4f} | "
                        f"{rows['lgi']['mean']:.4f} | {rows['lgi']['open_mean']:.4f} |"
                    )
                if not quiet:
                    print(lines[-1], f"({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    return lines


def part_loo(folder: Path, quiet: bool) -> list[str]:
    data = ict.load_dataset(folder)
    markers = ict.load_markers(folder)
    ks = [data.names.index(n) for n in LOO_SHAPES]
    lines = [
        "| dataset (augmented without the held-out shape) | mean | p95 | max |",
        "|---|---|---|---|",
    ]
    for label in ("as is", "+ linear in-betweens", "+ ARAP in-betweens"):

        def factory(ds: lgi.Dataset, mk: object, label: str = label) -> dict[str, scoring.Solver]:
            aug = augmentations_one(ds, label)
            return {label: lgi.Model.build(aug, np.asarray(mk), jaw=None)}

        t0 = time.perf_counter()
        (row,) = scoring.leave_one_out(data, markers, factory, shapes=ks, region=ict.skin())
        lines.append(f"| {label} | {row['mean']:.4f} | {row['p95']:.4f} | {row['max']:.4f} |")
        if not quiet:
            print(lines[-1], f"({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    return lines


def augmentations_one(ds: lgi.Dataset, label: str) -> lgi.Dataset:
    n = inbetween_count(ds)
    if label == "as is":
        return ds
    if label == "+ linear in-betweens":
        return ds.augmented(n)
    return ds.augmented(n, method="arap", quiet=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--parts", default="rig,volume,capture,loo")
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--out", type=Path, help="markdown file (default: stdout)")
    ap.add_argument("--images", type=Path, default=Path("docs/images"))
    ap.add_argument("-q", "--quiet", action="store_true")
    args = ap.parse_args()
    folder = ict.find(os.environ.get(ict.ENV))
    if folder is None:
        raise SystemExit(f"ICT-FaceKit data not found (set ${ict.ENV})")
    args.images.mkdir(parents=True, exist_ok=True)
    parts = args.parts.split(",")
    lines: list[str] = []
    for part in parts:
        t0 = time.perf_counter()
        if part == "rig":
            body = part_rig(folder, args.images, args.quiet)
        elif part == "volume":
            body = part_volume(folder)
        elif part == "capture":
            body = part_capture(folder, args.frames, args.quiet)
        elif part == "loo":
            body = part_loo(folder, args.quiet)
        else:
            raise SystemExit(f"unknown part {part!r}")
        lines += [f"### {part} ({time.perf_counter() - t0:.0f} s)", "", *body, ""]
        print("\n".join(lines[-len(body) - 3 :]), flush=True)
    if args.out:
        args.out.write_text("\n".join(lines))


if __name__ == "__main__":
    main()
