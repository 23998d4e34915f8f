"""What outputs say on stderr while the TUI holds the terminal (the Rerun listener's "written
to run.rrd", a web viewer's address): kept line by line, shown in the TUI as notifications as
they come, and printed again on stderr once the terminal is given back."""

from __future__ import annotations

import io
import threading
from collections.abc import Callable
from typing import IO


class Notes(io.TextIOBase):
    """A text stream of whole lines. ``show``: called with each line as it is completed (the
    app's notification, from any thread); ``lines``: every line so far."""

    def __init__(self) -> None:
        super().__init__()
        self.lines: list[str] = []
        self.show: Callable[[str], None] | None = None
        self._part = ""
        self._lock = threading.Lock()

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        with self._lock:
            *done, self._part = (self._part + text).split("\n")
            self.lines += [line for line in done if line.strip()]
        show = self.show
        for line in done:
            if show is not None and line.strip():
                show(line)
        return len(text)

    def print(self, out: IO[str]) -> None:
        """Every line (and an unfinished one) on ``out``."""
        with self._lock:
            lines = self.lines + ([self._part] if self._part.strip() else [])
        for line in lines:
            print(line, file=out)
