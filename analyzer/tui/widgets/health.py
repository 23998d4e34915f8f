"""The health lines: one line per bus (CANalyzer's and PCAN-View's bus statistics, in one line):
the load of its latest whole second in percent of its bit rate or baud, and the highest of any
second the bus covered whole; its frames and errors in that second; a CAN controller's state
when it is not error-active; the worst event of the bus's last ``RECENT_S`` seconds in words
and how long ago it was (on the capture's clock, or the wall clock live). The figures are the
health package's (``HealthSecond``), never computed here. A bus whose frames have no times (a
raw dump) says so rather than show a load or a rate; a live bus that has gone quiet says for
how long."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final

from rich.style import Style
from rich.text import Text
from textual.widgets import Static

from decoders.can_errors import ERROR_ACTIVE

from ...health.bus import NO_TIMING
from ...health.seconds import severity

if TYPE_CHECKING:
    from ...health.seconds import HealthSecond

QUIET_S: Final = 2.0  # a live bus not heard for longer is said to be quiet
RECENT_S: Final = 60  # an event is shown until a worse one comes, or for this long
STYLE_BUS: Final = Style(bold=True)
STYLE_DIM: Final = Style(dim=True)
STYLE_BAD: Final = Style(color="red", bold=True)
STYLE_EVENT: Final = Style(color="yellow")
WAITING: Final = "bus health: no frames yet"
UNITS: Final = ("frames/s", "errors/s")
SHORT_UNITS: Final = ("fr/s", "err/s")  # under NARROW columns
NARROW: Final = 100


@dataclass
class BusHealthLine:
    """What one bus's line shows. ``peak``: the highest load of a second the bus covered whole
    (its first second, and its last one at the end, are partly outside its frames);
    ``event``: the second of the worst recent event, and the event in words (a later one as
    serious or worse, or any once it is ``RECENT_S`` old, takes its place); ``whole``: the bus's
    figures over the whole session, once it is over (``stats --format json``'s)."""

    bus: str
    untimed: bool = False
    last: HealthSecond | None = None
    first: int | None = None
    peak: float | None = None
    event: tuple[int, str] | None = None
    whole: dict[str, Any] | None = None

    def add(self, row: HealthSecond, whole: bool) -> None:
        if self.first is None:
            self.first = row.second
        load = row.load_pct
        if whole and row.second != self.first and load is not None:
            self.peak = load if self.peak is None else max(self.peak, load)
        self.last = row
        if row.worst is not None and self._replaces(row.second, row.worst):
            self.event = (row.second, row.worst)

    def _replaces(self, second: int, worst: str) -> bool:
        if self.event is None or second - self.event[0] >= RECENT_S:
            return True
        return severity(worst) <= severity(self.event[1])


def ago(seconds: float) -> str:
    if seconds >= 120:
        return f"{seconds / 60:.0f} min ago"
    return f"{max(0, int(seconds))} s ago"


def percent(value: float | None) -> str:
    return "-" if value is None else f"{value:.1f}%"


Part = tuple[str, Style | None]  # one group of a line, and its style


def health_text(line: BusHealthLine, now: float | None, live: bool, narrow: bool = False) -> Text:
    """One bus's line: its latest second, or once the session is over, all of it (``narrow``:
    the units in short, one space between the groups)."""
    units = SHORT_UNITS if narrow else UNITS
    untimed = line.untimed or (line.whole is not None and line.whole.get("timing") is not None)
    if untimed and line.last is None:
        parts = untimed_parts(line.whole)
    elif line.whole is not None:
        parts = [*whole_parts(line.whole, units), event_part(line, now)]
    elif line.last is not None:
        parts = [*second_parts(line, now, live, units), event_part(line, now)]
    else:
        parts = [("measuring: its first second is not over", STYLE_DIM)]
    text = Text(no_wrap=True, overflow="ellipsis")
    text.append(f"{line.bus:6}", STYLE_BUS)
    for words, style in parts:
        text.append(" " if narrow else "  ")
        text.append(words, style)
    return text


def event_part(line: BusHealthLine, now: float | None) -> Part:
    if line.event is None:
        return "no errors", STYLE_DIM
    second, words = line.event
    return words + ("" if now is None else f" {ago(now - second)}"), STYLE_EVENT


def second_parts(
    line: BusHealthLine, now: float | None, live: bool, units: tuple[str, str]
) -> list[Part]:
    """The bus's latest whole second: load (and the highest so far), frames, errors, state."""
    last = line.last
    assert last is not None
    pad = 0 if units is SHORT_UNITS else 5  # aligned across buses where there is room
    peak = "" if line.peak is None else f" max {percent(line.peak)}"
    parts: list[Part] = [
        (f"load {percent(last.load_pct):>{pad}}{peak}", None),
        (f"{last.frames:>{pad},} {units[0]}", None),
        (f"{last.errors} {units[1]}", STYLE_BAD if last.errors else None),
    ]
    if last.state not in (None, ERROR_ACTIVE):
        parts.append((last.state.replace("_", " "), STYLE_BAD))
    if live and now is not None and now - (last.second + 1) > QUIET_S:
        parts.append((f"quiet {now - (last.second + 1):.0f} s", STYLE_EVENT))
    return parts


def whole_parts(figures: dict[str, Any], units: tuple[str, str]) -> list[Part]:
    """The bus over the whole session: mean and highest load, frames and errors per second."""
    load = figures["load_pct"]
    errors = figures["error_frames"]["total"]
    span = figures["duration_s"]
    return [
        (f"load {percent(load['mean'])} mean {percent(load['max'])} max", None),
        (f"{rate_text(figures['frames_per_s'])} {units[0]}", None),
        (f"{rate_text(errors / span if span else None)} {units[1]}", STYLE_BAD if errors else None),
    ]


def rate_text(per_s: float | None) -> str:
    if per_s is None:
        return "-"
    return f"{per_s:,.0f}" if per_s >= 10 else f"{per_s:.1f}"


def untimed_parts(whole: dict[str, Any] | None) -> list[Part]:
    """A bus without times: what is known (its frames and errors, at the end), never a load."""
    parts: list[Part] = [(f"{NO_TIMING}: load and rates unknown", STYLE_DIM)]
    if whole is not None:
        errors = whole["error_frames"]["total"]
        parts.append((f"{whole['frames']:,} frames", None))
        parts.append((f"{errors:,} errors", STYLE_BAD if errors else None))
    return parts


class HealthLines(Static):
    """See the module doc. ``clock``: now, on the clock ages are measured on; ``live``: the
    buses are live (a silent one is quiet, not over)."""

    DEFAULT_CSS = """
    HealthLines { height: auto; text-wrap: nowrap; text-overflow: ellipsis; padding: 0 0 0 1; }
    """

    def __init__(self, clock: Callable[[], float | None], live: bool, **kwargs: Any) -> None:
        super().__init__(Text(WAITING, STYLE_DIM), **kwargs)
        self.clock = clock
        self.live = live
        self.lines: dict[str, BusHealthLine] = {}
        self._shown = 1  # lines shown

    def take(
        self, seconds: list[HealthSecond], untimed: set[str], whole: list[dict[str, Any]] | None
    ) -> None:
        """Seconds each bus completed; ``whole``: the session is over (the seconds still open
        came too), each bus's figures over all of it."""
        lines = self.lines
        for bus in untimed:
            lines.setdefault(bus, BusHealthLine(bus)).untimed = True
        # at the end, each bus's last second is cut by the end of its frames
        last = {} if whole is None else {row.bus: row.second for row in seconds}
        for row in seconds:
            line = lines.setdefault(row.bus, BusHealthLine(row.bus))
            line.add(row, whole=last.get(row.bus) != row.second)
        for figures in whole or []:
            lines.setdefault(figures["bus"], BusHealthLine(figures["bus"])).whole = figures
        self.redraw()

    def redraw(self) -> None:
        if not self.lines:
            return
        now, narrow = self.clock(), self.size.width < NARROW
        shown = [health_text(self.lines[b], now, self.live, narrow) for b in sorted(self.lines)]
        # the same number of lines: no layout of the screen needed (twice a second)
        self.update(Text("\n").join(shown), layout=len(shown) != self._shown)
        self._shown = len(shown)
