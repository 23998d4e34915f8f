"""The device panel: one row per gripper per bus (canopen-monitor's node table, cansniffer's
change highlighting): opening as a bar in 0-1000 and mm, force, current, temperature, state and
fault in words, the setpoints, the last command, counts, latency p50/p95 and the age since last
heard. Silent for ``STALE_S``: stale; for ``LOST_S``: lost. A value that just changed is
highlighted and fades over ``FADE_S``."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, Final

from rich.text import Text
from textual.geometry import Size
from textual.scroll_view import ScrollView
from textual.strip import Strip

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


# (heading, width): fixed widths, so a redraw is one pass of string formatting (a rich Table
# measures every cell of every row on each redraw, which starved the session's thread)
COLUMNS: Final = (
    ("bus", 6), ("ID", 5), ("opening", 23), ("force", 5), ("current", 7), ("°C", 4),
    ("state", 12), ("fault", 14), ("target", 15), ("speed", 5), ("f.limit", 7),
    ("last command", 16), ("frames", 8), ("err", 5), ("unans", 5), ("p50/p95 ms", 11),
    ("age", 10),
)  # fmt: skip
LINE_WIDTH: Final = sum(width + 1 for _, width in COLUMNS)


def table_line(cells: list[Any], bold: bool = False) -> Text:
    """Cells (text or ``Text``) side by side in ``COLUMNS``' widths, cut with an ellipsis."""
    line = Text(no_wrap=True, style="bold" if bold else "")
    for cell, (_, width) in zip(cells, COLUMNS, strict=True):
        part = cell if isinstance(cell, Text) else Text(str(cell))
        part.truncate(width, overflow="ellipsis", pad=True)
        line.append_text(part)
        line.append(" ")
    return line


class DevicePanel(ScrollView):
    """See the module doc. ``clock``: the time ages are measured against (the wall clock
    live, the newest record's time in a capture). ``redraw()`` takes the rows as they are;
    ``render_line`` draws a line the first time it is shown after that (the Line API: no
    layout pass, and no work for the rows scrolled out of the panel)."""

    DEFAULT_CSS = "DevicePanel { height: 1fr; }"

    def __init__(self, clock: Callable[[], float | None], **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.clock = clock
        self.rows: list[DeviceRow] = []
        self.latency: dict[DeviceKey, LatencyStats] = {}
        self.changed_at: dict[tuple[str, int, str], float] = {}
        self._shown: list[DeviceRow] = []  # the rows as of the last redraw
        self._at: tuple[float | None, float] = (None, 0.0)  # (clock, monotonic) of that redraw
        self._strips: dict[int, Strip] = {}

    def take(self, rows: list[DeviceRow], changed: set[tuple[str, int, str]]) -> None:
        now = time.monotonic()
        for key in changed:
            self.changed_at[key] = now
        self.rows = sorted(rows, key=lambda r: (r.bus, r.device))

    def redraw(self) -> None:
        if not self.rows:
            return
        self._shown = self.rows
        self._at = (self.clock(), time.monotonic())
        self._strips = {}
        self.virtual_size = Size(LINE_WIDTH, len(self._shown) + 1)
        self.refresh()

    @property
    def lines(self) -> list[Text]:
        """Every line as of the last redraw: the heading, then one per gripper."""
        if not self._shown:
            return [Text("no gripper heard yet")]
        return [self._line(position) for position in range(len(self._shown) + 1)]

    def _line(self, position: int) -> Text:
        if position == 0:
            return table_line([name for name, _ in COLUMNS], bold=True)
        clock, mono = self._at
        return table_line(self._cells(self._shown[position - 1], clock, mono))

    def notify_style_update(self) -> None:
        super().notify_style_update()
        self._strips = {}

    def render_line(self, y: int) -> Strip:
        scroll_x, scroll_y = self.scroll_offset
        width = self.size.width
        position = scroll_y + y
        if not 0 <= position < len(self._shown) + 1:  # the heading, or the "no gripper" line
            return Strip.blank(width, self.rich_style)
        strip = self._strips.get(position)
        if strip is None:
            line = self._line(position) if self._shown else self.lines[0]
            line.stylize_before(self.rich_style)
            strip = self._strips[position] = Strip(line.render(self.app.console), line.cell_len)
        return strip.crop_extend(scroll_x, scroll_x + width, self.rich_style)

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
