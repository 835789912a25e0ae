"""Makes the README's pictures with the commands they show: the built-in sample as files (a C3D
take with two labels swapped for 50 frames and a 1.5 cm spike), `lgi build`, `lgi solve`
(noise-aware and exact), `lgi report`, `lgi view` in headless Chromium, and `lgi demo`'s panel.
Usage: python scripts/docs_pictures.py [OUT_DIR] (default docs/images)."""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from headless import chromium  # noqa: E402
from lgi.lab.sample import make_sample  # noqa: E402
from pipeline_files import write_actor, write_c3d  # noqa: E402


def lgi(*args: object) -> None:
    subprocess.run([sys.executable, "-m", "lgi.app.main", *map(str, args)], check=True)


def main() -> None:
    out = Path(sys.argv[1] if len(sys.argv) > 1 else HERE.parent / "docs" / "images").resolve()
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        s = make_sample(0)
        actor = write_actor(d, s)
        frames = np.asarray(s.performance).copy()
        a, b = actor.names.index("glabella"), actor.names.index("lidLowerOuter_L")
        frames[40:90, [a, b]] = frames[40:90, [b, a]]
        frames[120:123, actor.names.index("mouthCorner_R")] += [0.0, 0.0, 1.5]
        write_c3d(d / "take.c3d", frames, actor.names, 30.0, "cm")
        lgi(
            "build",
            actor.neutral,
            actor.shapes,
            actor.markers,
            "-o",
            d / "m.lgi",
            "--units",
            "cm",
            "-q",
        )
        lgi("solve", d / "m.lgi", d / "take.c3d", "-o", d / "solved.npz", "--marker-noise", "0.02")
        lgi("solve", d / "m.lgi", d / "take.c3d", "-o", d / "exact.npz", "-q")
        lgi("report", d / "solved.npz", "--compare", d / "exact.npz", "-o", d / "report.html")
        driver = chromium()
        try:
            driver.set_window_size(1100, 1500)
            driver.get((d / "report.html").as_uri())
            driver.save_screenshot(str(out / "report.png"))
            driver.set_window_size(1100, 760)
            view = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "lgi.app.main",
                    "view",
                    d / "solved.npz",
                    "--compare",
                    d / "exact.npz",
                ],
                stdout=subprocess.PIPE,
                text=True,
            )
            assert view.stdout is not None
            url = view.stdout.readline().split()[2]
            driver.get(url + "#frame=60")
            while driver.execute_script("return document.body.dataset.frame") != "60":
                time.sleep(0.05)
            driver.execute_script(
                "const c = document.getElementById('colour'); c.value = 'difference';"
                "c.dispatchEvent(new Event('change'));"
            )
            while driver.execute_script("return document.body.dataset.colour") != "difference":
                time.sleep(0.05)
            time.sleep(0.5)
            driver.save_screenshot(str(out / "viewer.png"))
            view.terminate()
        finally:
            driver.quit()
        lgi("demo", "--out", d / "demo", "-q")
        (out / "demo-panel.png").write_bytes((d / "demo" / "panel.png").read_bytes())
    print(f"wrote {out}/report.png, viewer.png and demo-panel.png")


if __name__ == "__main__":
    main()
