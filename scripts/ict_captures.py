"""What the capture measurements of issue 34 share (scripts/noise_estimate_results.py,
scripts/perturbation_results.py, and the tables of scripts/peer_results.py and
scripts/scans_results.py): ICT-FaceKit with its generic layout, the capture truth rig's hinge
jaw, the default build, the shared Live Link recordings' curves on ICT's shapes, and a
protocol's rows read per recording."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

import lgi
from lgi.io.livelink import read_livelinkface
from lgi.lab import ict
from lgi.lab import methods as lab_methods
from lgi.lab.capture import HingeJaw

ICT = "../shared/data/ict-facekit"
LIVELINK = "../shared/data/livelinkface"
RECORDINGS = ("alex_rom_4", "jmtechart_myslate_3")


def setup() -> tuple[Any, np.ndarray, HingeJaw, lgi.Model]:
    """ICT's dataset, its layout's rest positions, the hinge jaw and the default build."""
    d = ict.load_dataset(ICT)
    positions = ict.load_layout(ICT).positions
    jaw = HingeJaw.fit(d, ict.lower_teeth())
    return d, positions, jaw, lgi.Model.build(d, positions)


def recordings(dataset: Any) -> Iterator[tuple[str, np.ndarray]]:
    """Each shared recording's name and its curves as weights of `dataset`'s shapes."""
    for rec in RECORDINGS:
        yield rec, read_livelinkface(f"{LIVELINK}/{rec}.csv").for_dataset(dataset.names)


def by_recording(rows: list[dict[str, Any]]) -> dict[str, dict[str, dict[str, Any]]]:
    """A protocol's rows ("recording: method") as recording -> method -> row."""
    out: dict[str, dict[str, dict[str, Any]]] = {}
    for r in rows:
        rec, method = r["method"].split(": ", 1)
        out.setdefault(rec, {})[method] = r
    return out


#: The peers a TD has: the rig solve with the jaw as a joint and its residual corrective, and
#: where a protocol has them (the scans'), the same with the weights unbounded.
PEERS = lab_methods.PEER_NAMES


def peer_ratio(means: dict[str, Any], method: str = "LGI") -> float:
    """`method`'s mean error over the best of the peers' the protocol ran (`PEERS`)."""
    return float(means[method] / min(means[p] for p in PEERS if p in means))


def lomo_errors(
    methods_for: Callable[[Any, np.ndarray, np.ndarray], dict[str, Any]],
) -> Iterator[tuple[str, dict[str, np.ndarray]]]:
    """The lomo protocol as the issue's scripts run it: each shared AnimFace take retargeted
    onto ICT, 8 of its non-skull markers left out one at a time (`lgi.lab.lomo`), every
    method of `methods_for` built and solved without the one left out on about 250 frames;
    per take its stem and each method's distances (cm) from the left-out markers."""
    from lgi.io.takes import read_raw
    from lgi.lab import lomo

    d = ict.load_dataset(ICT)
    lm = np.asarray(ict.load_landmarks(ICT), dtype=np.int64)
    marks = {n: int(lm[k]) for n, k in lomo.ANIMFACE_IBUG.items()}
    face = ict.face_triangles(d)
    for path in ict.animface(Path(ICT).parent):
        take = lomo.retarget(read_raw(path), d.neutral, face, marks)
        step = max(1, take.frames.shape[0] // 250)
        cand = [i for i, n in enumerate(take.names) if n not in set(lomo.RIGID)]
        picked = lomo.held_out_markers(take.rest, take.frames, cand, 8)
        got = lomo.lomo(d, take, picked, methods_for, step=step)
        yield Path(path).stem, {m: np.concatenate(list(e.values())) for m, e in got.errors.items()}


def print_lomo(
    methods_for: Callable[[Any, np.ndarray, np.ndarray], dict[str, Any]],
    label: Callable[[str], str] = str,
) -> None:
    """`lomo_errors` printed: a line per take (`label` of its stem, then each method's mean
    distance in mm from the left-out markers) and one over both takes."""
    every: dict[str, list[np.ndarray]] = {}
    for stem, errs in lomo_errors(methods_for):
        for m, e in errs.items():
            every.setdefault(m, []).append(e)
        print(label(stem), " ".join(f"{m}={10 * e.mean():.3f} mm" for m, e in errs.items()))
    both = {m: 10 * np.concatenate(e).mean() for m, e in every.items()}
    print("both takes", " ".join(f"{m}={v:.3f} mm" for m, v in both.items()))
