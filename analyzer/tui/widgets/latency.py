"""Latency per command type: a small histogram and p50/p95/max. The figures are of the last
``LATENCY_KEEP`` answers of each command; the samples column says how many of how many."""

from __future__ import annotations

from typing import Any

from rich.table import Table
from textual.widgets import Static

from ..aggregates import LatencyStats

BLOCKS = " ▁▂▃▄▅▆▇█"


def sparkline(counts: list[int]) -> str:
    top = max(counts) or 1
    return "".join(BLOCKS[round(c / top * (len(BLOCKS) - 1))] for c in counts)


class LatencyPanel(Static):
    DEFAULT_CSS = "LatencyPanel { height: auto; }"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("no answered requests yet", **kwargs)
        self.empty = True

    def ended(self, what: str) -> None:
        """The session is over (``what``: the capture, the session)."""
        if self.empty:
            self.update(f"no answered requests in this {what}")

    def take(self, stats: dict[str, LatencyStats]) -> None:
        if not stats:
            return
        self.empty = False
        table = Table(expand=True, box=None)
        for name in ("command", "answers", "p50 ms", "p95 ms", "max ms", "0 .. max"):
            table.add_column(name, no_wrap=True, overflow="ellipsis")
        for name, s in sorted(stats.items()):
            table.add_row(
                name, s.samples_text(), f"{s.p50:.2f}", f"{s.p95:.2f}", f"{s.max:.2f}",
                sparkline(s.histogram),
            )  # fmt: skip
        self.update(table)
