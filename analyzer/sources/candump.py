"""The lines candump writes, as CanFrames: every layout, with or without time stamps.

- ``-l`` / ``-L`` (log files): ``(1600000000.123456) can0 04FF0001#0000F401F401``, also remote
  frames ``123#R`` / ``123#R5``, CAN FD ``123##<flags><data>``, the classic DLC 9-15 suffix
  ``123#1122334455667788_F`` and the direction flag python-can appends (`` R`` / `` T``);
- the default columns (``candump can0 > file``): ``can0  0C8   [8]  F0 00 00 00 00 00 00 00``,
  CAN FD lengths ``[NN]`` (two digits, up to 64), ``remote request``, the ``-a`` ASCII view and
  the ``ERRORFRAME`` mark after the data, the ``-e`` explanation lines (a TAB, after an error
  frame) that follow it;
- time stamps before either: ``(1594172462.126542)`` (``-ta``: Unix time), ``(000.000000)``
  (``-tz``: seconds since the start; ``-td``: seconds since the previous frame, summed here),
  ``(2020-12-19 12:04:45.485261)`` (``-tA``: local date and time, read in this machine's time
  zone); none at all (``t`` is None);
- ``ERROR`` lines (``can0  ERROR``): an error frame without an identifier.

A log's relative stamps are ``-td`` deltas when one of them in the first 64 KiB is smaller than
the one before it (``-tz`` stamps never go back); ``-L`` stamps are always Unix time.

native/src/sources/candump.rs mirrors this module line by line: the same frames and the same error
texts from both engines.
"""

from __future__ import annotations

import binascii
import io
import itertools
import time
import zlib
from collections.abc import Iterator
from typing import IO, Final

from decoders.model import CanFrame

HEAD_SIZE = 1 << 16  # bytes looked at for a byte order mark, the line ends and -td stamps
READ_BUFFER = 1 << 20
BOM = b"\xef\xbb\xbf"

CAN_ERR_FLAG = 0x20000000  # SocketCAN: error frame; the identifier carries the error class
CAN_RTR_FLAG = 0x40000000  # SocketCAN: remote frame; never printed by candump (it writes "#R")
CAN_EFF_MASK = 0x1FFFFFFF
CANFD_MAX_LEN = 64
RELATIVE_LIMIT = 662688000.0  # 1991-01-01: a smaller stamp is relative (-tz, -td), not Unix time

MAX_QUOTED = 80  # characters of a bad line quoted in its error
MAX_REASON = 100  # characters of why it is bad (a float() error repeats the whole field)

_HEX_DIGITS = frozenset(b"0123456789abcdefABCDEF")
_DIRECTIONS = frozenset({b"R", b"T", b"r", b"t"})  # python-can appends the direction
_LOG = "log"  # an -l/-L line: "(stamp) channel ID#DATA"
_COLUMNS = "columns"  # the default layout, and ERROR lines


# -- lines ---------------------------------------------------------------------------------------


class ByteLines:
    """The lines of a binary text file, each ending in b"\\n" but a cut last one: without its
    UTF-8 byte order mark, and split at lone CRs when the file ends its lines that way. A read
    error (a cut .gz) is raised after the lines read before it. ``head`` is the first 64 KiB
    (without the mark), read at once."""

    def __init__(self, f: IO[bytes]) -> None:
        self._f = f
        head = b""
        self._error: BaseException | None = None
        read1 = getattr(f, "read1", f.read)  # read1: a cut .gz keeps what it gave before the cut
        try:
            while len(head) < HEAD_SIZE and (block := read1(HEAD_SIZE - len(head))):
                head += block
        except (OSError, EOFError, zlib.error) as exc:
            self._error = exc
        if head.startswith(BOM):
            head = head[len(BOM) :]
        self.head = head
        self.cr = b"\n" not in head and b"\r" in head

    def __iter__(self) -> Iterator[bytes]:
        head, f, error = self.head, self._f, self._error
        if self.cr:
            lines: Iterator[bytes] = _cr_lines(head, f if error is None else io.BytesIO())
        elif error is not None:  # the line the damage cut is part of it: said once, with it
            lines = io.BytesIO(head[: head.rfind(b"\n") + 1])
        elif not head:
            lines = io.BytesIO(head)
        else:
            if not head.endswith(b"\n"):
                head += f.readline()
            lines = itertools.chain(io.BytesIO(head), f)
        yield from lines
        if error is not None:
            raise error


def _cr_lines(head: bytes, f: IO[bytes]) -> Iterator[bytes]:
    rest = head
    while True:
        block = f.read(READ_BUFFER)
        lines = (rest + block).split(b"\r")
        rest = lines.pop()
        for line in lines:
            yield line + b"\n"
        if not block:
            break
    if rest:
        yield rest


def quote(line: bytes, limit: int = MAX_QUOTED) -> str:
    """A line for an error text: stripped, cut at ``limit`` characters, quoted as Python's
    ``ascii`` does (a byte that is no ASCII shows as ``\\xff``, never as a stand-in)."""
    text = line.decode("latin-1").strip(STRIPPED)
    if len(text) > limit:
        text = text[: limit - 3] + "..."
    return ascii(text)


STRIPPED: Final = " \t\n\r\x0b\x0c\x1c\x1d\x1e\x1f"  # what str.strip takes of ASCII


def reason(exc: BaseException) -> str:
    """Why a line is bad, in at most MAX_REASON characters."""
    text = str(exc)
    return text if len(text) <= MAX_REASON else text[: MAX_REASON - 3] + "..."


# -- time ----------------------------------------------------------------------------------------


class Clock:
    """Turns a line's stamp into ``t``: summed when the log holds -td deltas."""

    def __init__(self, deltas: bool = False) -> None:
        self.deltas = deltas
        self.total = 0.0

    def relative(self, stamp: float) -> float:
        """A numeric stamp of a default-layout or ERROR line."""
        if not self.deltas or stamp >= RELATIVE_LIMIT:
            return stamp
        self.total += stamp
        return self.total


def holds_deltas(head: bytes, cr: bool) -> bool:
    """Whether the relative stamps of a log's default-layout lines go back somewhere in its
    first 64 KiB: ``candump -td``, whose stamps are the gaps between frames."""
    lines = head.split(b"\r" if cr else b"\n")
    lines.pop()  # the last one may be cut
    clock = Clock()
    channels: dict[bytes, str] = {}
    last = -1.0
    for line in lines:
        try:
            parsed = parse_line(line + b"\n", channels, clock)
        except ValueError:
            continue
        if parsed is None or parsed[1] != _COLUMNS or parsed[0].t is None:
            continue
        t = parsed[0].t
        if t >= RELATIVE_LIMIT or parsed[2]:  # Unix time, or a date
            continue
        if t < last:
            return True
        last = t
    return False


def local_time(date: bytes, clock: bytes) -> float:
    """``2020-12-19`` and ``12:04:45.485261`` (candump -tA) as Unix time, read in this machine's
    time zone as candump wrote it in the recording machine's (``TZ`` sets it)."""
    ymd = date.split(b"-")
    hms, _, frac = clock.partition(b".")
    fields = [*ymd, *hms.split(b":")]
    widths = [(4, 4), (1, 2), (1, 2), (1, 2), (1, 2), (1, 2)]
    if len(fields) != 6 or not all(
        lo <= len(x) <= hi and x.isdigit() for x, (lo, hi) in zip(fields, widths, strict=False)
    ):
        raise ValueError("bad date and time")
    if frac and not (frac.isdigit() and len(frac) <= 9):
        raise ValueError("bad date and time")
    y, mo, d, h, mi, s = (int(x) for x in fields)
    if not (1 <= mo <= 12 and 1 <= d <= 31 and h <= 23 and mi <= 59 and s <= 60):
        raise ValueError("bad date and time")
    try:
        seconds = time.mktime((y, mo, d, h, mi, s, 0, 0, -1))
    except OverflowError:
        raise ValueError("bad date and time") from None
    return seconds + (int(frac) / 10 ** len(frac) if frac else 0.0)


# -- one line ------------------------------------------------------------------------------------


def parse_line(
    line: bytes, channels: dict[bytes, str], clock: Clock
) -> tuple[CanFrame, str, bool] | None:
    """Any candump line: (frame, layout, dated) where layout is "log" (-l/-L) or "columns"
    (the default layout, ERROR lines) and dated says the stamp was a date; None for a blank or
    ``#`` comment line; else ValueError saying what is wrong."""
    parts = line.split()
    if not parts or parts[0][:1] == b"#":
        return None
    t: float | None = None
    dated = False
    rest = parts
    first = parts[0]
    if first[:1] == b"(":
        if len(first) > 1 and first[-1:] == b")":
            t = float(first[1:-1])
            rest = parts[1:]
        elif len(parts) > 1 and parts[1][-1:] == b")":
            t = local_time(first[1:], parts[1][:-1])
            dated = True
            rest = parts[2:]
        else:
            raise ValueError("no (timestamp)")
    if len(rest) < 2:
        raise ValueError("expected a channel and a frame")
    chan, body = rest[0], rest[1:]
    if body == [b"ERROR"]:
        frame = CanFrame(None, 0, b"", True, False, True, False, 0, _channel(chan, channels))
        layout = _COLUMNS
    elif b"#" in body[0] and (len(body) == 1 or (len(body) == 2 and body[1] in _DIRECTIONS)):
        frame = _log_frame(body[0], _channel(chan, channels))
        layout = _LOG
    elif len(body) >= 2 and body[1][:1] == b"[":
        frame = _columns_frame(body, _channel(chan, channels))
        layout = _COLUMNS
    else:
        raise ValueError("not a candump frame")
    if t is not None and layout == _COLUMNS and not dated:
        t = clock.relative(t)
    frame.t = t
    return frame, layout, dated


def is_complete(line: bytes, layout: str) -> bool:
    """Whether a line that parsed, but has no line end (the file's last), cannot be the start
    of a longer one. The default layout states the length and was checked against it; a -L
    line states none, so only one at a full length (8 data bytes, 64 in CAN FD), with its
    direction flag, a remote DLC or a DLC suffix is known to be whole."""
    parts = line.split()
    if layout != _LOG or parts[-1] in _DIRECTIONS:
        return True
    payload = parts[-1].partition(b"#")[2]
    if payload[:1] == b"#":
        return len(payload) == 2 + 2 * CANFD_MAX_LEN
    if payload[:1] in (b"R", b"r"):
        return len(payload) == 2
    return b"_" in payload or len(payload) == 16


def _channel(chan: bytes, channels: dict[bytes, str]) -> str:
    channel = channels.get(chan)
    if channel is None:
        try:
            channel = chan.decode("ascii")
        except UnicodeDecodeError:
            raise ValueError("the channel name is not ASCII") from None
        channels[chan] = channel
    return channel


def _identifier(ident: bytes) -> tuple[int, bool, bool]:
    """(identifier, extended, error frame) of 1-8 hex digits as candump prints them."""
    if not ident or not _HEX_DIGITS.issuperset(ident) or len(ident) > 8:
        raise ValueError(f"bad identifier {ident.decode('ascii', 'replace')!r}")
    aid = int(ident, 16)
    extended = len(ident) > 3
    error = False
    if extended:
        if aid & CAN_RTR_FLAG:
            raise ValueError(f"identifier {ident.decode()} does not fit in 29 bits")
        error = bool(aid & CAN_ERR_FLAG)
        aid &= CAN_EFF_MASK
    elif aid > 0x7FF:
        raise ValueError("standard identifier above 0x7FF")
    return aid, extended, error


def _log_frame(body: bytes, channel: str) -> CanFrame:
    """``ID#DATA`` and its variants (-l/-L)."""
    ident, _, payload = body.partition(b"#")
    aid, extended, error = _identifier(ident)
    remote = fd = False
    if payload[:1] == b"#":  # CAN FD: "##", one flags digit (BRS, ESI: not kept), the data
        if len(payload) < 2 or payload[1] not in _HEX_DIGITS:
            raise ValueError("CAN FD frame without its flags digit")
        fd = True
        data = binascii.unhexlify(payload[2:])
        dlc = len(data)
    elif payload[:1] in (b"R", b"r"):  # remote frame, optional DLC digit
        data = b""
        dlc = int(payload[1:], 16) if len(payload) > 1 else 0
        if not 0 <= dlc <= 15:
            raise ValueError("bad remote DLC")
        remote = True
    elif b"_" in payload:  # classic frame with a DLC of 9-15: 8 data bytes and "_<dlc>"
        hexdata, _, dlc_text = payload.partition(b"_")
        data = binascii.unhexlify(hexdata)
        dlc = int(dlc_text, 16)
        if len(data) != 8 or not 9 <= dlc <= 15:
            raise ValueError("bad DLC suffix")
    else:
        try:
            data = binascii.unhexlify(payload)
        except binascii.Error as exc:
            raise ValueError(f"bad data: {exc}") from None
        dlc = len(data)
        fd = dlc > 8  # more than a classic frame holds: CAN FD written without its "##"
    if len(data) > CANFD_MAX_LEN:
        raise ValueError(f"{len(data)} data bytes: more than a CAN FD frame holds")
    return CanFrame(None, aid, data, extended, remote, error, fd, dlc, channel)


def _columns_frame(body: list[bytes], channel: str) -> CanFrame:
    """``ID  [n]  AA BB ...`` (the default layout): data bytes as many as the length says, then
    nothing, the ASCII view (``'...'``) or ``ERRORFRAME``."""
    aid, extended, error = _identifier(body[0])
    digits = body[1][1:-1]
    if body[1][-1:] != b"]" or not digits.isdigit() or len(digits) > 2:
        raise ValueError(f"bad length {body[1].decode('ascii', 'replace')!r}")
    n = int(digits)
    fd = len(digits) == 2  # candump prints a CAN FD length with two digits: [08], [12]
    if n > CANFD_MAX_LEN:
        raise ValueError(f"length {n}: more than a CAN FD frame holds")
    values = body[2:]
    if values == [b"remote", b"request"] and not fd:
        return CanFrame(None, aid, b"", extended, True, error, False, n, channel)
    tokens, tail = values[:n], values[n:]
    if len(tokens) < n or not all(len(x) == 2 and _HEX_DIGITS.issuperset(x) for x in tokens):
        raise ValueError(f"expected {n} data bytes")
    if tail and tail != [b"ERRORFRAME"] and tail[0][:1] != b"'":
        raise ValueError(f"more than {n} data bytes")
    return CanFrame(None, aid, bytes.fromhex(b"".join(tokens).decode()), extended, False, error,
                    fd or n > 8, n, channel)  # fmt: skip
