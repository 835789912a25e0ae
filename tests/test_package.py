"""The package's layout: no production module imports the lab (`lgi.lab`: the sample, ground
truth and evaluation), and the package re-exports the library's faces, not the lab or the
application. Each production module is imported in a fresh interpreter, one after another, and
the lab modules it pulled in are named with it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import lgi

PACKAGE = Path(lgi.__file__).parent


def _modules() -> list[str]:
    """Every module of the installed package, by file (importing a package to list it would run
    its `__init__`)."""
    out = []
    for f in sorted(PACKAGE.rglob("*.py")):
        parts = f.relative_to(PACKAGE.parent).with_suffix("").parts
        out.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return out


def _is_lab(name: str) -> bool:
    return name == "lgi.lab" or name.startswith("lgi.lab.")


def test_no_production_module_imports_the_lab() -> None:
    production = [m for m in _modules() if not _is_lab(m)]
    assert {"lgi", "lgi.io", "lgi.capture", "lgi.pipeline", "lgi.cli"} <= set(production)
    script = (
        "import importlib, json, sys\n"
        "import lgi\n"
        "found = {'lgi.__file__': lgi.__file__}\n"
        f"for name in {production!r}:\n"
        "    importlib.import_module(name)\n"
        "    lab = sorted(m for m in sys.modules if m == 'lgi.lab' or m.startswith('lgi.lab.'))\n"
        "    if lab:\n"
        "        found[name] = lab\n"
        "        break\n"
        "print(json.dumps(found))\n"
    )
    run = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=False
    )
    assert run.returncode == 0, run.stderr
    found = json.loads(run.stdout.strip().splitlines()[-1])
    assert found.pop("lgi.__file__") == lgi.__file__  # the package under test, not another
    assert found == {}, f"a production module imports the lab: {found}"


def test_the_package_exports_the_library_faces_only() -> None:
    exported = set(lgi.__all__)
    assert {"Model", "Dataset", "BuildConfig", "SolveResult", "io", "capture", "jaw"} <= exported
    assert not exported & {"lab", "pipeline", "batch", "cli", "sample", "evaluate"}
    assert all(hasattr(lgi, name) for name in exported)
