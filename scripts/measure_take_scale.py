"""Usage: python scripts/measure_take_scale.py (from the checkout, ../shared beside it).
Measured size factors (docs/reliability.md): ICT captures from both Live Link recordings,
and markers sampled on ICT's five identity meshes against the generic layout."""

import numpy as np

from lgi.data.dataset import Dataset
from lgi.io.livelink import read_livelinkface
from lgi.lab import ict
from lgi.lab.capture import make_capture, marker_samples
from lgi.solve.placement import take_scale

D = "../shared/data/ict-facekit"
d = ict.load_dataset(D)
lay = ict.load_layout(D)
for rec in ["alex_rom_4", "jmtechart_myslate_3"]:
    c = read_livelinkface(f"../shared/data/livelinkface/{rec}.csv")
    w = c.for_dataset(d.names)
    for seed in (0, 1):
        t = make_capture(
            d, w[:200], lay.positions, sigma=0.05, dropout=0.02, holdout=0, seed=seed, jaw=None
        )
        f = take_scale(t.frames, lay.positions)
        print(rec, seed, round(f.factor, 4), round(f.spread, 4))
for k in range(5):
    idd = Dataset.from_obj(f"{D}/identities/identity{k:03d}.obj", [])
    pts = marker_samples(d, lay.positions, np.asarray(idd.neutral)[None])
    f = take_scale(pts, lay.positions)
    print("identity", k, round(f.factor, 4))
