"""lgi: Local Geometric Indexing of facial shapes from sparse motion-capture markers.

Every marker ("bundle") looks up local geometry that really occurred in a dataset of facial
shapes; the pieces are sewn so that the surface passes exactly through every marker.
"""

from lgi import camera, export, jaw, rig, rig_export, stabilize, takes
from lgi._lgi import (
    Choices,
    SolveResult,
    __version__,
    get_num_threads,
    set_num_threads,
)
from lgi.dataset import Dataset
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
from lgi.model import BuildConfig, Model, estimate_marker_noise

__all__ = [
    "BuildConfig",
    "Choices",
    "Dataset",
    "DatasetError",
    "DatasetFileError",
    "FileWriteError",
    "InputError",
    "LgiError",
    "LgiWarning",
    "MarkerError",
    "Model",
    "ModelFormatError",
    "SolveResult",
    "__version__",
    "camera",
    "estimate_marker_noise",
    "export",
    "get_num_threads",
    "jaw",
    "rig",
    "rig_export",
    "set_num_threads",
    "stabilize",
    "takes",
]
