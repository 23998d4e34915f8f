"""The cycles panel: every grip cycle as it ends, one line each, as a Line-API view like the
frame list (only the visible lines are drawn; a long capture's thousands of cycles cost
nothing to scroll). A line: when the cycle began (seconds from the capture's first record, as
the frame list's relative time; ``@seq`` without times), bus, gripper, the outcome coloured by
what it means, the opening at contact (mm), the force peak, the time to contact and the cycle
time (ms), the warnings and the command in words. Enter shows the cycle's frames.

Following, the newest cycle stays in view; moving the cursor stops that, End resumes."""

from __future__ import annotations

from typing import Any, ClassVar, Final

from rich.style import Style
from rich.text import Text
from textual import events
from textual.binding import Binding, BindingType
from textual.geometry import Size
from textual.strip import Strip

from ...cycles import model as M
from ...cycles.model import Cycle
from ..layout import CycleLayout, cycle_layout
from ..messages import CycleChosen
from ..rows import fit
from ..store import RecordStore
from .cursor_list import CURSOR_CLASS, CursorList

OUTCOME_STYLES: Final = {
    M.GRIPPED: Style(color="green", bold=True),
    M.CLOSED_EMPTY: Style(color="yellow", bold=True),
    M.OPENED: Style(color="cyan"),
    M.POSITIONED: Style(color="cyan"),
    M.STOPPED: Style(color="blue"),
    M.FAULTED: Style(color="red", bold=True),
    M.REFUSED: Style(color="red"),
    M.UNANSWERED: Style(color="magenta", bold=True),
    M.UNFINISHED: Style(dim=True),
    M.UNKNOWN: Style(dim=True),
}
STYLE_HEADER: Final = Style(bold=True, underline=True)
STYLE_WARNING: Final = Style(color="yellow")
STYLE_DIM: Final = Style(dim=True)
CHOSEN: Final = "▶"  # the gutter of the cycle whose frames the list shows
WAITING: Final = (
    "no grip cycles yet: a cycle is listed when it ends (at the next motion command to its "
    "gripper, a stop, or the end of the capture)"
)


def figure(value: float | None, width: int, digits: int = 1) -> str:
    return ("-" if value is None else f"{value:.{digits}f}").rjust(width)


def cycle_figures(c: Cycle, cols: CycleLayout) -> list[str]:
    """The cycle's measures in ``cols.figures``'s columns ("-": not measured)."""
    force = None if c.force_peak is None else float(c.force_peak)
    values = (c.width_mm, force, c.time_to_contact_ms, c.duration_ms)
    digits = (1, 0, 1, 1)
    columns = zip(cols.figures, values, digits, strict=True)
    return [figure(value, width, d) for (_, width), value, d in columns]


def when(c: Cycle, t0: float | None) -> str:
    """When a cycle began: seconds from ``t0``, or ``@seq`` when it has no time."""
    if c.start_t is None:
        return f"@{c.start_seq}"
    return f"{c.start_t - (t0 if t0 is not None else c.start_t):.3f}"


def render_header(cols: CycleLayout) -> Text:
    text = Text(no_wrap=True, overflow="ellipsis")
    text.append(" " + "start s".rjust(cols.time) + " ")
    text.append(fit("bus", cols.bus) + " " + fit("ID", cols.device) + " ")
    text.append(fit("outcome", 12) + " ")
    text.append(" ".join(name.rjust(w) for name, w in cols.figures) + "  ")
    if cols.warnings:
        text.append(fit("warnings", cols.warnings) + " ")
    text.append("command")
    text.stylize(STYLE_HEADER)
    text.truncate(cols.width, overflow="ellipsis", pad=True)
    return text


def render_cycle(c: Cycle, t0: float | None, cols: CycleLayout, chosen: bool = False) -> Text:
    """One cycle as one line in ``cols``'s widths."""
    text = Text(no_wrap=True, overflow="ellipsis")
    text.append(CHOSEN if chosen else " ", STYLE_WARNING)
    text.append(when(c, t0).rjust(cols.time) + " ", STYLE_DIM if c.start_t is None else None)
    text.append(fit(c.bus, cols.bus) + " " + fit(f"ID {c.device}", cols.device) + " ")
    text.append(fit(c.outcome, 12), OUTCOME_STYLES.get(c.outcome))
    text.append(" " + " ".join(cycle_figures(c, cols)) + "  ")
    warnings = ", ".join(c.warnings + c.faults)
    if cols.warnings:
        text.append(fit(warnings, cols.warnings) + " ", STYLE_WARNING)
    elif warnings:
        text.append(warnings + " ", STYLE_WARNING)
    text.append(c.command)
    text.truncate(cols.width, overflow="ellipsis")
    return text


class CyclesPanel(CursorList):
    """See the module doc. ``store``: where the capture's first time is read (relative
    times, as the frame list's)."""

    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("enter", "choose", "show the cycle's frames", show=False),
    ]
    DEFAULT_CSS = """
    CyclesPanel { height: 1fr; }
    """
    HEADER_ROWS = 1

    def __init__(self, store: RecordStore, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.store = store
        self.cycles: list[Cycle] = []
        self.cursor = -1
        self.follow = True
        self.chosen: Cycle | None = None
        self.empty_text = WAITING

    # -- what is shown --------------------------------------------------------------------

    def take(self, cycles: list[Cycle]) -> None:
        """Cycles that ended: listed after the others."""
        if not cycles:
            return
        self.cycles.extend(cycles)
        if self.region:  # shown: hidden (another tab), it catches up when shown (on_show)
            self._catch_up()

    def _catch_up(self) -> None:
        self._resize()
        if self.follow:
            self.move_to(len(self.cycles) - 1, follow=True)
        self.refresh()

    def on_show(self) -> None:
        self._catch_up()

    def ended(self, what: str) -> None:
        """The session is over (``what``: the capture, the session)."""
        if not self.cycles:
            self.empty_text = (
                f"no grip cycles in this {what} (no motion command: catch, release, seek or a "
                "target opening written)"
            )
            self.refresh()

    @property
    def row_count(self) -> int:
        return len(self.cycles)

    @property
    def selected(self) -> Cycle | None:
        return self.cycles[self.cursor] if 0 <= self.cursor < len(self.cycles) else None

    # -- the cursor -------------------------------------------------------------------------

    def move_to(self, position: int, follow: bool = False) -> None:
        n = len(self.cycles)
        self.cursor = min(max(position, 0), n - 1) if n else -1
        self.follow = follow
        rows = max(1, self.scrollable_content_region.height - 1)  # under the header
        y = self.scroll_offset.y
        if self.cursor >= 0 and not y <= self.cursor < y + rows:
            target = self.cursor - rows + 1 if self.cursor >= y + rows else self.cursor
            self.scroll_to(y=target, animate=False, immediate=True, force=True)
        self.refresh()

    def action_choose(self) -> None:
        cycle = self.selected
        if cycle is not None:
            self.chosen = cycle
            self.refresh()
            self.post_message(CycleChosen(cycle))

    def _resize(self) -> None:
        size = Size(self.scrollable_content_region.width, len(self.cycles) + 1)  # + the header
        self._grow_to(size)  # cycles end many times a second on a busy bus

    def on_resize(self, event: events.Resize) -> None:
        self._catch_up()

    # -- rendering ----------------------------------------------------------------------------

    def render_line(self, y: int) -> Strip:
        width = self.scrollable_content_region.width
        cols = cycle_layout(width)
        if y == 0:
            return self._strip(render_header(cols), width)
        if not self.cycles:
            text = Text(" " + self.empty_text, STYLE_DIM) if y == 1 else Text("")
            text.truncate(width, overflow="ellipsis")
            return self._strip(text, width)
        position = self.scroll_offset.y + y - 1
        if not 0 <= position < len(self.cycles):
            return Strip.blank(width, self.rich_style)
        cycle = self.cycles[position]
        text = render_cycle(cycle, self.store.t0, cols, cycle is self.chosen)
        if position != self.cursor:
            return self._strip(text, width)
        cursor = Style(bgcolor=self.get_component_rich_style(CURSOR_CLASS).bgcolor)
        text.stylize(cursor)
        return self._strip(text, width, self.rich_style + cursor)

    def _strip(self, text: Text, width: int, fill: Style | None = None) -> Strip:
        text.stylize_before(self.rich_style)
        line = text.render(self.app.console)
        strip = Strip(list(line), text.cell_len)
        return strip.extend_cell_length(width, fill or self.rich_style)
