"""The `lgi` command's entry, light on purpose: it takes Ctrl-C in hand before Python loads
the rest of lgi (numpy, the core, USD), so a Ctrl-C at any moment, those imports included,
ends the command with one line and exit 130, never a traceback. Some native modules turn an
interrupt that arrives while they load into an error of their own (numpy's C core raises an
ImportError naming `datetime`): one that follows a Ctrl-C is read as the Ctrl-C."""

from __future__ import annotations

import _signal as signal  # `signal` itself imports enum: 8 ms before Ctrl-C is in hand
import sys

__all__ = ["entry"]


def entry() -> None:
    """The `lgi` command: `lgi.app.cli.main`, imported inside the guard."""
    pressed: list[int] = []

    def interrupt(signum: int, _frame: object) -> None:
        pressed.append(signum)
        raise KeyboardInterrupt

    try:
        before = signal.signal(signal.SIGINT, interrupt)
        try:
            from lgi.app.cli import main
        except Exception:
            if pressed:
                raise KeyboardInterrupt from None
            raise
        finally:
            signal.signal(signal.SIGINT, before)
        code = main()
    except KeyboardInterrupt:
        print("lgi: interrupted", file=sys.stderr)
        code = 130
    sys.exit(code)


if __name__ == "__main__":
    entry()
