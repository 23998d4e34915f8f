"""Modbus RTU framing: finding frames in the bytes of an RS485 line (reference section 2.2).

RTU marks frame boundaries with silence, which a tap behind a USB adapter (or a capture without
timing) does not see. So a frame is found from its bytes: the function code (and a byte count)
give the candidate lengths, the CRC-16/MODBUS confirms one. A read request (8 bytes) and a
one-register read response (7 bytes) start the same way; both are tried, the shape the bus
expects first (a request is pending: response first), and the CRC decides. A frame-shaped
candidate with a bad CRC is reported as a frame only where it is plausible as one (the stream
ends right after it, a timing gap follows it, or a valid frame starts right after it); otherwise
its first byte is garbage and the search goes on one byte later. Timing gaps only ever help;
nothing needs them.

CRC-16 collides structurally between readings one or two bytes apart (a good frame followed by
00 is a good frame one byte longer; one frame in 256 has a good prefix one byte shorter), so a
reading within two bytes of the chosen one is checked too, and when both hold, what the
readings say and what follows them settles it (``ModbusFramer._decide``). That is why a read
request of 1024-1279 (01 03 04 ..) waits for the next byte before it is decided, unless the
source knows the direction.

What the frames mean is ``modbus_pdu``'s business; ``modbus_rtu.ModbusRtuDecoder`` joins the two.
Frames are built by ``decoders.build``.
"""

from __future__ import annotations

from typing import Any, Final

import crcmod.predefined

from . import messages as M
from .framing import LINE_BITS_PER_BYTE, NEED_MORE, ByteStreamDecoder
from .model import MODBUS_RTU, RESPONSE

crc16: Final = crcmod.predefined.mkCrcFun("modbus")  # CRC-16/MODBUS (C extension)

# Modbus over serial line (V1.02, 2.5.1.1): frames are apart by at least 3.5 characters of
# silence; above 19200 baud by a fixed 1.75 ms
SILENCE_CHARACTERS: Final = 3.5
FIXED_SILENCE_ABOVE_BAUD: Final = 19200
FIXED_SILENCE_S: Final = 0.00175


def frame_silence_s(baud: int) -> float:
    """The silence the Modbus RTU standard puts between frames at ``baud`` (t3.5)."""
    if baud > FIXED_SILENCE_ABOVE_BAUD:
        return FIXED_SILENCE_S
    return SILENCE_CHARACTERS * LINE_BITS_PER_BYTE / baud


def _raw_crc() -> tuple[Any, Any]:
    """crcmod's C function and table, to skip its Python wrapper on the hot path."""
    try:
        init, table, fun = crc16.__defaults__  # type: ignore[attr-defined]
        if init == 0xFFFF and fun(b"123456789", 0xFFFF, table) == 0x4B37:
            return fun, table
    except (AttributeError, TypeError, ValueError):
        pass
    return (lambda data, init, table: crc16(data)), None


_crc, _TABLE = _raw_crc()

# function codes, as sent in requests (an exception response sets bit 7)
READ_COILS, READ_DISCRETE, READ_HOLDING, READ_INPUT = 0x01, 0x02, 0x03, 0x04
WRITE_COIL, WRITE_SINGLE, WRITE_COILS, WRITE_MULTIPLE = 0x05, 0x06, 0x0F, 0x10

FUNCTION_TEXT: Final[dict[int, str]] = {
    READ_COILS: "read coils",
    READ_DISCRETE: "read discrete inputs",
    READ_HOLDING: "read holding registers",
    READ_INPUT: "read input registers",
    WRITE_COIL: "write single coil",
    WRITE_SINGLE: "write single register",
    WRITE_COILS: "write multiple coils",
    WRITE_MULTIPLE: "write multiple registers",
}

# what a function code byte announces: 0 nothing we frame, else one of these shapes
KIND_READ, KIND_SINGLE, KIND_MULTI, KIND_EXCEPTION = 1, 2, 3, 4
_kind = bytearray(256)
for _fc in (READ_COILS, READ_DISCRETE, READ_HOLDING, READ_INPUT):
    _kind[_fc] = KIND_READ
for _fc in (WRITE_COIL, WRITE_SINGLE):
    _kind[_fc] = KIND_SINGLE
for _fc in (WRITE_COILS, WRITE_MULTIPLE):
    _kind[_fc] = KIND_MULTI
for _fc in FUNCTION_TEXT:
    _kind[_fc | 0x80] = KIND_EXCEPTION
KIND: Final = bytes(_kind)

NO_ADDRESS: Final = 0xFF  # never a slave address (the gripper takes 1-254, 0 is broadcast)
CLOSE: Final = 2  # candidate lengths this near each other can collide structurally (_decide)

# (slave, function, first PDU word, second PDU word, its CRC held) of the request awaiting its
# response. A request with a bad CRC still names the registers of a response that fits it (the
# slave answered, so it read the request; the damage was on the tap's side or in the CRC alone).
Pending = tuple[int, int, int, int, bool]


def read_response_len(fc: int, bc: int) -> int:
    """Length of a read response with byte count bc, 0 if bc cannot be one."""
    if bc == 0 or (fc >= READ_HOLDING and bc & 1):
        return 0
    return 5 + bc


def write_request_len(fc: int, count: int, bc: int) -> int:
    """Length of a write-multiple request, 0 if count and byte count disagree."""
    if count == 0:
        return 0
    if fc == WRITE_MULTIPLE:
        return 9 + bc if bc == 2 * count else 0
    return 9 + bc if bc == (count + 7) >> 3 else 0


def candidates(buf: bytes | bytearray, pos: int, n: int, kind: int, resp_first: bool) -> list[int]:
    """Candidate frame lengths at pos, preferred first; -1 where the length is not known yet."""
    fc = buf[pos + 1]
    if kind == KIND_READ:
        resp = read_response_len(fc, buf[pos + 2]) if pos + 2 < n else -1
        if resp == 0 or resp == 8:
            return [8]
        return [resp, 8] if resp_first else [8, resp]
    if kind == KIND_MULTI:
        if pos + 6 < n:
            req = write_request_len(fc, buf[pos + 4] << 8 | buf[pos + 5], buf[pos + 6])
        else:
            req = -1
        if req == 0:
            return [8]
        return [8, req] if resp_first else [req, 8]
    if kind == KIND_SINGLE:
        return [8]
    return [5]


CRC_BAD, CRC_OK, CRC_SWAPPED_ORDER = 0, 1, 2


def crc_state(buf: bytes | bytearray, pos: int, end: int) -> int:
    """CRC_OK, CRC_SWAPPED_ORDER or CRC_BAD for the frame buf[pos:end]."""
    c = _crc(buf[pos : end - 2], 0xFFFF, _TABLE)
    got = buf[end - 2] | buf[end - 1] << 8
    if got == c:
        return CRC_OK
    return CRC_SWAPPED_ORDER if got == ((c >> 8) | (c & 0xFF) << 8) else CRC_BAD


def _first_holding(states: list[int | None], final: bool) -> int | None:
    """Index of the first reading whose CRC holds, -1 if none does; None while a reading
    preferred to it is not complete yet."""
    for i, state in enumerate(states):
        if state is None:
            if not final:
                return None
        elif state:
            return i
    return -1


def _contenders(
    cands: list[int], states: list[int | None], best: int, rivals: bool, final: bool
) -> list[int] | None:
    """The holding reading cands[best] and the later readings close enough to rival it that
    hold too; None while such a rival is not complete yet."""
    length = cands[best]
    contenders = [length]
    for c, state in zip(cands[best + 1 :], states[best + 1 :], strict=True):
        if rivals and (c < 0 or abs(c - length) <= CLOSE):
            if state is None:
                if not final:
                    return None
            elif state:
                contenders.append(c)
    return contenders


class ModbusFramer(ByteStreamDecoder):
    """The framing half of the Modbus RTU decoder: ``frame_at`` and what it needs. The
    decoder keeps ``_pending`` (the request awaiting its response) up to date."""

    protocol = MODBUS_RTU

    def __init__(self, bus: str = "rs485", *, byte_time_s: float | None = None) -> None:
        super().__init__(bus, byte_time_s=byte_time_s)
        self._pending: Pending | None = None
        # (offset, length) of the last frame frame_at found valid with its CRC bytes swapped;
        # a frame's CRC state is a property of its bytes, so this never goes stale
        self._swapped: tuple[int, int] | None = None

    @property
    def pending(self) -> Pending | None:
        """(slave, function, start or address, count or value, CRC held) of the request
        awaiting its response, as on the wire."""
        return self._pending

    def frame_at(self, buf: bytearray, pos: int, final: bool) -> int:
        n = len(buf)
        if buf[pos] == NO_ADDRESS:
            return 0
        if pos + 1 >= n:
            return NEED_MORE
        kind = KIND[buf[pos + 1]]
        if kind in (KIND_SINGLE, KIND_EXCEPTION):  # one shape, either direction
            return self._one_shape_at(buf, pos, n, final, 8 if kind == KIND_SINGLE else 5)
        if not kind:
            return 0
        hint = self.direction_hint
        first, second = self._two_readings(buf, pos, n, kind, hint)
        length = self._expected_reading(buf, pos, n, final, first, second, hint)
        if length is not None:
            return length
        cands = [first] if second == 0 else [first, second]
        return self._decide(buf, pos, n, final, cands, hint is None)

    def _one_shape_at(self, buf: bytearray, pos: int, n: int, final: bool, length: int) -> int:
        """frame_at for a function with one frame length in either direction."""
        end = pos + length
        if end <= n:
            c = _crc(buf[pos : end - 2], 0xFFFF, _TABLE)
            got = buf[end - 2] | buf[end - 1] << 8
            if got == c:
                return length
            if got == ((c >> 8) | (c & 0xFF) << 8):
                self._swapped = (self._base + pos, length)  # for make_record
                return length
        return self._decide(buf, pos, n, final, [length], False)

    def _two_readings(
        self, buf: bytearray, pos: int, n: int, kind: int, hint: str | None
    ) -> tuple[int, int]:
        """The two candidate lengths, preferred first, as candidates() orders them (inlined:
        this runs once per frame); second == 0: none, -1: its length is not known yet."""
        if hint is None:
            p = self._pending
            resp_first = p is not None and p[0] == buf[pos]
        else:
            resp_first = hint == RESPONSE
        fc = buf[pos + 1]
        if kind == KIND_READ:
            if pos + 2 < n:
                bc = buf[pos + 2]
                other = 0 if bc == 0 or (fc >= READ_HOLDING and bc & 1) or bc == 3 else 5 + bc
            else:
                other = -1
            return (other, 8) if resp_first and other else (8, other)
        if pos + 6 < n:
            other = write_request_len(fc, buf[pos + 4] << 8 | buf[pos + 5], buf[pos + 6])
        else:
            other = -1
        return (8, other) if resp_first or not other else (other, 8)

    def _expected_reading(
        self,
        buf: bytearray,
        pos: int,
        n: int,
        final: bool,
        first: int,
        second: int,
        hint: str | None,
    ) -> int | None:
        """The common case: the expected shape checks, and no other reading is close enough
        to it to collide (see _decide) or that reading fails its CRC; a known direction
        settles the reading by itself. None when this does not settle it."""
        end = pos + first
        if first <= 0 or end > n:
            return None
        c = _crc(buf[pos : end - 2], 0xFFFF, _TABLE)
        got = buf[end - 2] | buf[end - 1] << 8
        if got != c and got != ((c >> 8) | (c & 0xFF) << 8):
            return None
        d = second - first
        if second > 0 and hint is None and -CLOSE <= d <= CLOSE:
            rival = self._close_reading_holds(buf, pos, n, final, end, second, got == c)
            if rival is None:
                return NEED_MORE
            if rival:  # then _decide settles it
                return self._decide(buf, pos, n, final, [first, second], True)
        if got != c:
            self._swapped = (self._base + pos, first)  # for make_record
        return first

    @staticmethod
    def _close_reading_holds(
        buf: bytearray, pos: int, n: int, final: bool, end: int, second: int, exact: bool
    ) -> bool | None:
        """Does the close reading of length second hold its CRC too, beside the one ending at
        end? None when that needs more bytes."""
        d = pos + second - end
        if d > 0 and exact:
            # exact shortcut: this frame's CRC residue is 0, so a reading d bytes longer holds
            # exactly when the d bytes after it are 00
            if end + d > n:
                return None if not final else False
            return not buf[end] and (d == 1 or not buf[end + 1])
        if pos + second > n:
            return None if not final else False
        return crc_state(buf, pos, pos + second) != CRC_BAD

    def _decide(
        self, buf: bytearray, pos: int, n: int, final: bool, cands: list[int], rivals: bool
    ) -> int:
        """frame_at beyond the common case: every candidate, in the order the bus expects.

        The reading is the first candidate whose CRC holds. Another reading within CLOSE bytes
        of it is checked too: CRC-16 makes such pairs collide far more often than 1 in 65536
        (a good frame followed by a 00 byte is a good frame one byte longer; a frame whose last
        data byte equals the low CRC byte of the bytes before it has a good prefix one byte
        shorter: 1 in 256). When both hold, the one followed by a frame boundary (a good frame,
        a timing gap or the end of the stream) wins; failing that, the expected one.
        """
        states = [None if c < 0 or pos + c > n else crc_state(buf, pos, pos + c) for c in cands]
        best = _first_holding(states, final)
        if best is None:
            return NEED_MORE
        if best < 0:
            return self._damaged_reading(buf, pos, n, final, cands, states)
        contenders = _contenders(cands, states, best, rivals, final)
        if contenders is None:
            return NEED_MORE
        length = contenders[0]
        if len(contenders) > 1:
            length = self._settle(buf, pos, n, final, contenders, cands[0])
            if length == NEED_MORE:
                return NEED_MORE
        if states[cands.index(length)] == CRC_SWAPPED_ORDER:
            self._swapped = (self._base + pos, length)
        return length

    def _damaged_reading(
        self,
        buf: bytearray,
        pos: int,
        n: int,
        final: bool,
        cands: list[int],
        states: list[int | None],
    ) -> int:
        """Every candidate failed its CRC, or the stream ended: the first candidate cut off by
        the end makes a truncated frame (the base reports it on NEED_MORE when final); a bad
        CRC makes a frame only where one plausibly ends."""
        for c, state in zip(cands, states, strict=True):
            if state is None:
                return NEED_MORE
            end = pos + c
            if end == n:
                return -c if final else NEED_MORE  # not final: does the stream end here?
            if self.gap_at(end):
                return -c
            after = self._valid_at(buf, end, n, final)
            if after is None:
                return NEED_MORE
            if after:
                return -c
        return 0

    def _settle(
        self, buf: bytearray, pos: int, n: int, final: bool, contenders: list[int], expected: int
    ) -> int:
        """Several readings at pos hold their CRC: the one that makes sense wins.

        First what the readings say (the expected direction, and content a host or gripper
        would send: a read count of 1-125, a response that fits the pending request), then
        what follows them (a good frame, a timing gap or the end of the stream), then the
        expected reading. A stray 00 byte after a request (a bus turnaround glitch) makes the
        same bytes as a response whose 8-byte prefix collides; this tells them apart.
        """
        scores = [self._sense(buf, pos, c) + (c == expected) for c in contenders]
        top = max(scores)
        tied = [c for c, score in zip(contenders, scores, strict=True) if score == top]
        if len(tied) == 1:
            return tied[0]
        for c in tied:
            end = pos + c
            if end >= n:
                if not final:
                    return NEED_MORE
                return c
            if self.gap_at(end):
                return c
            after = self._valid_at(buf, end, n, final)
            if after is None:
                return NEED_MORE
            if after:
                return c
        return tied[0]

    def _sense(self, buf: bytearray, pos: int, length: int) -> int:
        """1 if the reading of buf[pos:pos + length] is content a real device would send."""
        slave, fc = buf[pos], buf[pos + 1]
        kind = KIND[fc]
        p = self._pending
        answers = p is not None and p[0] == slave and p[1] == fc
        if kind == KIND_READ and length == 8:  # a read request
            count = buf[pos + 4] << 8 | buf[pos + 5]
            return int(1 <= count <= (125 if fc >= READ_HOLDING else 2000))
        if kind == KIND_READ:  # a read response
            if not answers or p is None:
                return 1
            bc = buf[pos + 2]
            return int(bc == (2 * p[3] if fc >= READ_HOLDING else (p[3] + 7) >> 3))
        if kind == KIND_MULTI and length == 8:  # a write-multiple response
            start, count = buf[pos + 2] << 8 | buf[pos + 3], buf[pos + 4] << 8 | buf[pos + 5]
            if answers and p is not None:
                return int(p[2] == start and p[3] == count)
            return int(1 <= count <= (123 if fc == WRITE_MULTIPLE else 1968))
        return 1

    def _valid_at(self, buf: bytearray, pos: int, n: int, final: bool) -> bool | None:
        """Does a frame with a good CRC start at pos? None: not known before more bytes."""
        if pos >= n:
            return False if final else None
        if buf[pos] == NO_ADDRESS:
            return False
        if pos + 1 >= n:
            return False if final else None
        kind = KIND[buf[pos + 1]]
        if not kind:
            return False
        cut = False
        for length in candidates(buf, pos, n, kind, False):
            if length < 0 or pos + length > n:
                cut = True
            elif crc_state(buf, pos, pos + length):
                return True
        return None if cut and not final else False

    def truncated_reason(self, raw: bytes) -> str:
        n = len(raw)
        got = f"{n} byte{'s' if n != 1 else ''}"
        kind = KIND[raw[1]] if n >= 2 else 0
        if not kind:
            return M.MODBUS_TRUNCATED.text(bytes=got)
        func = FUNCTION_TEXT[raw[1] & 0x7F]
        what = f"exception response to {func}" if kind == KIND_EXCEPTION else func
        lengths = sorted({c for c in candidates(raw, 0, n, kind, False) if c > n})
        if lengths:
            text = " or ".join(map(str, lengths))
            return M.MODBUS_TRUNCATED_LENGTHS.text(length=n, lengths=text, what=what)
        return M.MODBUS_TRUNCATED_FUNCTION.text(bytes=got, what=what)
