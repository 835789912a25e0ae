"""The one output-path check every writer and the pipeline use: a file path (not a folder) in
a folder that exists. Writers replace an old file; refusing a missing folder here, not deep in
a writer, gives one message naming the argument."""

from __future__ import annotations

import os
from pathlib import Path

from lgi.errors import InputError

__all__ = ["output_file"]


def output_file(path: str | os.PathLike[str], what: str) -> Path:
    """An output file path: not a folder, in a folder that exists (an old file is replaced);
    `InputError` naming `what` (the argument: `--out`, "USD output") and the path otherwise."""
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{what} {os.fspath(path)}: is a folder, expected a file path")
    if not p.parent.is_dir():
        raise InputError(f"{what} {os.fspath(path)}: the folder {p.parent} does not exist")
    return p
