"""lgi: Local Geometric Indexing of facial shapes from sparse motion-capture markers.

Every marker ("bundle") looks up local geometry that really occurred in a dataset of facial
shapes; the pieces are sewn so that the surface passes exactly through every marker.

The package re-exports the library's faces: `Model`, `Dataset` and their results, the errors,
the thread pool, and the subpackages `io` (files in and out), `capture` (cameras to bundles),
`jaw` and `rig`. The application (`lgi.pipeline`, `lgi.batch`, `lgi.cli`) and the lab
(`lgi.lab`: sample, ground truth, evaluation) are imported by name.
"""

from lgi import capture, io, jaw, rig
from lgi._lgi import (
    Choices,
    SolveResult,
    __version__,
    get_num_threads,
    set_num_threads,
)
from lgi.choices import SolvePlan, plan_solve
from lgi.dataset import Dataset
from lgi.denoise import DenoisedTake, denoise_take
from lgi.detail import estimate_detail_weight
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
from lgi.local import LocalFitsEstimate, estimate_local_fits
from lgi.model import BuildConfig, Model
from lgi.noise import estimate_marker_noise
from lgi.take_prior import (
    TakePrior,
    TakePriorEstimate,
    estimate_take_prior,
    estimate_take_prior_use,
)
from lgi.unbounded import UnboundedFitEstimate, estimate_unbounded_fit

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
