"""Human-readable output: one line per record, and one per source event.

``  0.012345  can0  → ID 1     CMD_MC_MOVE_CATCH_XG   catch speed=500 force=100 g``
Errors are shown in red and warnings in yellow when the terminal has colour. A latency measured
between times estimated from the line's baud rate is shown as ``~0.41 ms``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import IO

from decoders.flags import ESTIMATED_TIME
from decoders.model import FRAME, REQUEST, RESPONSE, Record

from ..model import SourceEvent
from ..session.listener import Listener

RED, YELLOW, RESET = "\x1b[31m", "\x1b[33m", "\x1b[0m"
ARROWS = {REQUEST: "→", RESPONSE: "←"}


def use_colour(stream: IO[str]) -> bool:
    """Colour only on a terminal, and never when NO_COLOR is set (no-color.org)."""
    if os.environ.get("NO_COLOR"):
        return False
    if os.environ.get("FORCE_COLOR"):
        return True
    isatty = getattr(stream, "isatty", None)
    return bool(isatty and isatty())


class TextFormatter:
    """Formats records as lines; times are shown relative to the first timestamp seen."""

    def __init__(
        self, colour: bool = False, absolute_time: bool = False, t0: float | None = None
    ) -> None:
        """``t0``: the time shown as 0 (a live session's start); default the first record's."""
        self.colour = colour
        self.absolute_time = absolute_time
        self._t0 = t0

    def time_column(self, rec: Record) -> str:
        if rec.t is None:
            where = rec.offset if rec.offset is not None else rec.index
            return f"@{where}".rjust(11)
        if self.absolute_time:
            return f"{rec.t:17.6f}"
        if self._t0 is None:
            self._t0 = rec.t
        return f"{rec.t - self._t0:11.6f}"

    def format(self, rec: Record) -> str:
        arrow = ARROWS.get(rec.direction or "", "·")
        who = f"ID {rec.device}" if rec.device is not None else "-"
        name = (rec.name or rec.protocol) if rec.kind == FRAME else rec.kind.upper()
        parts = [
            self.time_column(rec),
            f"{rec.bus:6}",
            arrow,
            f"{who:8}",
            f"{name:26}",
            rec.summary,
        ]
        if rec.latency_ms is not None and rec.direction == RESPONSE:
            about = "~" if ESTIMATED_TIME in rec.flags else ""
            parts.append(f"({about}{rec.latency_ms:.2f} ms)")
        line = " ".join(parts)
        if rec.errors:
            text = "  !! " + "; ".join(rec.errors)
            line += f"{RED}{text}{RESET}" if self.colour else text
        if rec.warnings:
            text = "  ⚠ " + "; ".join(rec.warnings)
            line += f"{YELLOW}{text}{RESET}" if self.colour else text
        return line


class TextListener(Listener):
    """Formatted lines on a text stream; source events as lines that stand out. ``t0``: the time
    shown as 0 (a live session's start); default the first record's."""

    def __init__(
        self,
        out: IO[str],
        colour: bool | None = None,
        absolute_time: bool = False,
        t0: float | None = None,
    ) -> None:
        self.out = out
        colour = use_colour(out) if colour is None else colour
        self.formatter = TextFormatter(colour=colour, absolute_time=absolute_time, t0=t0)
        self.label = f"text output to {getattr(out, 'name', 'a stream')}"

    def on_records(self, records: Sequence[Record]) -> None:
        fmt = self.formatter.format
        self.out.write("".join([fmt(r) + "\n" for r in records]))

    def on_event(self, event: SourceEvent) -> None:
        line = format_event(event, self.formatter.colour)
        self.out.write(line + "\n")

    def tick(self, now: float) -> None:
        self.out.flush()

    def close(self) -> None:
        self.out.flush()


def format_event(event: SourceEvent, colour: bool) -> str:
    """A source event (port lost, reopened, drops ...) as a line that stands out."""
    line = f"-- {event.bus}: {event.message}"
    if event.count > 1:
        line += f" (x{event.count})"
    if not colour or event.level < 3:
        return line
    return f"{RED if event.level >= 4 else YELLOW}{line}{RESET}"
