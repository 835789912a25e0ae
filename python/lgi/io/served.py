"""The types `lgi.io` writes, recognised by name. Arrows point one way: io never imports the
dataset or the model it serves (they import io to read their own files), so a writer that must
tell a `Dataset` or a `Model` from an array checks the class by its full name."""

from __future__ import annotations

__all__ = ["is_a"]


def is_a(value: object, qualified: str) -> bool:
    """`isinstance(value, C)` for the class whose module path and name are `qualified`
    ("lgi.data.dataset.Dataset"), without importing it."""
    module, _, name = qualified.rpartition(".")
    return any(c.__module__ == module and c.__name__ == name for c in type(value).__mro__)
