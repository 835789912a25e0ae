"""The package's layout: no production module imports the lab (`lgi.lab`: the sample, ground
truth and evaluation), and the package re-exports the library's faces, not the lab or the
application. Each production module is imported in a fresh interpreter, one after another, and
the lab modules it pulled in are named with it."""

from __future__ import annotations

import ast
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
    assert {"lgi", "lgi.io", "lgi.capture", "lgi.app.pipeline", "lgi.app.cli"} <= set(production)
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


# The rooms of `python/lgi`, lowest first (docs/architecture.md): a module may import its own
# room and the rooms below it, never one above. The lab sits beside the application, above all.
ROOMS = ["errors", "io", "data", "solve", "capture", "plan", "review", "app", "lab"]
# The application's lab commands (`lgi demo`, `lgi evaluate`, `lgi helmet-demo`) import the lab.
MAY_IMPORT_THE_LAB = {"lgi.app.cli"}


def _room(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in ROOMS else None


def _imports(path: Path, module: str) -> set[str]:
    """The lgi modules `path` imports anywhere (functions included), leaving out imports under
    `if TYPE_CHECKING:` (annotations only)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    typing_only = {
        id(n)
        for node in ast.walk(tree)
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
        for n in ast.walk(node)
    }
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("lgi.")}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join([*up, *([base] if base else [])])
            if base == "lgi":
                found |= {f"lgi.{a.name}" for a in node.names}
            elif base.startswith("lgi."):
                found.add(base)
    return found


def _sources() -> dict[str, Path]:
    return dict(zip(_modules(), sorted(PACKAGE.rglob("*.py")), strict=True))


def test_imports_point_down_the_rooms_and_only_the_cli_reaches_the_lab() -> None:
    up: list[str] = []
    for module, path in _sources().items():
        here = _room(module)
        if here is None:
            continue
        for target in _imports(path, module):
            there = _room(target)
            if there is None or there == here:
                continue
            if there == "lab":
                if module not in MAY_IMPORT_THE_LAB:
                    up.append(f"{module} -> {target}")
            elif here != "lab" and ROOMS.index(there) > ROOMS.index(here):
                up.append(f"{module} -> {target}")
    assert up == [], f"imports that point up the rooms: {up}"


def test_no_module_imports_one_that_imports_it_back() -> None:
    sources = _sources()
    graph = {m: _imports(p, m) & set(sources) for m, p in sources.items()}
    both = sorted(
        f"{a} <-> {b}" for a, deps in graph.items() for b in deps if a < b and a in graph.get(b, ())
    )
    assert both == []


def test_at_most_six_modules_at_the_top_of_the_package() -> None:
    top = [f.stem for f in PACKAGE.glob("*.py") if f.stem not in ("__init__", "errors")]
    assert len(top) <= 6, top


def test_no_source_file_is_over_800_lines() -> None:
    """Python and Rust sources, tests and the vendored three.js aside (read from the checkout
    where the tests run beside it)."""
    checkout = Path(__file__).resolve().parents[1]
    files = [*PACKAGE.rglob("*.py")]
    if (checkout / "crates").is_dir():
        files += [
            f
            for f in (checkout / "crates").rglob("*.rs")
            if "tests" not in f.parts and f.name != "tests.rs"
        ]
    long = {
        str(f): n for f in files if (n := len(f.read_text(encoding="utf-8").splitlines())) > 800
    }
    assert long == {}
