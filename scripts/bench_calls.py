"""The user's calls end to end: whole `lgi solve` processes on a long take, each timed with its
peak RSS (the process's own, read from `wait4`), medians over `--reps` runs interleaved call by
call so the machine's drift falls on every call alike.

The take: 1,200 frames (`--frames`) of the Live Link recording `alex_rom_4` at 60 Hz, 160
random markers, 0.2 mm noise, 2 % dropouts, written as an npz take; the model: ICT-FaceKit with
a quarter of its shapes held out (`--dataset ict`) or 120 whole-face scans picked from
`jmtechart_myslate_3`'s curves (`--dataset scans`), built and saved once before the runs (not
timed). The calls (`--calls`): exact (no option), `--marker-noise auto` (sigma),
`--recommended`, and `--marker-noise auto --denoise` (denoise); each to the formats given
(`--formats usd pc2 npz`).

    python scripts/bench_calls.py [--dataset ict|scans] [--calls exact sigma recommended denoise]
                                  [--formats pc2] [--reps 3] [--frames 1200] [--stages]

`--stages`: each call once more in a process of its own, its stages timed (wall seconds, from
wrappers around the pipeline's functions) with the process's peak RSS as each stage ends: the
take read, the plan's readings (noise, denoising, the fits' choice, the take prior, the detail
weight), the solve (gaps filled, the core's solve, the local fits' surface or detail blend, the
steady pass), the faults looked for and repaired, and the output written.

Needs ../shared/data beside the checkout (or $LGI_SHARED_DATA). Prints a markdown table."""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import measure_faults as mf

CALLS = {
    "exact": [],
    "sigma": ["--marker-noise", "auto"],
    "recommended": ["--recommended"],
    "denoise": ["--marker-noise", "auto", "--denoise"],
}
SUFFIX = {"usd": ".usd", "pc2": ".pc2", "npz": ".npz"}


def prepare(folder: Path, dataset: str, frames: int) -> tuple[Path, Path]:
    """The model file and the take file of the workload, written into `folder`."""
    import lgi

    d, _, pos, data = mf.data()
    t, given = mf._take_of(d, pos, data, 0, dataset)
    model = lgi.Model.build(given, pos, units="cm")
    model_path = folder / "actor.lgi"
    model.save(model_path)
    take = folder / "take.npz"
    np.savez(
        take,
        markers=np.asarray(t.frames[:frames], dtype=np.float64),
        names=np.array(model.marker_names),
        units=np.str_("cm"),
        fps=np.float64(60.0),
    )
    return model_path, take


def run(argv: list[str]) -> tuple[float, float]:
    """Wall seconds and peak RSS (GiB) of one `lgi` process."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    seconds = time.perf_counter() - t0
    err = proc.stderr.read().decode() if proc.stderr else ""
    if status != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({status}):\n{err}")
    return seconds, usage.ru_maxrss / 2**20  # KiB on Linux


STAGES = [
    ("read the take", "lgi.app.pipeline", "read_take"),
    ("plan: noise", "lgi.plan.choices", "marker_noise"),
    ("plan: denoise", "lgi.plan.choices", "take_denoised"),
    ("plan: fits' choice (local fits, box)", "lgi.plan.choices", "fits_choice"),
    ("plan: take prior", "lgi.plan.choices", "take_prior_choice"),
    ("plan: detail weight", "lgi.plan.choices", "detail_weight"),
    ("solve: the take's motion read (the fill's choice)", "lgi.solve.model", "Model._fill_motion"),
    ("solve: gaps filled", "lgi.solve.model", "Model._gaps_filled"),
    ("solve: local fits / detail", "lgi.solve.model", "Model._finish_steadied"),
    ("solve: steady", "lgi.solve.model", "steadied"),
    ("solve and repair (all; core = the rest)", "lgi.app.pipeline", "solve_take"),
    ("write", "lgi.app.pipeline", "write_solved"),
]
"""(stage, module, function): the `solve:` stages count only within `solve_take` (the readings
solve their left-out rows with the same functions). The calls here are steady solves, whose
local fits and detail are `Model._finish_steadied`'s."""


def staged(argv: list[str]) -> None:
    """Runs `lgi` with `argv` in this process, each of `STAGES` timed, and prints one JSON
    line: stage -> [seconds, calls, peak RSS GiB when it last ended]."""
    import importlib
    import json
    import resource

    spent: dict[str, list[float]] = {}
    final = [False]  # within solve_take

    def wrapped(name: str, fn):  # type: ignore[no-untyped-def]
        outer = fn.__name__ == "solve_take"

        def timed(*args, **kw):  # type: ignore[no-untyped-def]
            if name.startswith("solve:") and not final[0]:
                return fn(*args, **kw)
            final[0] = final[0] or outer
            t0 = time.perf_counter()
            try:
                return fn(*args, **kw)
            finally:
                final[0] = final[0] and not outer
                got = spent.setdefault(name, [0.0, 0, 0.0])
                got[0] += time.perf_counter() - t0
                got[1] += 1
                got[2] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20

        return timed

    for name, module, attr in STAGES:
        owner = importlib.import_module(module)
        *path, leaf = attr.split(".")
        for part in path:
            owner = getattr(owner, part)
        setattr(owner, leaf, wrapped(name, getattr(owner, leaf)))
    from lgi.app.main import entry

    sys.argv = ["lgi", *argv]
    t0 = time.perf_counter()
    try:
        entry()
    except SystemExit as e:
        if e.code not in (0, None):
            raise
    spent["whole process (after imports)"] = [time.perf_counter() - t0, 1, 0.0]
    print(json.dumps(spent))


def stage_table(lgi_cmd: list[str], argv_of: dict[str, list[str]]) -> None:
    """Each call's stages (`staged`, a process each), as a markdown table."""
    import json

    rows: dict[str, dict[str, list[float]]] = {}
    for call, argv in argv_of.items():
        out = subprocess.run(
            [*lgi_cmd[:1], __file__, "--run-staged", *argv], capture_output=True, text=True
        )
        if out.returncode != 0:
            raise SystemExit(f"stages of {call} failed:\n{out.stderr}")
        rows[call] = json.loads(out.stdout.strip().splitlines()[-1])
    calls = list(rows)
    print("\n| stage | " + " | ".join(calls) + " |")
    print("|---|" + "---|" * len(calls))
    names = [n for n, _, _ in STAGES] + ["whole process (after imports)"]
    for n in names:
        cells = []
        for c in calls:
            got = rows[c].get(n)
            cells.append(
                "-"
                if got is None
                else f"{got[0]:.2f} s" + (f" ({got[2]:.2f} GiB)" if got[2] else "")
            )
        print(f"| {n} | " + " | ".join(cells) + " |")


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--run-staged":
        staged(sys.argv[2:])
        return
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--dataset", choices=["ict", "scans"], default="ict")
    ap.add_argument("--calls", nargs="+", choices=list(CALLS), default=list(CALLS))
    ap.add_argument("--formats", nargs="+", choices=list(SUFFIX), default=["pc2"])
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--frames", type=int, default=1200)
    ap.add_argument("--stages", action="store_true")
    args = ap.parse_args()
    lgi_cmd = [sys.executable, "-m", "lgi.app.main"]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        model, take = prepare(folder, args.dataset, args.frames)
        times: dict[tuple[str, str], list[tuple[float, float]]] = {}
        for _ in range(args.reps):
            for call in args.calls:
                for fmt in args.formats:
                    out = folder / f"out{SUFFIX[fmt]}"
                    argv = [*lgi_cmd, "solve", str(model), str(take), "-o", str(out), "-q"]
                    times.setdefault((call, fmt), []).append(run([*argv, *CALLS[call], "--force"]))
                    out.unlink(missing_ok=True)
    frames = args.frames
    print(f"{args.dataset}, {frames} frames, median of {args.reps} (range)\n")
    print("| call | output | wall | per frame | peak RSS |")
    print("|---|---|---|---|---|")
    for (call, fmt), got in times.items():
        wall = [w for w, _ in got]
        rss = [r for _, r in got]
        med = statistics.median(wall)
        print(
            f"| {call} | {fmt} | {med:.1f} s ({min(wall):.1f}-{max(wall):.1f}) | "
            f"{1000 * med / frames:.1f} ms | {statistics.median(rss):.2f} GiB |"
        )
    if args.stages:
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp)
            model, take = prepare(folder, args.dataset, args.frames)
            out = folder / "out.pc2"
            base = ["solve", str(model), str(take), "-o", str(out), "-q", "--force"]
            stage_table(lgi_cmd, {c: [*base, *CALLS[c]] for c in args.calls})


if __name__ == "__main__":
    main()
