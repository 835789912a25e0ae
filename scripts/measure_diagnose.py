"""Usage: python scripts/measure_diagnose.py (from the checkout, ../shared beside it).
False findings of lgi.solve.diagnose on clean ICT captures of both Live Link recordings, whole
length, 0.5 mm noise, 2 % dropouts, noise-aware solves, read without and with the solve's
sigma (`noise=`, what `lgi solve` / `info` / `report` pass); then a swapped pair (50 frames)
and a 1 cm spike (3 frames) planted in 300-frame captures (two recordings x three seeds),
read with the solve's sigma (docs/reliability.md)."""

import lgi
from lgi.io.livelink import read_livelinkface
from lgi.lab import ict
from lgi.lab.capture import make_capture
from lgi.solve.diagnose import diagnose

SIGMA = 0.05
D = "../shared/data/ict-facekit"
d = ict.load_dataset(D)
lay = ict.load_layout(D)
m = lgi.Model.build(d, lay.positions)
names = list(m.marker_names)
tot = {False: 0, True: 0}
frames = 0
curves = {}
for rec in ["alex_rom_4", "jmtechart_myslate_3"]:
    w = read_livelinkface(f"../shared/data/livelinkface/{rec}.csv").for_dataset(d.names)
    curves[rec] = w
    for seed in (0, 1):
        t = make_capture(
            d, w, lay.positions, sigma=SIGMA, dropout=0.02, holdout=0, seed=seed, jaw=None
        )
        r = m.solve(t.frames, marker_noise=SIGMA, quiet=True)
        for known in (False, True):
            f = diagnose(
                r.bundle_residuals,
                r.missing,
                names,
                size=m.diagonal,
                markers=t.frames,
                noise=SIGMA if known else None,
            )
            tot[known] += len(f)
            print(rec, seed, t.frames.shape[0], "sigma known" if known else "", len(f))
        frames += t.frames.shape[0]
print("clean findings without sigma", tot[False], "with", tot[True], "frames", frames)
swaps = spikes = runs = 0
for rec, w in curves.items():
    for seed in (1, 2, 3):
        t = make_capture(
            d, w[:300], lay.positions, sigma=SIGMA, dropout=0.02, holdout=0, seed=seed, jaw=None
        )
        x = t.frames.copy()
        x[100:150, [12, 47]] = x[100:150, [47, 12]]
        x[200:203, 33] += [0.0, 0.0, 1.0]
        r = m.solve(x, marker_noise=SIGMA, quiet=True)
        f = diagnose(r.bundle_residuals, r.missing, names, size=m.diagonal, markers=x, noise=SIGMA)
        swaps += any(g.kind == "swap" and (g.first, g.last) == (100, 149) for g in f)
        spikes += any(g.kind == "spike" and g.markers == ("m033",) and g.first == 200 for g in f)
        runs += 1
        print(rec, seed, [g.describe() for g in f])
print(f"planted, sigma known: swap named with its frames {swaps}/{runs}, spike {spikes}/{runs}")
