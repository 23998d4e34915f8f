"""The events tab: the source's events (a device lost or reopened, drops, a failed output) and
the damage found in a capture, one line each; while there are none it says so."""

from __future__ import annotations

from typing import Any

from rich.text import Text
from textual.widgets import RichLog

EMPTY = "no events yet (a device lost or reopened, dropped items, damage in a capture)"


class EventLog(RichLog):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(max_lines=2000, markup=False, **kwargs)
        self.empty = True

    def on_mount(self) -> None:
        self.write(Text(EMPTY, style="dim"))

    def add(self, line: str) -> None:
        if self.empty:
            self.empty = False
            self.clear()
        self.write(line)

    def ended(self, what: str) -> None:
        """The session is over: none now means none in ``what`` (the capture, the session)."""
        if self.empty:
            self.clear()
            self.write(Text(f"no events in this {what}", style="dim"))
