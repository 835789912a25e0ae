"""Every CSV lgi reads (marker layouts, marker takes, Live Link Face curves) opened one way."""

from __future__ import annotations

import csv
import os

from lgi.errors import InputError


def read_csv_rows(path: str | os.PathLike[str], what: str) -> tuple[str, list[list[str]]]:
    """The file's path as a string and its rows (UTF-8, any newline). A missing or unreadable
    file, or one that is not UTF-8 text, is an `InputError` naming the file and `what` it was
    meant to be (e.g. "a marker CSV")."""
    p = os.fspath(path)
    try:
        with open(p, newline="", encoding="utf-8") as fh:
            return p, list(csv.reader(fh))
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise InputError(f"{p}: cannot read {what}: {e}") from None
