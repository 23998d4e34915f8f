"""How the screen is shared at each terminal size: the breakpoints the stylesheet uses and the
frame list's column widths.

- Narrow (under ``MEDIUM`` columns): the detail pane is hidden (``d`` swaps the list and the
  detail); the list keeps time, bus, direction, ID, name and the decoded values.
- Medium (``MEDIUM`` to ``WIDE``): the detail pane is shrunk to a fixed width.
- Wide: the list and the detail share the width 3:2.
- Short terminals (under ``TALL`` lines) give the panels fewer lines.

Anything cut to fit ends in an ellipsis, never mid-word without a mark.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

MEDIUM: Final = 100
WIDE: Final = 160
TALL: Final = 30
WIDTH_BREAKPOINTS: Final = ((0, "-narrow"), (MEDIUM, "-medium"), (WIDE, "-wide"))
HEIGHT_BREAKPOINTS: Final = ((0, "-short"), (TALL, "-tall"))


@dataclass(frozen=True)
class RowLayout:
    """Column widths of one frame-list row (0: the column is left out). The summary (decoded
    values) and the latency take what is left of ``width``."""

    width: int
    seq: int
    time: int
    bus: int
    device: int
    name: int


def row_layout(width: int) -> RowLayout:
    """The columns for a list ``width`` cells wide: the record number and wide names only
    where there is room; time, bus, direction, ID, name and values always."""
    if width >= 150:
        return RowLayout(width, seq=7, time=15, bus=8, device=8, name=32)
    if width >= 110:  # the longest register ranges (CMD_OPENLEN_SET..CMD_FORCE_SET) fit
        return RowLayout(width, seq=7, time=12, bus=6, device=8, name=31)
    return RowLayout(width, seq=0, time=12, bus=6, device=8, name=18)


@dataclass(frozen=True)
class CycleLayout:
    """Column widths of one row of the cycles panel. The command in words takes what is left
    of ``width``; ``warnings`` 0: a cycle's warnings go before its command instead;
    ``figures``: the measures' headers and widths (opening at contact, force peak, time to
    contact, cycle time)."""

    width: int
    time: int
    bus: int
    device: int
    warnings: int
    figures: tuple[tuple[str, int], ...]


def cycle_layout(width: int) -> CycleLayout:
    """The cycles panel's columns for ``width`` cells: the outcome and the figures always,
    a warnings column of its own where there is room."""
    if width >= 110:
        figures = (("width mm", 8), ("force", 5), ("contact ms", 10), ("cycle ms", 9))
        return CycleLayout(width, time=11, bus=7, device=7, warnings=14, figures=figures)
    figures = (("mm", 5), ("force", 5), ("touch ms", 8), ("cycle ms", 8))
    return CycleLayout(width, time=8, bus=6, device=5, warnings=0, figures=figures)
