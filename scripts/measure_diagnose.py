"""Usage: python scripts/measure_diagnose.py (from the checkout, ../shared beside it).
False findings of lgi.diagnose on clean ICT captures of both Live Link recordings, whole
length, 0.5 mm noise, 2 % dropouts, noise-aware solves (docs/reliability.md)."""

import lgi
from lgi.diagnose import diagnose
from lgi.io.livelink import read_livelinkface
from lgi.lab import ict
from lgi.lab.capture import make_capture

D = "../shared/data/ict-facekit"
d = ict.load_dataset(D)
lay = ict.load_layout(D)
m = lgi.Model.build(d, lay.positions)
names = list(m.marker_names)
tot = 0
frames = 0
for rec in ["alex_rom_4", "jmtechart_myslate_3"]:
    w = read_livelinkface(f"../shared/data/livelinkface/{rec}.csv").for_dataset(d.names)
    for seed in (0, 1):
        t = make_capture(
            d, w, lay.positions, sigma=0.05, dropout=0.02, holdout=0, seed=seed, jaw=None
        )
        r = m.solve(t.frames, marker_noise=0.05, quiet=True)
        f = diagnose(r.bundle_residuals, r.missing, names, size=m.diagonal, markers=t.frames)
        tot += len(f)
        frames += t.frames.shape[0]
        print(rec, seed, t.frames.shape[0], len(f), [g.describe() for g in f[:3]])
print("findings", tot, "frames", frames)
