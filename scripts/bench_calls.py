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
                                  [--formats pc2] [--reps 3] [--frames 1200]

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--dataset", choices=["ict", "scans"], default="ict")
    ap.add_argument("--calls", nargs="+", choices=list(CALLS), default=list(CALLS))
    ap.add_argument("--formats", nargs="+", choices=list(SUFFIX), default=["pc2"])
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--frames", type=int, default=1200)
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


if __name__ == "__main__":
    main()
