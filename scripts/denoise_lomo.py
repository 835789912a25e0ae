"""The take denoised by its own low-rank structure on real takes (issue 34): the lomo protocol
(`lgi.lab.lomo`: each shared AnimFace take retargeted onto ICT, 8 markers left out one at a
time, every method built and solved without the one left out; the noise estimated as
`--marker-noise auto` does) with LGI's recommended call with and without `lgi.denoise_take`
first, and the displacement interpolation and the fit + jaw + residual peer, each also given the
same denoised markers. Each line: the take, its estimated noise, and every method's mean
distance (mm) from the left-out markers; then both takes (docs/results.md).

Usage: python scripts/denoise_lomo.py (from the checkout, ../shared beside it)
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

from lgi.io.takes import read_raw
from lgi.lab import ict, lomo
from lgi.lab.evaluate import (
    DENOISED,
    DENOISED_PEER,
    OnDenoised,
    Recommended,
    capture_methods,
)

ICT = "../shared/data/ict-facekit"
OTHERS = ("displacement interpolation", "fit + jaw + residual")
#: Each solve's estimated noise (cm), for the line of its take.
NOISE: list[float] = []


def methods_for(dataset: Any, rest: np.ndarray, frames: np.ndarray) -> dict[str, Any]:
    ms = capture_methods(dataset, rest, None, frames)
    lgi = ms["LGI"]
    NOISE.append(float(lgi.marker_noise))
    out: dict[str, Any] = {
        "LGI": lgi,
        DENOISED: Recommended(lgi.model, lgi.marker_noise, denoise=True),
    }
    for name in OTHERS:
        out[name] = ms[name]
        out[DENOISED_PEER.format(name)] = OnDenoised(ms[name], lgi.marker_noise)
    return out


def main() -> None:
    warnings.filterwarnings("ignore")
    d = ict.load_dataset(ICT)
    lm = np.asarray(ict.load_landmarks(ICT), dtype=np.int64)
    marks = {n: int(lm[k]) for n, k in lomo.ANIMFACE_IBUG.items()}
    face = ict.face_triangles(d)
    every: dict[str, list[np.ndarray]] = {}
    for path in ict.animface(Path(ICT).parent):
        NOISE.clear()
        take = lomo.retarget(read_raw(path), d.neutral, face, marks)
        step = max(1, take.frames.shape[0] // 250)
        cand = [i for i, n in enumerate(take.names) if n not in set(lomo.RIGID)]
        picked = lomo.held_out_markers(take.rest, take.frames, cand, 8)
        got = lomo.lomo(d, take, picked, methods_for, step=step)
        errs = {m: np.concatenate(list(e.values())) for m, e in got.errors.items()}
        for m, e in errs.items():
            every.setdefault(m, []).append(e)
        noise = f"noise {min(NOISE):.5f}-{max(NOISE):.5f} cm"
        print(
            Path(path).stem, noise, " ".join(f"{m}={10 * e.mean():.3f} mm" for m, e in errs.items())
        )
    both = {m: 10 * np.concatenate(e).mean() for m, e in every.items()}
    print("both takes", " ".join(f"{m}={v:.3f} mm" for m, v in both.items()))


if __name__ == "__main__":
    main()
