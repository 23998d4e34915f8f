"""One stored record as one line of the frame list: time, bus, direction, device, the manual's
name, the summary with units, latency; coloured by severity and flag codes, never by text.

```
   1234  12.345678 can0   → ID 1  CMD_OPENLEN_SET            write target_opening=0   0.41 ms
```
"""

from __future__ import annotations

import math
import time
from enum import Enum
from typing import Final

from rich.style import Style
from rich.text import Text

from decoders import flags as F

from .store import ERROR, WARNING, RecordStore

ARROWS: Final = ("·", "→", "←")  # by the store's direction column
NAME_WIDTH: Final = 28
BUS_WIDTH: Final = 6
TIME_WIDTH: Final = 15

STYLE_ERROR: Final = Style(color="red", bold=True)
STYLE_WARNING: Final = Style(color="yellow")
STYLE_DIM: Final = Style(dim=True)
STYLE_UNANSWERED: Final = Style(color="magenta")
STYLE_ORPHAN: Final = Style(color="magenta", italic=True)
STYLE_TIME: Final = Style(color="cyan")
STYLE_SEQ: Final = Style(dim=True)
STYLE_LATENCY: Final = Style(color="green")
STYLE_REF: Final = Style(color="black", bgcolor="cyan", bold=True)
STYLE_MATCH: Final = Style(color="black", bgcolor="yellow")


class TimeMode(Enum):
    """What the time column shows (Wireshark's "View > Time Display Format")."""

    RELATIVE = "relative"  # seconds since the first record
    ABSOLUTE = "absolute"  # the capture clock (wall time of day for live buses)
    DELTA = "delta"  # since the previous displayed record
    REFERENCE = "reference"  # since the time reference (``t`` on a frame)

    def next(self) -> TimeMode:
        members = list(TimeMode)
        return members[(members.index(self) + 1) % len(members)]


def format_time(
    store: RecordStore,
    i: int,
    mode: TimeMode,
    previous: int | None = None,
    reference: float | None = None,
) -> str:
    """The time column of record ``i`` (``TIME_WIDTH`` characters)."""
    t = store.t[i]
    if math.isnan(t):
        return "-".rjust(TIME_WIDTH)
    if mode is TimeMode.ABSOLUTE:
        if t > 1e8:  # an epoch time: the time of day is what a person reads
            clock = time.strftime("%H:%M:%S", time.localtime(t))
            return f"{clock}.{int(t % 1 * 1e6):06d}".rjust(TIME_WIDTH)
        return f"{t:{TIME_WIDTH}.6f}"
    if mode is TimeMode.DELTA:
        before = store.t[previous] if previous is not None else math.nan
        return f"{0.0 if math.isnan(before) else t - before:+{TIME_WIDTH}.6f}"
    if mode is TimeMode.REFERENCE and reference is not None:
        return f"{t - reference:+{TIME_WIDTH}.6f}"
    return f"{t - (store.t0 if store.t0 is not None else t):{TIME_WIDTH}.6f}"


def row_style(store: RecordStore, i: int) -> tuple[Style | None, str]:
    """The colour of a row and the one-character marker before it."""
    sev = store.severity[i]
    mask = store.flags[i]
    bits = store.flag_bits
    if sev == ERROR:
        return STYLE_ERROR, "!"
    if mask & bits.get(F.UNANSWERED):
        return STYLE_UNANSWERED, "?"
    if mask & bits.get(F.ORPHAN_RESPONSE):
        return STYLE_ORPHAN, "¿"
    if mask & bits.get(F.RETRANSMISSION):
        return STYLE_DIM, "↻"
    if sev == WARNING:
        return STYLE_WARNING, "⚠"
    if mask & bits.get(F.FOREIGN):
        return STYLE_DIM, " "
    return None, " "


def render_row(
    store: RecordStore,
    i: int,
    mode: TimeMode,
    previous: int | None = None,
    reference: float | None = None,
    is_reference: bool = False,
    mark: str = "",
) -> Text:
    """Record ``i`` as one line of text (styles applied; the caller adds the cursor)."""
    style, marker = row_style(store, i)
    device = store.device_of(i)
    who = f"ID {device}" if device is not None else "-"
    text = Text(no_wrap=True, overflow="ellipsis")
    text.append(f"{mark or marker:1}", style or STYLE_SEQ)
    text.append(f"{store.seq[i]:>7} ", STYLE_SEQ)
    time_text = (
        "*REF*".rjust(TIME_WIDTH)
        if is_reference
        else format_time(store, i, mode, previous, reference)
    )
    text.append(time_text, STYLE_REF if is_reference else STYLE_TIME)
    text.append(f" {store.bus_of(i)[:BUS_WIDTH]:{BUS_WIDTH}} {ARROWS[store.direction[i]]} ")
    text.append(f"{who:7} ")
    name = store.name_of(i)
    text.append(f"{name[:NAME_WIDTH]:{NAME_WIDTH}} ", style or Style(bold=True))
    text.append(store.summary[i], style)
    latency = store.latency_ms(i)
    if latency is not None and store.direction[i] == 2:
        about = "~" if store.flags[i] & store.flag_bits.get(F.ESTIMATED_TIME) else ""
        text.append(f"  {about}{latency:.2f} ms", STYLE_LATENCY)
    return text


def plain_row(store: RecordStore, i: int, mode: TimeMode = TimeMode.RELATIVE) -> str:
    """The row as plain text (search, tests)."""
    return render_row(store, i, mode).plain
