"""The device panel: one row per gripper per bus (canopen-monitor's node table, cansniffer's
change highlighting): opening as a bar in 0-1000 and mm, force, current, temperature, state and
fault in words, the setpoints, the last command, counts, latency p50/p95 and the age since last
heard. Silent for ``STALE_S``: stale; for ``LOST_S``: lost. A value that just changed is
highlighted and fades over ``FADE_S``.

On a narrow panel the columns a person watches stay (bus, ID, state, faults, latency, age,
then opening, force, temperature ...) and the others are left out (``columns_for``); a state or
fault too long for its column is abbreviated (``SHORT_STATES``, ``SHORT_FAULTS``), never cut. A
gripper whose state or faults were never read (one never heard, a broadcast ID) shows ``-``,
not "none", and its age is "never": requests sent to it are not hearing from it. One heard in
a capture without times shows "heard"."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, Final

from rich.text import Text
from textual.geometry import Size
from textual.scroll_view import ScrollView
from textual.strip import Strip

from decoders.registers import FAULT_BITS

from ...model import derived
from ...session.tracker import READINGS
from ..aggregates import DeviceKey, LatencyStats
from ..messages import DeviceRow

STALE_S: Final = 2.0
LOST_S: Final = 10.0
FADE_S: Final = 2.0
BAR_WIDTH: Final = 10


# the manual's state words (decoders.registers.STATE_TEXT) in at most STATE_WIDTH characters
SHORT_STATES: Final = {
    1: "open, idle",
    2: "closed, idle",
    3: "stopped, idle",
    4: "closing",
    5: "opening",
    6: "force-stopped",
}
SHORT_FAULTS: Final = dict(
    zip(FAULT_BITS, ("stall", "over-temp", "over-curr", "driver", "comms"), strict=True)
)


def opening_bar(opening: int | None, mm: float | None, bar: bool = True) -> Text:
    if opening is None:
        return Text("-", style="dim")
    text = Text()
    if bar:
        filled = round(max(0, min(1000, opening)) / 1000 * BAR_WIDTH)
        text.append("█" * filled, style="green")
        text.append("░" * (BAR_WIDTH - filled) + " ", style="dim")
    text.append(f"{opening:4} {mm if mm is not None else 0:4.1f}mm")
    return text


def state_words(state: int | None, text: str | None, width: int) -> str:
    """The state in words, abbreviated when the manual's words do not fit ``width``."""
    if state is None or text is None:
        return "-"
    return text if len(text) <= width else SHORT_STATES.get(state, text)


def fault_words(fault: int | None, texts: list[str], width: int) -> str:
    """The faults in words (abbreviated to fit ``width``); "none" only for a fault register
    read as 0, "-" when it was never read."""
    if fault is None:
        return "-"
    if not texts:
        return "none"
    full = ", ".join(texts)
    return full if len(full) <= width else ",".join(SHORT_FAULTS.get(t, t) for t in texts)


def age_text(age: float | None, heard: bool = True) -> Text:
    """``age``: seconds since it was last heard; None with ``heard``: heard, but the capture
    has no times."""
    if not heard:
        return Text("never", style="dim")
    if age is None:
        return Text("heard", style="dim")
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


STATE_WIDTH: Final = 14
FAULT_WIDTH: Final = 14
BAR_OPENING: Final = 23  # the opening with its bar; without: 1000  70.0mm
# (heading, width, priority): fixed widths, so a redraw is one pass of string formatting (a
# rich Table measures every cell of every row on each redraw, which starved the session's
# thread); a narrow panel keeps the columns of the lowest priority numbers
COLUMNS: Final = (
    ("bus", 6, 0), ("ID", 5, 0), ("opening", 11, 6), ("force", 5, 7), ("current", 7, 9),
    ("°C", 4, 8), ("state", STATE_WIDTH, 1), ("fault", FAULT_WIDTH, 2), ("target", 15, 11),
    ("speed", 5, 12), ("f.limit", 7, 13), ("last command", 16, 10), ("frames", 8, 14),
    ("err", 5, 15), ("unans", 5, 16), ("p50/p95 ms", 11, 3), ("age", 10, 4),
)  # fmt: skip
ALL_WIDTH: Final = sum(w + 1 for _, w, _ in COLUMNS) + BAR_OPENING - 11


def columns_for(width: int) -> tuple[list[int], bool]:
    """The columns (indexes into ``COLUMNS``, in their order) that fit ``width`` cells, and
    whether the opening has room for its bar."""
    if width <= 0 or width >= ALL_WIDTH:
        return list(range(len(COLUMNS))), True
    kept: list[int] = []
    used = 0
    for k in sorted(range(len(COLUMNS)), key=lambda k: COLUMNS[k][2]):
        need = COLUMNS[k][1] + 1
        if used + need <= width or COLUMNS[k][2] == 0:
            kept.append(k)
            used += need
    return sorted(kept), False


def table_line(cells: list[Any], kept: list[int], bar: bool, bold: bool = False) -> Text:
    """The ``kept`` cells (text or ``Text``) side by side in their columns' widths."""
    line = Text(no_wrap=True, style="bold" if bold else "")
    for k in kept:
        name, width, _ = COLUMNS[k]
        width = BAR_OPENING if bar and name == "opening" else width
        cell = cells[k]
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
        self._width = -1  # the width the columns were chosen for
        self._kept, self._bar = columns_for(0)
        self.empty_text = "no gripper heard yet"

    def ended(self, what: str) -> None:
        """The session is over (``what``: the capture, the session)."""
        self.empty_text = f"no gripper heard in this {what}"
        self._strips = {}
        self.refresh()

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
        self._fit_width(force=True)
        self.refresh()

    def _fit_width(self, force: bool = False) -> None:
        width = self.scrollable_content_region.width
        if width == self._width and not force:
            return
        self._width = width
        self._kept, self._bar = columns_for(width)
        self._strips = {}
        line = sum(COLUMNS[k][1] + 1 for k in self._kept)
        line += BAR_OPENING - COLUMNS[2][1] if self._bar else 0
        self.virtual_size = Size(line, len(self._shown) + 1)

    @property
    def lines(self) -> list[Text]:
        """Every line as of the last redraw: the heading, then one per gripper."""
        if not self._shown:
            return [Text(self.empty_text)]
        return [self._line(position) for position in range(len(self._shown) + 1)]

    def _line(self, position: int) -> Text:
        if position == 0:
            return table_line([name for name, _, _ in COLUMNS], self._kept, self._bar, bold=True)
        clock, mono = self._at
        cells = self._cells(self._shown[position - 1], clock, mono)
        return table_line(cells, self._kept, self._bar)

    def notify_style_update(self) -> None:
        super().notify_style_update()
        self._strips = {}

    def render_line(self, y: int) -> Strip:
        self._fit_width()
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

        bar = opening_bar(v.get("opening"), v.get("opening_mm"), self._bar)
        at = self.changed_at.get((row.bus, row.device, "opening"))
        if at is not None and changed_style(mono - at):
            bar.stylize(changed_style(mono - at), BAR_WIDTH + 1 if self._bar else 0)
        faults = v.get("fault_text") or []
        lat = self.latency.get((row.bus, row.device))
        # heard: it answered (a latency) or something of it was read; requests sent to it
        # (one that never answers, a broadcast ID) are not hearing from it
        heard = v.get("latency_ms") is not None or any(v.get(k) is not None for k in READINGS)
        age = None if clock is None or row.t is None else max(0.0, clock - row.t)
        target = v.get("target_opening")
        return [
            row.bus,
            str(row.device),
            bar,
            cell("force"),
            cell("current"),
            cell("temperature_c"),
            cell("state", state_words(v.get("state"), v.get("state_text"), STATE_WIDTH)),
            Text(
                fault_words(v.get("fault"), faults, FAULT_WIDTH),
                style="bold red" if faults else "dim",
            ),
            cell("target_opening", None if target is None else f"{target} {v.get('target_mm')}mm"),
            cell("speed"),
            cell("force_setting"),
            cell("last_command"),
            str(v.get("frames", 0)),
            Text(str(v.get("errors", 0)), style="red" if v.get("errors") else ""),
            Text(str(v.get("unanswered", 0)), style="magenta" if v.get("unanswered") else ""),
            "-" if lat is None else f"{lat.p50:.2f}/{lat.p95:.2f}",
            age_text(age, heard),
        ]
