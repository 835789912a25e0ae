"""Exception classes raised by lgi (from Python and from the Rust core alike)."""


class LgiError(Exception):
    """Base class of every error lgi raises on purpose."""


class DatasetError(LgiError):
    """A dataset or mesh file is malformed or inconsistent (message names file and element)."""


class DatasetFileError(DatasetError, FileNotFoundError):
    """A dataset file is missing or unreadable."""


class FileWriteError(LgiError, OSError):
    """A file could not be written (missing directory, permissions, disk full)."""


class InputError(LgiError, ValueError):
    """An argument has the wrong shape, dtype or value (message names the argument)."""


class MarkerError(InputError):
    """A marker cannot be placed on the neutral surface: probably mislabelled or wrong unit."""


class LgiWarning(UserWarning):
    """A result that is valid but probably not what was meant (e.g. a build that left most
    markers without tets)."""


class ModelFormatError(LgiError):
    """A saved model file is corrupt, truncated, foreign or from an unsupported version."""


__all__ = [
    "DatasetError",
    "DatasetFileError",
    "FileWriteError",
    "InputError",
    "LgiError",
    "LgiWarning",
    "MarkerError",
    "ModelFormatError",
]
