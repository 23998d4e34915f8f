"""The problems panel (Wireshark's expert info): errors and warnings grouped by flag code and
device, with counts; Enter jumps to the group's first occurrence."""

from __future__ import annotations

from typing import Any

from rich.text import Text
from textual.widgets import DataTable

from decoders.flags import DESCRIPTIONS

from ..aggregates import ProblemGroup
from ..messages import JumpTo


class ProblemsPanel(DataTable[Any]):
    DEFAULT_CSS = "ProblemsPanel { height: 1fr; }"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(cursor_type="row", zebra_stripes=True, **kwargs)
        self.groups: list[ProblemGroup] = []
        self._shown: list[tuple[Any, ...]] = []

    def on_mount(self) -> None:
        self.add_columns("level", "flag", "what", "bus", "ID", "count", "first")

    def take(self, groups: list[ProblemGroup]) -> None:
        groups = sorted(groups, key=lambda g: (g.level != "error", -g.count, g.code, g.bus))
        shown = [(g.code, g.bus, g.device, g.count) for g in groups]
        if shown == self._shown:
            return
        self._shown = shown
        self.groups = groups
        row = self.cursor_row
        self.clear()
        for g in groups:
            style = "bold red" if g.level == "error" else "yellow"
            self.add_row(
                Text(g.level, style=style),
                Text(g.code, style=style),
                DESCRIPTIONS.get(g.code, ""),
                g.bus,
                "-" if g.device is None else str(g.device),
                f"{g.count:,}",
                f"#{g.first}",
            )
        if groups:
            self.move_cursor(row=min(row, len(groups) - 1))

    def on_data_table_row_selected(self, event: DataTable.RowSelected) -> None:
        event.stop()
        if 0 <= event.cursor_row < len(self.groups):
            self.post_message(JumpTo(self.groups[event.cursor_row].first))
