"""Ctrl-C, SIGTERM and SIGHUP noted rather than raised, for work that stops at safe points.

Python's own handling raises KeyboardInterrupt wherever the main thread happens to be, and code
there may lose it: an exception in a finalizer is only printed, and pyarrow's conversion of
Python lists sometimes returns normally after the handler ran (``eg2scope batch`` then went on
and exited 0). Noting the signal cannot be lost; the work asks ``noted`` between steps and
raises KeyboardInterrupt itself.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any


@contextmanager
def noted_interrupts() -> Iterator[list[int]]:
    """While inside, SIGINT, SIGTERM and SIGHUP are appended to the list given, not raised.
    Only the main thread can handle signals: elsewhere nothing is noted (and nothing changes)."""
    noted: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield noted
        return

    def note(signum: int, frame: Any) -> None:
        noted.append(signum)

    _NOTING.add(note)
    wanted = [signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None)]
    previous = {sig: signal.signal(sig, note) for sig in wanted if sig is not None}
    try:
        yield noted
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)
        _NOTING.discard(note)


def notes(signum: int) -> bool:
    """Whether ``signum`` is being noted (by ``noted_interrupts``): code that would raise it
    leaves it to the one noting, which acts on it at its own steps."""
    return signal.getsignal(signum) in _NOTING


_NOTING: set[Any] = set()  # the handlers of the noted_interrupts in force
