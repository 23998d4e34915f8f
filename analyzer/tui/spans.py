"""Which bytes of a frame carry which field: the hex pane's cross-highlighting.

A span names a field by its path in ``Record.fields`` (``("speed",)``, ``("values",
"CMD_OPENLEN_ACT")``) or a part of the frame's envelope (``("frame", "checksum")``), and gives
its bytes as ``[start, end)`` in ``Record.raw``. The layouts are the protocol reference's
(section 1: serial frames; section 2: Modbus RTU; section 3: CAN register spans); a payload
whose layout is not known gets one span for all of it.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

from decoders.eg2_serial import COMMANDS, RUN_STATE, Cmd, Field
from decoders.model import EG2_CAN, EG2_SERIAL, FRAME, MODBUS_RTU, REQUEST, Record

Path = tuple[str, ...]
FRAME_PART: Final = "frame"
RUN_STATE_LAYOUT: Final = tuple((v.key, struct.calcsize("<" + v.fmt)) for v in RUN_STATE)


@dataclass(frozen=True, slots=True)
class Span:
    path: Path
    start: int
    end: int

    @property
    def label(self) -> str:
        return ".".join(self.path[1:] if self.path[0] == FRAME_PART else self.path)

    def __contains__(self, offset: int) -> bool:
        return self.start <= offset < self.end


def _part(name: str, start: int, end: int) -> Span:
    return Span((FRAME_PART, name), start, end)


def _values(rec: Record, start: int, end: int, width: int = 2) -> list[Span]:
    """Register values packed from ``start``, ``width`` bytes each, named as decoded."""
    values = rec.fields.get("values")
    names = list(values) if isinstance(values, dict) else []
    out = []
    pos = start
    for name in names:
        if pos + width > end:
            break
        out.append(Span(("values", name), pos, pos + width))
        pos += width
    if not out and end > start:
        out.append(_part("data", start, end))
    return out


def serial_spans(rec: Record) -> list[Span]:
    n = len(rec.raw)
    if n < 6:
        return [_part("data", 0, n)] if n else []
    spans = [
        _part("header", 0, 2),
        Span(("id",), 2, 3),
        _part("length", 3, 4),
        _part("command", 4, 5),
        _part("checksum", n - 1, n),
    ]
    data_end = n - 1
    command = COMMANDS.get(rec.code) if rec.code is not None else None
    layout = None
    if command is not None:
        layout = command.request if rec.direction == REQUEST else command.response
    pos = 5
    if rec.code == Cmd.READ_EG_RUNSTATE and rec.direction != REQUEST:
        fields: list[tuple[str, int]] = list(RUN_STATE_LAYOUT)
    elif isinstance(layout, tuple) and layout:
        fields = [(f.key, struct.calcsize("<" + f.fmt)) for f in layout if isinstance(f, Field)]
    elif "status" in rec.fields:
        fields = [("status", 1)]
    else:
        fields = []
    for key, size in fields:
        if pos + size > data_end:
            break
        spans.append(Span((key,), pos, pos + size))
        pos += size
    if pos < data_end and not fields:
        spans.append(_part("data", pos, data_end))
    return spans


def modbus_spans(rec: Record) -> list[Span]:
    n = len(rec.raw)
    if n < 4:
        return [_part("data", 0, n)] if n else []
    spans = [Span(("slave",), 0, 1), Span(("function",), 1, 2), _part("crc", n - 2, n)]
    end = n - 2
    fc = rec.raw[1]
    if fc & 0x80:
        spans.append(_part("exception_code", 2, min(3, end)))
    elif (fc in (3, 4) and rec.direction == REQUEST) or (fc == 16 and rec.direction != REQUEST):
        spans += [Span(("start",), 2, 4), Span(("count",), 4, 6)]
    elif fc in (3, 4):
        spans.append(Span(("byte_count",), 2, 3))
        spans += _values(rec, 3, end)
    elif fc == 6:
        spans += [Span(("register",), 2, 4), Span(("value",), 4, 6)]
    elif fc == 16:
        spans += [Span(("start",), 2, 4), Span(("count",), 4, 6), Span(("byte_count",), 6, 7)]
        spans += _values(rec, 7, end)
    else:
        spans.append(_part("data", 2, end))
    return [s for s in spans if s.end <= n]


def can_spans(rec: Record) -> list[Span]:
    n = len(rec.raw)
    if not n:
        return []
    op = rec.fields.get("op")
    if op == "read" and rec.direction == REQUEST:
        return [Span(("length",), 0, 1)]
    if "written_bytes" in rec.fields:
        return [Span(("written_bytes",), 0, 1)]
    address = rec.fields.get("address")
    start = 1 if isinstance(address, int) and address & 1 else 0
    spans = [_part("odd_head", 0, 1)] if start else []
    return spans + _values(rec, start, n)


_BY_PROTOCOL: Final[dict[str, Callable[[Record], list[Span]]]] = {
    EG2_SERIAL: serial_spans,
    MODBUS_RTU: modbus_spans,
    EG2_CAN: can_spans,
}


def spans(rec: Record) -> list[Span]:
    """The spans of ``rec``'s bytes, narrowest first where they nest."""
    make = _BY_PROTOCOL.get(rec.protocol)
    if make is None or rec.kind != FRAME:
        return [_part(rec.kind, 0, len(rec.raw))] if rec.raw else []
    found = make(rec)
    return sorted(found, key=lambda s: (s.end - s.start, s.start))


def span_at(all_spans: list[Span], offset: int) -> Span | None:
    """The narrowest span holding byte ``offset``."""
    return next((s for s in all_spans if offset in s), None)


def span_of(all_spans: list[Span], path: Path) -> Span | None:
    return next((s for s in all_spans if s.path == path), None)
