"""One stored record as one line of the frame list: time, bus, direction, device, the manual's
name, the summary with units, latency; coloured by severity and flag codes, never by text.
Column widths follow the list's width (``layout.row_layout``); whatever is cut ends in ``…``.

```
   1234    12.345678 can0   → ID 1     CMD_OPENLEN_SET          write target_opening=0  0.41 ms
```

The gutter before the number marks problems (``MARKERS``), or the letter of a mark. Where the
number column is left out (a narrow list), a record without a time shows its number (``#seq``:
a raw dump's byte offset) in the time column instead of a bare ``-``.
"""

from __future__ import annotations

import math
import time
from enum import Enum
from typing import Final

from rich.style import Style
from rich.text import Text

from decoders import flags as F

from .layout import RowLayout, row_layout
from .store import ERROR, WARNING, RecordStore

ARROWS: Final = ("·", "→", "←")  # by the store's direction column
ELLIPSIS: Final = "…"

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
STYLE_EVIDENCE: Final = Style(color="yellow", bold=True)

# the gutter's markers, most serious first (the help screen lists them from here)
MARKER_ERROR: Final = "!"
MARKER_UNANSWERED: Final = "?"
MARKER_ORPHAN: Final = "¿"
MARKER_RETRANSMISSION: Final = "↻"
MARKER_WARNING: Final = "⚠"
MARKER_EVIDENCE: Final = "◆"
MARKERS: Final = (
    (MARKER_ERROR, "an error: bad checksum or CRC, garbage, a truncated or malformed frame"),
    (MARKER_UNANSWERED, "a request that got no response"),
    (MARKER_ORPHAN, "a response with no request before it"),
    (MARKER_RETRANSMISSION, "the same request sent again before the first was answered"),
    (MARKER_WARNING, "a warning: a value out of range, a timing rule broken, ..."),
    ("a-z", "a mark set with m (jump to it with ')"),
    (MARKER_EVIDENCE, "a frame that decided the grip cycle chosen in the cycles panel (] [ step)"),
)


SHORTEST_STUB: Final = 6  # a word cut shorter than this ("CMD_…") says nothing: cut before it


def cut_at(text: str, width: int) -> int:
    """Where to cut ``text`` so that it and an ellipsis fit ``width`` cells: at ``width - 1``,
    or before the item there when only a stub of it would show (``CMD_…``) and the items are
    a list (``a, b, c``) whose earlier item ends in the second half of the room: the list
    then loses whole items and says so (``a, b, …``). A range ``A..B`` keeps its stub, which
    shows it is one."""
    cut = max(0, width - 1)
    start = cut
    while start > 0 and _in_word(text[start - 1]):
        start -= 1
    stub = cut - start
    listed = start > 0 and text[start - 1] in " ,"
    if listed and 0 < stub < SHORTEST_STUB and _in_word(text[cut]) and start >= cut // 2:
        return start
    return cut


def _in_word(char: str) -> bool:
    return char.isalnum() or char == "_"


def fit(text: str, width: int) -> str:
    """``text`` in exactly ``width`` cells: padded, or cut with an ellipsis."""
    if len(text) <= width:
        return text.ljust(width)
    return text[: max(0, width - 1)] + ELLIPSIS if width > 0 else ""


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
    width: int = 15,
) -> str:
    """The time column of record ``i`` (at least ``width`` characters)."""
    t = store.t[i]
    if math.isnan(t):
        return "-".rjust(width)
    if mode is TimeMode.ABSOLUTE:
        if t > 1e8:  # an epoch time: the time of day is what a person reads
            clock = time.strftime("%H:%M:%S", time.localtime(t))
            return f"{clock}.{int(t % 1 * 1e6):06d}".rjust(width)
        return f"{t:{width}.6f}"
    if mode is TimeMode.DELTA:
        before = store.t[previous] if previous is not None else math.nan
        return f"{0.0 if math.isnan(before) else t - before:+{width}.6f}"
    if mode is TimeMode.REFERENCE and reference is not None:
        return f"{t - reference:+{width}.6f}"
    return f"{t - (store.t0 if store.t0 is not None else t):{width}.6f}"


def row_style(store: RecordStore, i: int) -> tuple[Style | None, str]:
    """The colour of a row and the one-character marker before it."""
    sev = store.severity[i]
    mask = store.flags[i]
    bits = store.flag_bits
    if sev == ERROR:
        return STYLE_ERROR, MARKER_ERROR
    if mask & bits.get(F.UNANSWERED):
        return STYLE_UNANSWERED, MARKER_UNANSWERED
    if mask & bits.get(F.ORPHAN_RESPONSE):
        return STYLE_ORPHAN, MARKER_ORPHAN
    if mask & bits.get(F.RETRANSMISSION):
        return STYLE_DIM, MARKER_RETRANSMISSION
    if sev == WARNING:
        return STYLE_WARNING, MARKER_WARNING
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
    layout: RowLayout | None = None,
) -> Text:
    """Record ``i`` as one line of text in ``layout``'s widths (styles applied; the caller
    adds the cursor)."""
    cols = layout or row_layout(200)
    style, marker = row_style(store, i)
    device = store.device_of(i)
    text = Text(no_wrap=True, overflow="ellipsis")
    gutter = STYLE_EVIDENCE if mark == MARKER_EVIDENCE else style or STYLE_SEQ
    text.append(f"{mark or marker:1}", gutter)
    if cols.seq:
        text.append(f"{store.seq[i]:>{cols.seq}} ", STYLE_SEQ)
    untimed = math.isnan(store.t[i])
    if is_reference:
        time_text = "*REF*".rjust(cols.time)
    elif untimed and not cols.seq:  # no time and no number column: the number, for go-to
        time_text = f"#{store.seq[i]}".rjust(cols.time)
    else:
        time_text = format_time(store, i, mode, previous, reference, cols.time)
    text.append(time_text, STYLE_REF if is_reference else STYLE_SEQ if untimed else STYLE_TIME)
    text.append(f" {fit(store.bus_of(i), cols.bus)} {ARROWS[store.direction[i]]} ")
    text.append(fit("-" if device is None else f"ID {device}", cols.device) + " ")
    text.append(fit(store.name_of(i), cols.name) + " ", style or Style(bold=True))
    text.append(store.summary[i], style)
    latency = store.latency_ms(i)
    if latency is not None and store.direction[i] == 2:
        about = "~" if store.flags[i] & store.flag_bits.get(F.ESTIMATED_TIME) else ""
        text.append(f"  {about}{latency:.2f} ms", STYLE_LATENCY)
    text.truncate(cols.width, overflow="ellipsis")
    return text


def plain_row(
    store: RecordStore, i: int, mode: TimeMode = TimeMode.RELATIVE, width: int = 200
) -> str:
    """The row as plain text, ``width`` cells at most (search, tests)."""
    return render_row(store, i, mode, layout=row_layout(width)).plain
