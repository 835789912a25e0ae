"""Times what a TD waits for on a solved take: `lgi report SOLVED` (whole command) and `lgi
view SOLVED` until the first frame is drawn in headless Chromium (from the command's start).
Usage: python scripts/time_view.py SOLVED.npz [--compare REF.npz] [--runs N]."""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from headless import chromium


def time_report(solved: str, compare: str | None) -> float:
    with tempfile.TemporaryDirectory() as d:
        cmd = [
            sys.executable,
            "-m",
            "lgi.app.main",
            "report",
            solved,
            "-o",
            str(Path(d) / "r.html"),
        ]
        t = time.perf_counter()
        subprocess.run(cmd + (["--compare", compare] if compare else []), check=True)
        return time.perf_counter() - t


def time_view(solved: str, compare: str | None) -> float:
    driver = chromium()
    driver.get("about:blank")  # the browser's own start is not lgi's time
    cmd = [sys.executable, "-m", "lgi.app.main", "view", solved]
    t = time.perf_counter()
    proc = subprocess.Popen(
        cmd + (["--compare", compare] if compare else []), stdout=subprocess.PIPE, text=True
    )
    try:
        assert proc.stdout is not None
        url = proc.stdout.readline().split()[2]
        driver.get(url)
        while driver.execute_script("return document.body.dataset.frame") is None:
            time.sleep(0.02)
        return time.perf_counter() - t
    finally:
        proc.terminate()
        proc.wait()
        driver.quit()


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("solved")
    p.add_argument("--compare", default=None)
    p.add_argument("--runs", type=int, default=3)
    a = p.parse_args()
    reports = sorted(time_report(a.solved, a.compare) for _ in range(a.runs))
    views = sorted(time_view(a.solved, a.compare) for _ in range(a.runs))
    print(f"lgi report: median {reports[len(reports) // 2]:.2f} s {[round(x, 2) for x in reports]}")
    print(
        f"lgi view, first frame: median {views[len(views) // 2]:.2f} s "
        f"{[round(x, 2) for x in views]}"
    )


if __name__ == "__main__":
    main()
