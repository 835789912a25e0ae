"""A real Ctrl-C in the middle of a solve, for the tests that check it stops the solve early."""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

# Longest a later frame waits for the signal to have been sent (seconds).
SEND_WAIT = 10.0


def sigint_at(frame: int, calls: list[int]) -> Callable[[int], None]:
    """A progress callback that appends each frame to `calls` and, at `frame`, has another
    thread send this process a real SIGINT (delivered to the main thread's handler, usually
    while the solve runs in Rust). Later frames wait until it was sent: on a loaded machine
    the sending thread may not run before a fast solve ends, which made the tests flaky."""
    sent = threading.Event()

    def send() -> None:
        os.kill(os.getpid(), signal.SIGINT)
        sent.set()

    def progress(f: int) -> None:
        calls.append(f)
        if f == frame:
            threading.Thread(target=send).start()
        elif f > frame and not sent.is_set():
            sent.wait(SEND_WAIT)

    return progress


@contextmanager
def python_sigint_handler() -> Iterator[None]:
    """Python's own SIGINT handler for the duration: a process started in the background by
    a non-interactive shell (`cmd &`) inherits SIGINT ignored, and Python then installs no
    handler, so a real Ctrl-C would raise nothing there."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, before)
