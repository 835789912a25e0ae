"""Ctrl-C is never swallowed. Some native modules catch whatever is raised while they load:
pxr's `Tf_PyPostProcessModule` turns a KeyboardInterrupt arriving during `import pxr` into a
warning, and the command ran on to the end. Code run under `deferred_interrupt` gets no
KeyboardInterrupt; a Ctrl-C pressed meanwhile is raised as soon as the block ends."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

__all__ = ["deferred_interrupt", "import_usd"]


@contextmanager
def deferred_interrupt() -> Iterator[None]:
    """Holds back Ctrl-C during the block and raises it after (main thread only: elsewhere
    Python delivers no signals)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pressed: list[int] = []

    def note(signum: int, _frame: FrameType | None) -> None:
        pressed.append(signum)

    previous = signal.signal(signal.SIGINT, note)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if pressed:
        raise KeyboardInterrupt


def import_usd() -> None:
    """Loads the USD modules lgi uses (`pxr`), Ctrl-C held back until they are in."""
    with deferred_interrupt():
        from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt  # noqa: F401
