"""PEAK's PCAN trace files (.trc), versions 1.0 to 2.1, line by line as CanFrames.

python-can's ``TRCReader`` reads 1.1, 1.3, 2.0 and 2.1, but gives up on a 1.2 trace (its
``$STARTTIME`` may end in ``;``) and on the ``ERROR`` lines of a 1.0 one, drops error frames,
and gives an FD frame its DLC code as its length. This module reads every version as PEAK
describes it: each version's columns are a table (``LAYOUTS``; 2.x traces name theirs in
``$COLUMNS``), a line is split into them and checked against its stated length.

- Message lines become CanFrames: data and remote (``RTR``, ``RR``) frames, CAN FD frames
  (``FD``, ``FB``, ``FE``, ``BI``), error frames (1.0 ``ERROR``, 1.x ``Error``, 2.x ``ER``:
  PEAK's error codes are kept as the data, the identifier is 0: no SocketCAN error class).
- Bus warnings (``Warng``, identifier ``FFFFFFFF``), status (``ST``), error counters (``EC``)
  and events (``EV``) are no frames: skipped as the format allows.
- ``t`` is ``$STARTTIME`` (days since 1899-12-30, taken as UTC as python-can does) plus the
  line's offset; a 1.0 trace has no start time: ``t`` is seconds since its start.
- The bus is the trace's bus number (``1`` where the version has no bus column).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta

from decoders.model import CanFrame

_EPOCH_1899 = datetime(1899, 12, 30, tzinfo=UTC)  # day 0 of $STARTTIME (an OLE date)
_HEX_DIGITS = frozenset("0123456789abcdefABCDEF")
# FD lengths by DLC code (ISO 11898-1)
_FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)

#: the columns of a message line per version: N number, O time offset (ms), B bus, T type,
#: I identifier, d direction, R reserved, L DLC, l length in bytes, D data (the rest)
LAYOUTS: dict[str, tuple[str, ...]] = {
    "1.0": ("N", "O", "I", "L", "D"),
    "1.1": ("N", "O", "T", "I", "L", "D"),
    "1.2": ("N", "O", "B", "T", "I", "L", "D"),
    "1.3": ("N", "O", "B", "T", "I", "R", "L", "D"),
}
DATA_TYPES = {"Rx", "Tx", "DT", "FD", "FB", "FE", "BI", "RR"}  # 1.x: Rx/Tx; 2.x: the rest
FD_TYPES = {"FD", "FB", "FE", "BI"}
ERROR_TYPES = {"Error", "ER"}
OTHER_TYPES = {"Warng", "ST", "EC", "EV"}  # bus warning, status, error counter, event
BUS_WARNING_ID = "FFFFFFFF"


@dataclass
class TraceHeader:
    """What the ``;$`` lines of a trace say."""

    version: str = "1.0"  # a trace without $FILEVERSION is a 1.0 one
    start: float = 0.0  # Unix time of offset 0 (0: unknown, t is relative)
    columns: tuple[str, ...] = field(default_factory=tuple)

    def read(self, line: str) -> None:
        """Take one ``;$KEY=value`` line (ValueError: a value that makes no sense)."""
        key, _, value = line[2:].partition("=")
        value = value.strip().rstrip(";").strip()  # 1.2 traces end $STARTTIME with ";"
        key = key.strip().upper()
        if key == "FILEVERSION":
            self.version = value
        elif key == "STARTTIME":
            try:
                days = float(value)
            except ValueError:
                raise ValueError(f"bad start time {value!r}") from None
            self.start = (_EPOCH_1899 + timedelta(days=days)).timestamp()
        elif key == "COLUMNS":
            self.columns = tuple(c.strip() for c in value.split(","))

    def layout(self) -> tuple[str, ...]:
        """The message columns (ValueError: a version this reader does not know)."""
        if self.version in LAYOUTS:
            return LAYOUTS[self.version]
        if self.version.startswith("2."):
            if not {"O", "T", "I", "D"} <= set(self.columns):
                raise ValueError(f"$COLUMNS lacks a column a message needs: {self.columns}")
            return self.columns
        raise ValueError(f"unknown trace version {self.version!r}")


def parse_message(line: str, header: TraceHeader, layout: tuple[str, ...]) -> CanFrame | None:
    """One message line: a CanFrame, or None for a line of another kind (bus warning, status,
    error counter, event); ValueError saying what is wrong."""
    tokens = line.split(maxsplit=len(layout) - 1)
    if len(tokens) < 3:
        raise ValueError("too few columns")
    kind = tokens[layout.index("T")] if "T" in layout else "Rx"
    if kind in OTHER_TYPES:
        return None
    if kind in ERROR_TYPES:
        return _error_frame(tokens, header, layout)
    if kind not in DATA_TYPES:
        raise ValueError(f"unknown message type {kind!r}")
    cols = dict(zip(layout, tokens, strict=False))
    ident = cols.get("I", "")
    if ident == BUS_WARNING_ID:
        return None
    data_tokens = cols.get("D", "").split()
    if layout == LAYOUTS["1.0"] and data_tokens[:1] == ["ERROR"]:
        return _error_frame(tokens, header, layout)
    aid, extended = _identifier(ident)
    fd = kind in FD_TYPES
    remote = kind == "RR" or data_tokens == ["RTR"]
    if "l" in cols:
        n = _number(cols["l"], "length", 64)
        dlc = n
    else:
        dlc = _number(cols.get("L", ""), "DLC", 15 if fd else 8)
        n = _FD_LENGTHS[dlc] if fd else dlc
    if remote:
        if data_tokens and data_tokens != ["RTR"]:
            raise ValueError("data in a remote frame")
        data = b""
    else:
        data = _data(data_tokens)
        if fd and len(data) == dlc:  # some writers put the length where the DLC belongs
            n = dlc
        if len(data) != n:
            raise ValueError(f"{'length' if 'l' in cols else 'DLC'} {dlc} but {len(data)} "
                             "data bytes")  # fmt: skip
        dlc = len(data) if fd else dlc
    return CanFrame(_time(cols, header), aid, data, extended, remote, False, fd, dlc,
                    _bus(cols))  # fmt: skip


def _error_frame(tokens: list[str], header: TraceHeader, layout: tuple[str, ...]) -> CanFrame:
    """An error frame: PEAK's error codes as the data, the identifier 0."""
    cols = dict(zip(layout, tokens, strict=False))
    if "d" in layout:
        # 2.x writers leave the identifier, reserved and length columns blank or "-": the codes
        # are the two-digit values after the direction (a one-digit value first is their count)
        after = " ".join(tokens[layout.index("T") + 1 :]).split()
        if "B" in layout and layout.index("B") == layout.index("T") + 1 and after:
            cols["B"] = after.pop(0)
        while after and after[0] in ("-", "Rx", "Tx"):
            after.pop(0)
        count = int(after.pop(0)) if after and len(after[0]) == 1 and after[0].isdigit() else None
        data = _data(after)
    else:
        values = cols.get("D", "").split()
        data = _data(values[1:] if values[:1] == ["ERROR"] else values)
        count = _number(cols.get("L", ""), "DLC", 8)
    if count is not None and count != len(data):
        raise ValueError(f"length {count} but {len(data)} error bytes")
    return CanFrame(_time(cols, header), 0, data, True, False, True, False, len(data),
                    _bus(cols))  # fmt: skip


def _identifier(ident: str) -> tuple[int, bool]:
    if not ident or len(ident) > 8 or not _HEX_DIGITS.issuperset(ident):
        raise ValueError(f"bad identifier {ident!r}")
    aid = int(ident, 16)
    extended = len(ident) > 4  # 4 digits for 11-bit identifiers, 8 for 29-bit ones
    if aid > (0x1FFFFFFF if extended else 0x7FF):
        raise ValueError(f"identifier {ident} out of range")
    return aid, extended


def _number(text: str, what: str, highest: int) -> int:
    if not text.isdigit() or int(text) > highest:
        raise ValueError(f"bad {what} {text!r}")
    return int(text)


def _data(tokens: list[str]) -> bytes:
    if not all(len(x) == 2 and _HEX_DIGITS.issuperset(x) for x in tokens):
        raise ValueError("data bytes are not two hex digits each")
    return bytes.fromhex("".join(tokens))


def _time(cols: dict[str, str], header: TraceHeader) -> float:
    try:
        offset = float(cols.get("O", ""))
    except ValueError:
        raise ValueError(f"bad time offset {cols.get('O', '')!r}") from None
    return offset / 1000 + header.start


def _bus(cols: dict[str, str]) -> str:
    bus = cols.get("B", "1")
    if not bus.isdigit():
        raise ValueError(f"bad bus {bus!r}")
    return str(int(bus))
