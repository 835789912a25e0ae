"""lgi: Local Geometric Indexing of facial shapes from sparse motion-capture markers.

Every marker ("bundle") looks up local geometry that really occurred in a dataset of facial
shapes; the pieces are sewn so that the surface passes exactly through every marker.

The package is grouped by job (docs/architecture.md): `io` (files in and out), `data` (datasets
and what is made of them), `solve` (the model and what a solve applies), `capture` (cameras to
bundles), `plan` (the readings behind `--recommended`), `review` (findings, report, viewer) and
`app` (the command line and the pipeline of a take). `lab` is the evaluation harness, not the
library. This module re-exports the library's faces: `Model`, `Dataset` and their results, the
readings, the errors, the thread pool, and the subpackages `io`, `capture`, `jaw` and `rig`.
Each is imported on first use (PEP 562), so `import lgi` and the `lgi` command start without
loading numpy, the core or USD: a Ctrl-C then ends the command in lgi's words, however early.
"""

from __future__ import annotations

import importlib

from lgi.errors import (
    DatasetError,
    DatasetFileError,
    FileWriteError,
    InputError,
    LgiError,
    LgiWarning,
    MarkerError,
    ModelFormatError,
)

# `typing` itself costs ~17 ms at start: the names below are for type checkers only.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any

    from lgi import capture, io
    from lgi._lgi import Choices, SolveResult, __version__, get_num_threads, set_num_threads
    from lgi.data.dataset import Dataset
    from lgi.plan.choices import SolvePlan, plan_solve
    from lgi.plan.denoise import DenoisedTake, denoise_take
    from lgi.plan.detail import estimate_detail_weight
    from lgi.plan.local import LocalFitsEstimate, estimate_local_fits
    from lgi.plan.noise import estimate_marker_noise
    from lgi.plan.take_prior import estimate_take_prior
    from lgi.plan.take_prior_use import TakePriorEstimate, estimate_take_prior_use
    from lgi.plan.unbounded import UnboundedFitEstimate, estimate_unbounded_fit
    from lgi.solve import jaw, rig
    from lgi.solve.model import BuildConfig, Model
    from lgi.solve.options import SolveOptions
    from lgi.solve.take_prior import TakePrior

__all__ = [
    "BuildConfig",
    "Choices",
    "Dataset",
    "DatasetError",
    "DatasetFileError",
    "DenoisedTake",
    "FileWriteError",
    "InputError",
    "LgiError",
    "LgiWarning",
    "LocalFitsEstimate",
    "MarkerError",
    "Model",
    "ModelFormatError",
    "SolveOptions",
    "SolvePlan",
    "SolveResult",
    "TakePrior",
    "TakePriorEstimate",
    "UnboundedFitEstimate",
    "__version__",
    "capture",
    "denoise_take",
    "estimate_detail_weight",
    "estimate_local_fits",
    "estimate_marker_noise",
    "estimate_take_prior",
    "estimate_take_prior_use",
    "estimate_unbounded_fit",
    "get_num_threads",
    "io",
    "jaw",
    "plan_solve",
    "rig",
    "set_num_threads",
]

# Where each face lives: imported on first use, then kept as this module's attribute.
_FACES = {
    "BuildConfig": "lgi.solve.model",
    "Choices": "lgi._lgi",
    "Dataset": "lgi.data.dataset",
    "DenoisedTake": "lgi.plan.denoise",
    "LocalFitsEstimate": "lgi.plan.local",
    "Model": "lgi.solve.model",
    "SolveOptions": "lgi.solve.options",
    "SolvePlan": "lgi.plan.choices",
    "SolveResult": "lgi._lgi",
    "TakePrior": "lgi.solve.take_prior",
    "TakePriorEstimate": "lgi.plan.take_prior_use",
    "UnboundedFitEstimate": "lgi.plan.unbounded",
    "__version__": "lgi._lgi",
    "denoise_take": "lgi.plan.denoise",
    "estimate_detail_weight": "lgi.plan.detail",
    "estimate_local_fits": "lgi.plan.local",
    "estimate_marker_noise": "lgi.plan.noise",
    "estimate_take_prior": "lgi.plan.take_prior",
    "estimate_take_prior_use": "lgi.plan.take_prior_use",
    "estimate_unbounded_fit": "lgi.plan.unbounded",
    "get_num_threads": "lgi._lgi",
    "plan_solve": "lgi.plan.choices",
    "set_num_threads": "lgi._lgi",
}
# The subpackages re-exported, and the rooms (`lgi.solve`, `lgi.plan`, ...) reached by attribute.
_MODULES = {
    "capture": "lgi.capture",
    "io": "lgi.io",
    "jaw": "lgi.solve.jaw",
    "rig": "lgi.solve.rig",
    **{room: f"lgi.{room}" for room in ("app", "data", "lab", "plan", "review", "solve")},
}


def __getattr__(name: str) -> Any:
    if name in _MODULES:
        value: Any = importlib.import_module(_MODULES[name])
    elif name in _FACES:
        value = getattr(importlib.import_module(_FACES[name]), name)
    else:
        raise AttributeError(f"module 'lgi' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
