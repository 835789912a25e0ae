"""Marker faults, model gaps, repair and pops on the capture protocol's takes (ICT-FaceKit with a
quarter of its shapes held out, driven by the shared Live Link recordings; docs/reliability.md).

    python scripts/measure_faults.py findings [--sigma 0 0.02 0.05] [--seeds 0] [--list]
                                              [--holdout 0.25]
        clean takes (markers_120 and 160 random markers, both recordings whole): findings by
        kind; then a swap of two markers 1-2 cm apart (60 frames) and spikes of 1 cm and 0.5 cm
        (3 frames) planted in each: which are named as faults (`--list`: each take's, with
        its markers' dropouts near them and, where missed, what was found on them).
    python scripts/measure_faults.py repair [--seeds 0 1] [--call auto|recommended]
                                            [--dataset ict|scans]
        a 1,200-frame 60 Hz take (160 random markers, 0.2 mm noise, 2 % dropouts) with a swap
        (60 frames) and a 1 cm spike (3 frames): the face-skin error on those frames, repaired
        and kept as given, against the clean take's solve; and the clean take's error over all
        frames with and without repair (`--dataset scans`: the model's dataset as for `pops`).
    python scripts/measure_faults.py study [--seeds 0 1 2] [--dataset ict|scans]
        the detection study: on 1,200-frame takes (markers_120 and 160 random markers, 0.2 mm
        noise, 2 % dropouts) swaps of two markers 0.5-3 cm apart lasting 1-120 frames and
        spikes of 0.3-2 cm lasting 1-5 frames, six planted per take in their own 200 frames;
        per cell, how many were named as faults (and swaps as the swap of that pair), and the
        marker faults named on the clean takes.
    python scripts/measure_faults.py clean [--seeds 0 1] [--dataset ict|scans]
        the study's clean takes solved as `lgi solve` solves them, the fast call and
        --recommended: what the pipeline repairs (nothing where no fault is named).
    python scripts/measure_faults.py fills
        dropouts filled (`lgi.solve.gaps`): on 24 takes (markers_120 and 160 random markers,
        both recordings, the first 1,200 frames, seeds 0 and 1, noise 0, 0.2 and 0.5 mm, 2 %
        dropouts, all of ICT's shapes), each take's dropouts filled as a steady solve fills
        them (the take's motion where its held-out runs say so) and by the markers'
        neighbours alone, against the true markers: mean, 99th percentile and largest miss.
    python scripts/measure_faults.py cost
        the steady solve's cost: the same take solved each frame alone and steady, in-process.
    python scripts/measure_faults.py pops [--seeds 0] [--dataset ict|scans] [--list]
        the same clean take: frames whose face-skin error jumps by more than 2 and 5 mm
        (`lgi.lab.scoring.pops`), the fast call, --recommended and the rig-solve peer; lgi's
        calls each frame alone (`steady=False`), steady with the markers as given
        (`repair=False`) and steady with the faults its solve shows repaired (the
        default). With `--dataset scans` the model's dataset is 120 whole-face scans
        picked from the other recording's curves (`lgi.lab.scans`), all of ICT's shapes
        kept in the truth.

Needs ../shared/data beside the checkout (or $LGI_SHARED_DATA)."""

from __future__ import annotations

import argparse
import collections
import os
import time
import warnings
from pathlib import Path

import numpy as np

import lgi
from lgi.app.pipeline import plan_take, solve_take
from lgi.io.livelink import read_livelinkface
from lgi.lab import ict
from lgi.lab.baselines import FitJaw
from lgi.lab.capture import make_capture, random_layout
from lgi.lab.scoring import POP_CM, pops
from lgi.solve.diagnose import diagnose

ROOT = Path(__file__).resolve().parents[1]
RECORDINGS = ("alex_rom_4", "jmtechart_myslate_3")


def data() -> tuple[lgi.Dataset, np.ndarray, np.ndarray, Path]:
    folder = ict.find(os.environ.get(ict.ENV), start=ROOT)
    if folder is None:
        raise SystemExit("ICT-FaceKit not found: put ../shared/data beside the checkout")
    d = ict.load_dataset(folder)
    return (
        d,
        ict.load_layout(folder).positions,
        random_layout(d, 160, 1, np.arange(ict.NARROW_FACE)),
        folder,
    )


def curves(d: lgi.Dataset, folder: Path, name: str) -> np.ndarray:
    return read_livelinkface(folder.parent / "livelinkface" / f"{name}.csv").for_dataset(d.names)


def _found(m: lgi.Model, x: np.ndarray, sig: float) -> list:  # type: ignore[type-arg]
    """The findings of `x` solved noise-aware, as `lgi solve` reads them."""
    r = m.solve(x, marker_noise=sig, repair=False, quiet=True)
    names = list(m.marker_names)
    return diagnose(r.bundle_residuals, r.missing, names, size=m.diagonal, markers=x, noise=sig)


def findings(
    sigmas: list[float], seeds: list[int], listed: bool = False, holdout: float = 0.25
) -> None:
    d, markers_120, random_160, folder = data()
    clean: collections.Counter[str] = collections.Counter()
    named: collections.Counter[str] = collections.Counter()
    takes = frames = 0
    for layout, pos in (("markers_120", markers_120), ("random 160", random_160)):
        for rec in RECORDINGS:
            w = curves(d, folder, rec)
            for sigma in sigmas:
                for seed in seeds:
                    t = make_capture(
                        d, w, pos, sigma=sigma, dropout=0.02, holdout=holdout, seed=seed, jaw=None
                    )
                    m = lgi.Model.build(t.dataset, pos)
                    names, n = list(m.marker_names), t.frames.shape[0]
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore", lgi.LgiWarning)
                        sig = lgi.estimate_marker_noise(t.frames, m)

                    for g in _found(m, t.frames, sig):
                        clean[g.kind] += 1
                    x = t.frames.copy()
                    pose = np.nanmedian(x, axis=0)
                    dist = np.linalg.norm(pose[:, None] - pose[None], axis=2)
                    rng = np.random.default_rng(seed + 10)
                    a = int(rng.integers(len(names)))
                    b = int(np.flatnonzero((dist[a] > 1.0) & (dist[a] < 2.0))[0])
                    s0, s1, s2 = n // 4, n // 2, (3 * n) // 4
                    x[s0 : s0 + 60, [a, b]] = x[s0 : s0 + 60, [b, a]]
                    c, e = (int(k) for k in rng.choice(len(names), 2, replace=False))
                    x[s1 : s1 + 3, c] += [0.0, 0.0, 1.0]
                    x[s2 : s2 + 3, e] += [0.0, 0.5, 0.0]
                    got = _found(m, x, sig)
                    hit = {
                        "swap": any(
                            g.kind == "swap" and set(g.markers) == {names[a], names[b]} for g in got
                        )
                    }
                    for key, k, s in (("spike 1 cm", c, s1), ("spike 0.5 cm", e, s2)):
                        hit[key] = any(
                            g.fault and names[k] in g.markers and g.first <= s + 2 and g.last >= s
                            for g in got
                        )
                    named.update({key: int(v) for key, v in hit.items()})
                    takes, frames = takes + 1, frames + n
                    print(layout, rec, sigma, seed, n, f"noise read {sig:.2g}", flush=True)
                    if listed:
                        lost = np.isnan(t.frames).any(axis=2)
                        for key, ks, s, length in (
                            ("swap", (a, b), s0, 60),
                            ("spike 1 cm", (c,), s1, 3),
                            ("spike 0.5 cm", (e,), s2, 3),
                        ):
                            gone = [int(lost[max(s - 8, 0) : s + length + 8, k].sum()) for k in ks]
                            print(
                                f"  {key} {' '.join(names[k] for k in ks)}, frames {s}-"
                                f"{s + length - 1}: {'named' if hit[key] else 'MISSED'} "
                                f"(missing within 8 frames: {gone})"
                            )
                            if not hit[key]:
                                for g in got:
                                    if {names[k] for k in ks} & set(g.markers):
                                        print(f"    {g.describe()}")
    print(f"clean takes: {takes}, {frames} frames; findings by kind: {dict(clean)}")
    print(f"planted faults named (of {takes}): {dict(named)}")


def take(d: lgi.Dataset, pos: np.ndarray, folder: Path, seed: int):  # type: ignore[no-untyped-def]
    w = curves(d, folder, RECORDINGS[0])[:1200]
    return make_capture(d, w, pos, sigma=0.02, dropout=0.02, holdout=0.25, seed=seed, jaw=None)


def _error(
    m: lgi.Model, opts: lgi.SolveOptions, frames: np.ndarray, fix: bool, truth: np.ndarray,
    rows: slice = slice(None),
) -> tuple[float, float]:  # fmt: skip
    """Mean and max face-skin error (cm) of `frames` solved as `lgi solve` solves them."""
    skin = ict.skin()
    fixed = opts.replace(repair=fix)
    _, r, _ = solve_take(plan_take(frames, m, fixed), m, fixed)
    e = np.linalg.norm(np.asarray(r.vertices)[rows][:, skin] - truth[rows][:, skin], axis=2)
    return float(e.mean()), float(e.max())


def repair(seeds: list[int], call: str, dataset: str = "ict") -> None:
    d, _, pos, folder = data()
    opts = lgi.SolveOptions(marker_noise="auto", recommended=call == "recommended")
    for seed in seeds:
        t, given = _take_of(d, pos, folder, seed, dataset)
        m = lgi.Model.build(given, pos)
        pose = np.nanmedian(t.frames, axis=0)
        dist = np.linalg.norm(pose[:, None] - pose[None], axis=2)
        rng = np.random.default_rng(seed)
        a = int(rng.integers(160))
        b = int(np.argmin(np.abs(dist[a] - 1.5)))
        c = int(rng.integers(160))
        x = t.frames.copy()
        x[300:360, [a, b]] = x[300:360, [b, a]]
        x[700:703, c] += [0.0, 0.0, 1.0]
        truth = np.asarray(t.truth)

        head = f"seed {seed}, {dataset}, {call}"
        print(f"{head}: the clean take's error, all frames (mean / max cm):")
        fixed, kept = (
            _error(m, opts, t.frames, True, truth),
            _error(m, opts, t.frames, False, truth),
        )
        print(f"  repaired {fixed}, kept as given {kept}")
        for name, rows in (("swap", slice(300, 360)), ("spike", slice(700, 703))):
            (cm, cx), (km, kx), (fm, fx) = (
                _error(m, opts, t.frames, True, truth, rows),
                _error(m, opts, x, False, truth, rows),
                _error(m, opts, x, True, truth, rows),
            )  # fmt: skip
            print(
                f"  {name} frames: clean {cm:.4f} / {cx:.3f}; kept as given {km:.4f} / {kx:.3f} "
                f"({km / cm:.2f} x mean); repaired {fm:.4f} / {fx:.3f} ({fm / cm:.2f} x mean, "
                f"{fx / cx:.2f} x max)",
                flush=True,
            )


def _accel(x: np.ndarray) -> np.ndarray:
    """(F - 2, V) each vertex's second difference in time (its one-frame excursion), cm."""
    return np.linalg.norm(x[2:] - 2.0 * x[1:-1] + x[:-2], axis=2)


def _pop_list(vertices: np.ndarray, truth: np.ndarray, rest: np.ndarray) -> None:
    """Each frame the error pops above 2 mm: the vertex (its rest position), its error's jump,
    and the second differences there of the true face and of the solved surface."""
    skin = ict.skin()
    v, tr = np.asarray(vertices)[:, skin], truth[:, skin]
    err = np.linalg.norm(v - tr, axis=2)
    jump = np.abs(err[2:] - 2.0 * err[1:-1] + err[:-2])
    face, solved = _accel(tr), _accel(v)
    for f in np.flatnonzero(jump.max(axis=1) > POP_CM[0]):
        k = int(jump[f].argmax())
        print(
            f"  frame {f + 1}: error jump {10 * jump[f, k]:.1f} mm at {np.round(rest[skin][k], 1)} "
            f"cm; the face's second difference {10 * face[f, k]:.1f} mm, the solve's "
            f"{10 * solved[f, k]:.1f} mm"
        )


def _pops(label: str, vertices: np.ndarray, truth: np.ndarray, seconds: float) -> None:
    """The error's pops (`lgi.lab.scoring.pops`), and the frames where the solved surface
    itself jumps by more than the true face does (beyond 2 mm at some vertex): an error pop
    where the face moves fast and the solve does not follow is the dataset's reach, this one
    the solve's own."""
    skin = ict.skin()
    v, tr = np.asarray(vertices)[:, skin], truth[:, skin]
    err = np.linalg.norm(v - tr, axis=2)
    own = int(((_accel(v) - _accel(tr)).max(axis=1) > POP_CM[0]).sum())
    print(
        f"{label}: mean {err.mean():.4f} cm; pops > 2 mm {pops(err, POP_CM[0])}, > 5 mm "
        f"{pops(err, POP_CM[1])}; the surface jumping > 2 mm more than the face {own}; of "
        f"{err.shape[0]} frames ({seconds:.1f} s)",
        flush=True,
    )


def _scans_take(d: lgi.Dataset, pos: np.ndarray, folder: Path, seed: int):  # type: ignore[no-untyped-def]
    """The 1,200-frame take of the first recording, and a dataset of 120 scans picked from
    the second recording's curves (no held-out shapes: the scans are the dataset)."""
    from lgi.lab.scans import scan_session

    session = scan_session(d, curves(d, folder, RECORDINGS[1]), 120, None, None)
    w = curves(d, folder, RECORDINGS[0])[:1200]
    t = make_capture(d, w, pos, sigma=0.02, dropout=0.02, holdout=0.0, seed=seed, jaw=None)
    return t, session.dataset


def _take_of(d: lgi.Dataset, pos: np.ndarray, folder: Path, seed: int, dataset: str):  # type: ignore[no-untyped-def]
    """The 1,200-frame take and the dataset its model is built from (`dataset` "ict": ICT with
    a quarter of its shapes held out; "scans": `_scans_take`)."""
    if dataset == "scans":
        return _scans_take(d, pos, folder, seed)
    t = take(d, pos, folder, seed)
    return t, t.dataset


def fills() -> None:
    from lgi.solve import gaps
    from lgi.solve.detail import rest_positions

    d, markers_120, random_160, folder = data()
    rows = []
    for layout, pos in (("markers_120", markers_120), ("random 160", random_160)):
        model = lgi.Model.build(d, pos)
        rest = rest_positions(model)
        for rec in RECORDINGS:
            w = curves(d, folder, rec)[:1200]
            for seed in (0, 1):
                for sigma in (0.0, 0.02, 0.05):
                    t = make_capture(
                        d, w, pos, sigma=sigma, dropout=0.02, holdout=0.0, seed=seed, jaw=None
                    )
                    frames = np.asarray(t.frames)
                    true = model.bundle_positions(np.asarray(t.truth))
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")  # the noise-free takes' reading
                        sig = lgi.estimate_marker_noise(frames, model)
                    t0 = time.perf_counter()
                    motion = gaps.fill_motion(frames, rest, sig)
                    took = time.perf_counter() - t0
                    by_take, done = gaps.filled(frames, rest, motion)
                    by_neighbours, done_n = gaps.filled(frames, rest)
                    both = done & done_n
                    miss = [
                        10.0 * np.linalg.norm(x - true, axis=2)[both]
                        for x in (by_take, by_neighbours)
                    ]
                    stats = [(m.mean(), np.percentile(m, 99), m.max()) for m in miss]
                    rows.append(stats)
                    rank = "neighbours" if motion is None else f"rank {motion.rank}"
                    print(
                        f"{layout}, {rec}, seed {seed}, {10 * sigma:.1f} mm: {rank} "
                        f"({took:.2f} s); filled {stats[0][0]:.3f} / {stats[0][1]:.2f} / "
                        f"{stats[0][2]:.2f} mm, neighbours {stats[1][0]:.3f} / {stats[1][1]:.2f}"
                        f" / {stats[1][2]:.2f} mm ({both.sum()} samples)",
                        flush=True,
                    )
    r = np.array(rows)  # (takes, 2, 3)
    print(
        f"{len(rows)} takes (mean, 99th percentile, largest miss, mm): filled "
        f"{r[:, 0, 0].mean():.3f} / {r[:, 0, 1].mean():.2f} / {r[:, 0, 2].max():.2f}, "
        f"neighbours {r[:, 1, 0].mean():.3f} / {r[:, 1, 1].mean():.2f} / {r[:, 1, 2].max():.2f};"
        f" filled nearer in mean on {(r[:, 0, 0] < r[:, 1, 0]).sum()}, at the 99th percentile "
        f"on {(r[:, 0, 1] < r[:, 1, 1]).sum()}, in the largest miss on "
        f"{(r[:, 0, 2] < r[:, 1, 2]).sum()}"
    )


def pop_counts(seeds: list[int], dataset: str, listed: bool) -> None:
    d, _, pos, folder = data()
    for seed in seeds:
        t, given = _take_of(d, pos, folder, seed, dataset)
        m = lgi.Model.build(given, pos)
        truth = np.asarray(t.truth)
        sig = lgi.estimate_marker_noise(t.frames, m)
        if m.jaw_rig is not None:  # the peer skins the fit's jaw pose (a scans model has none)
            t0 = time.perf_counter()
            peer = FitJaw(m).solve(t.frames, quiet=True)
            took = time.perf_counter() - t0
            _pops(f"seed {seed}, rig solve (fit + jaw)", peer.vertices, truth, took)
        plan = lgi.plan_solve(t.frames, m, recommended=True)
        for steady, fix, how in (
            (False, False, "each frame alone"),
            (True, False, "steady"),
            (True, True, "steady + repair (the default)"),
        ):
            t0 = time.perf_counter()
            fast = m.solve(t.frames, marker_noise=sig, steady=steady, repair=fix, quiet=True)
            took = time.perf_counter() - t0
            _pops(f"seed {seed}, --marker-noise auto, {how}", fast.vertices, truth, took)
            if listed and steady and not fix:
                _pop_list(fast.vertices, truth, np.asarray(given.neutral))
            t0 = time.perf_counter()
            opts = plan.options.replace(steady=steady, repair=fix)
            solved = m.solve(plan.frames, options=opts, quiet=True)
            took = time.perf_counter() - t0
            _pops(f"seed {seed}, --recommended, {how}", solved.vertices, truth, took)
            if listed and steady and not fix:
                _pop_list(solved.vertices, truth, np.asarray(given.neutral))


SWAP_CM = (0.5, 1.0, 2.0, 3.0)
SWAP_FRAMES = (1, 5, 30, 120)
SPIKE_CM = (0.3, 0.5, 1.0, 2.0)
SPIKE_FRAMES = (1, 3, 5)


def _planted(x: np.ndarray, cells: list, rng: np.random.Generator):  # type: ignore[type-arg]
    """`x` with each cell planted in its own 200-frame window on markers of its own, seen on
    every planted frame (a fault on a dropout is no fault): a swap ("swap", cm, frames) of two
    markers about cm apart, a spike ("spike", cm, frames) of one marker moved cm in a random
    direction; with where each went."""
    x = x.copy()
    pose = np.nanmedian(x, axis=0)
    dist = np.linalg.norm(pose[:, None] - pose[None], axis=2)
    used: set[int] = set()
    placed = []
    seen = np.isfinite(x).all(axis=2)
    for k, (kind, cm, n) in enumerate(cells):
        start = 200 * k + 40
        free = [
            i
            for i in rng.permutation(x.shape[1])
            if i not in used and seen[start : start + n, i].all()
        ]
        if kind == "swap":
            for a in free:
                near = [j for j in np.flatnonzero(np.abs(dist[a] - cm) < 0.25 * cm) if j in free]
                if near:
                    b = int(rng.choice(near))
                    break
            else:
                continue
            x[start : start + n, [a, b]] = x[start : start + n, [b, a]]
            used |= {int(a), b}
            placed.append((kind, cm, n, (int(a), b), start))
        else:
            a = int(free[0])
            d = rng.normal(size=3)
            x[start : start + n, a] += cm * d / np.linalg.norm(d)
            used.add(a)
            placed.append((kind, cm, n, (a,), start))
    return x, placed


def study(seeds: list[int], dataset: str) -> None:
    d, markers_120, random_160, folder = data()
    cells = [("swap", c, n) for c in SWAP_CM for n in SWAP_FRAMES]
    cells += [("spike", c, n) for c in SPIKE_CM for n in SPIKE_FRAMES]
    named: collections.Counter[tuple] = collections.Counter()  # type: ignore[type-arg]
    as_swap: collections.Counter[tuple] = collections.Counter()  # type: ignore[type-arg]
    tried: collections.Counter[tuple] = collections.Counter()  # type: ignore[type-arg]
    false_faults = clean_frames = 0
    for layout, pos in (("markers_120", markers_120), ("random 160", random_160)):
        for seed in seeds:
            t, given = _take_of(d, pos, folder, seed, dataset)
            m = lgi.Model.build(given, pos)
            names = list(m.marker_names)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", lgi.LgiWarning)
                sig = lgi.estimate_marker_noise(t.frames, m)
            clean = [g for g in _found(m, t.frames, sig) if g.fault]
            false_faults += len(clean)
            clean_frames += t.frames.shape[0]
            rng = np.random.default_rng(1000 + seed)
            order = [cells[i] for i in rng.permutation(len(cells))]
            for group in range(0, len(order), 6):
                x, placed = _planted(t.frames, order[group : group + 6], rng)
                got = [g for g in _found(m, x, sig) if g.fault]
                for kind, cm, n, who, start in placed:
                    key = (kind, cm, n)
                    tried[key] += 1
                    hit = [
                        g
                        for g in got
                        if {names[k] for k in who} & set(g.markers)
                        and g.first <= start + n - 1
                        and g.last >= start
                    ]
                    named[key] += bool(hit)
                    as_swap[key] += any(
                        g.kind == "swap" and set(g.markers) == {names[k] for k in who} for g in hit
                    )
            print(layout, seed, "clean faults", len(clean), flush=True)
    print(f"\n{dataset}: clean takes {clean_frames} frames, marker faults named {false_faults}")
    print("| fault | size | frames | named as a fault | named as that swap |")
    print("|---|---|---|---|---|")
    for key in cells:
        kind, cm, n = key
        swap = f"{as_swap[key]}/{tried[key]}" if kind == "swap" else "-"
        print(f"| {kind} | {cm} cm | {n} | {named[key]}/{tried[key]} | {swap} |")


def clean(seeds: list[int], dataset: str) -> None:
    """What the pipeline repairs on the study's clean takes (both layouts, each seed), with the
    fast call and with `--recommended`, as `lgi solve` solves them: nothing, where no fault is
    named."""
    d, markers_120, random_160, folder = data()
    for layout, pos in (("markers_120", markers_120), ("random 160", random_160)):
        for seed in seeds:
            t, given = _take_of(d, pos, folder, seed, dataset)
            m = lgi.Model.build(given, pos)
            for call, opts in (
                ("--marker-noise auto", lgi.SolveOptions(marker_noise="auto")),
                ("--recommended", lgi.SolveOptions(recommended=True)),
            ):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", lgi.LgiWarning)
                    solved, _, _ = solve_take(plan_take(t.frames, m, opts), m, opts)
                repairs = solved.settings.repairs
                print(f"{dataset}, {layout}, seed {seed}, {call}: repaired {list(repairs)}")


def steady_cost(seeds: list[int]) -> None:
    """`Model.solve` of the 1,200-frame take with `--marker-noise auto`'s sigma, each frame alone
    and steady (no repair), three runs alternating, in-process."""
    import statistics

    d, _, pos, folder = data()
    t = take(d, pos, folder, seeds[0])
    m = lgi.Model.build(t.dataset, pos)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", lgi.LgiWarning)
        sig = lgi.estimate_marker_noise(t.frames, m)
    m.solve(t.frames[:50], marker_noise=sig, quiet=True)  # the first solve's one-time work
    got: dict[bool, list[float]] = {False: [], True: []}
    for _ in range(3):
        for steady in (False, True):
            t0 = time.perf_counter()
            m.solve(t.frames, marker_noise=sig, steady=steady, repair=False, quiet=True)
            got[steady].append(time.perf_counter() - t0)
    for steady, times in got.items():
        runs = ", ".join(f"{x:.2f}" for x in times)
        how = "steady" if steady else "each frame alone"
        print(f"{how}: {runs} s, median {statistics.median(times):.2f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument(
        "what", choices=["findings", "repair", "pops", "study", "clean", "cost", "fills"]
    )
    ap.add_argument("--sigma", type=float, nargs="+", default=[0.0, 0.02, 0.05])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument(
        "--holdout", type=float, default=0.25, help="findings: the share of ICT's shapes held out"
    )
    ap.add_argument("--call", choices=["auto", "recommended"], default="auto")
    ap.add_argument("--dataset", choices=["ict", "scans"], default="ict")
    ap.add_argument(
        "--list",
        action="store_true",
        help="pops: each pop of both steady calls (markers as given), where and why; findings: "
        "each take's planted faults, named or missed, and what was found on their markers",
    )
    args = ap.parse_args()
    if args.what == "findings":
        findings(args.sigma, args.seeds, args.list, args.holdout)
    elif args.what == "repair":
        repair(args.seeds, args.call, args.dataset)
    elif args.what == "study":
        study(args.seeds, args.dataset)
    elif args.what == "clean":
        clean(args.seeds, args.dataset)
    elif args.what == "cost":
        steady_cost(args.seeds)
    elif args.what == "fills":
        fills()
    else:
        pop_counts(args.seeds, args.dataset, args.list)


if __name__ == "__main__":
    main()
