"""The device panel: one row per gripper per bus (canopen-monitor's node table, cansniffer's
change highlighting): opening as a bar in 0-1000 and mm, force, current, temperature, state and
fault in words, the setpoints, the last command, counts, latency p50/p95 and the age since last
heard. Silent for ``STALE_S``: stale; for ``LOST_S``: lost. A value that just changed is
highlighted and fades over ``FADE_S``."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, Final

from rich.table import Table
from rich.text import Text
from textual.widgets import Static

from ...model import derived
from ..aggregates import DeviceKey, LatencyStats
from ..messages import DeviceRow

STALE_S: Final = 2.0
LOST_S: Final = 10.0
FADE_S: Final = 2.0
BAR_WIDTH: Final = 10


def opening_bar(opening: int | None, mm: float | None) -> Text:
    if opening is None:
        return Text("-", style="dim")
    filled = round(max(0, min(1000, opening)) / 1000 * BAR_WIDTH)
    text = Text("█" * filled, style="green")
    text.append("░" * (BAR_WIDTH - filled), style="dim")
    text.append(f" {opening:4} {mm if mm is not None else 0:5.1f}mm")
    return text


def age_text(age: float | None) -> Text:
    if age is None:
        return Text("never", style="dim")
    if age >= LOST_S:
        return Text(f"LOST {age:.0f}s", style="bold red")
    if age >= STALE_S:
        return Text(f"stale {age:.1f}s", style="yellow")
    return Text(f"{age:.1f}s", style="green")


def changed_style(since: float | None) -> str:
    """Fresh changes stand out, then fade."""
    if since is None or since >= FADE_S:
        return ""
    if since < FADE_S / 3:
        return "bold black on bright_green"
    if since < 2 * FADE_S / 3:
        return "bold bright_green"
    return "green"


class DevicePanel(Static):
    """See the module doc. ``clock``: the time ages are measured against (the wall clock
    live, the newest record's time in a capture)."""

    DEFAULT_CSS = "DevicePanel { height: auto; }"

    def __init__(self, clock: Callable[[], float | None], **kwargs: Any) -> None:
        super().__init__("no gripper heard yet", **kwargs)
        self.clock = clock
        self.rows: list[DeviceRow] = []
        self.latency: dict[DeviceKey, LatencyStats] = {}
        self.changed_at: dict[tuple[str, int, str], float] = {}

    def take(self, rows: list[DeviceRow], changed: set[tuple[str, int, str]]) -> None:
        now = time.monotonic()
        for key in changed:
            self.changed_at[key] = now
        self.rows = sorted(rows, key=lambda r: (r.bus, r.device))

    def redraw(self) -> None:
        if not self.rows:
            return
        self.update(self.table())

    def table(self) -> Table:
        table = Table(expand=True, box=None, padding=(0, 1), header_style="bold")
        for name in (
            "bus", "ID", "opening", "force", "current", "°C", "state", "fault", "target",
            "speed", "f.limit", "last command", "frames", "err", "unans", "p50/p95 ms", "age",
        ):  # fmt: skip
            table.add_column(name, no_wrap=True, overflow="ellipsis")
        clock = self.clock()
        mono = time.monotonic()
        for row in self.rows:
            table.add_row(*self._cells(row, clock, mono))
        return table

    def _cells(self, row: DeviceRow, clock: float | None, mono: float) -> list[Any]:
        v = derived(dict(row.values))

        def cell(key: str, text: Any = None) -> Text:
            shown = v.get(key) if text is None else text
            at = self.changed_at.get((row.bus, row.device, key))
            return Text(
                "-" if shown is None else str(shown),
                style=changed_style(None if at is None else mono - at),
            )

        bar = opening_bar(v.get("opening"), v.get("opening_mm"))
        at = self.changed_at.get((row.bus, row.device, "opening"))
        if at is not None and changed_style(mono - at):
            bar.stylize(changed_style(mono - at), BAR_WIDTH)
        fault = v.get("fault_text") or []
        lat = self.latency.get((row.bus, row.device))
        age = None if clock is None or row.t is None else max(0.0, clock - row.t)
        target = v.get("target_opening")
        return [
            row.bus,
            str(row.device),
            bar,
            cell("force"),
            cell("current"),
            cell("temperature_c"),
            cell("state", v.get("state_text")),
            Text(", ".join(fault) or "none", style="bold red" if fault else "dim"),
            cell("target_opening", None if target is None else f"{target} {v.get('target_mm')}mm"),
            cell("speed"),
            cell("force_setting"),
            cell("last_command"),
            str(v.get("frames", 0)),
            Text(str(v.get("errors", 0)), style="red" if v.get("errors") else ""),
            Text(str(v.get("unanswered", 0)), style="magenta" if v.get("unanswered") else ""),
            "-" if lat is None else f"{lat.p50:.2f}/{lat.p95:.2f}",
            age_text(age),
        ]
