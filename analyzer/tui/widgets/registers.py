"""The register watch: for the selected gripper, every register seen with its last value, the
value before it, how many reads/writes and how often."""

from __future__ import annotations

from typing import Any

from rich.table import Table
from rich.text import Text
from textual.widgets import Static

from ..aggregates import DeviceKey, RegisterSeen


class RegisterWatch(Static):
    DEFAULT_CSS = "RegisterWatch { height: auto; }"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("select a frame of a gripper", **kwargs)
        self.device: DeviceKey | None = None
        self.tables: dict[DeviceKey, dict[str, RegisterSeen]] = {}

    def take(self, tables: dict[DeviceKey, dict[str, RegisterSeen]]) -> None:
        self.tables = tables
        self.redraw()

    def follow(self, device: DeviceKey | None) -> None:
        if device is not None and device != self.device:
            self.device = device
            self.redraw()

    def redraw(self) -> None:
        if self.device is None:
            return
        seen = self.tables.get(self.device, {})
        bus, dev = self.device
        table = Table(title=f"registers of ID {dev} on {bus}", expand=True, box=None)
        for name in ("register", "value", "was", "changes", "seen", "rate"):
            table.add_column(name, no_wrap=True)
        for name, reg in sorted(seen.items()):
            rate = reg.rate_hz
            table.add_row(
                name,
                Text(str(reg.value), style="bold"),
                "-" if reg.previous is None else str(reg.previous),
                str(reg.changes),
                str(reg.count),
                "-" if rate is None else f"{rate:.1f}/s",
            )
        self.update(table)
