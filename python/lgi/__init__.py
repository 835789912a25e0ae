"""lgi: Local Geometric Indexing of facial shapes from sparse motion-capture markers.

Every marker ("bundle") looks up local geometry that really occurred in a dataset of facial
shapes; the pieces are sewn so that the surface passes exactly through every marker.

The package is grouped by job (docs/architecture.md): `io` (files in and out), `data` (datasets
and what is made of them), `solve` (the model and what a solve applies), `capture` (cameras to
bundles), `plan` (the readings behind `--recommended`), `review` (findings, report, viewer) and
`app` (the command line and the pipeline of a take). `lab` is the evaluation harness, not the
library. This module re-exports the library's faces: `Model`, `Dataset` and their results, the
readings, the errors, the thread pool, and the subpackages `io`, `capture`, `jaw` and `rig`.
"""

from lgi import capture, io
from lgi._lgi import (
    Choices,
    SolveResult,
    __version__,
    get_num_threads,
    set_num_threads,
)
from lgi.data.dataset import Dataset
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
from lgi.plan.choices import SolvePlan, plan_solve
from lgi.plan.denoise import DenoisedTake, denoise_take
from lgi.plan.detail import estimate_detail_weight
from lgi.plan.local import LocalFitsEstimate, estimate_local_fits
from lgi.plan.noise import estimate_marker_noise
from lgi.plan.take_prior import TakePriorEstimate, estimate_take_prior, estimate_take_prior_use
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
