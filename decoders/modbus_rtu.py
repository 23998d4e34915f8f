"""Modbus RTU on the EG2-4X2's RS485 line (reference section 2), from the bytes alone.

Framing. RTU marks frame boundaries with silence, which a tap behind a USB adapter (or a
capture without timing) does not see. So a frame is found from its bytes: the function code
(and a byte count) give the candidate lengths, the CRC-16/MODBUS confirms one. A read request
(8 bytes) and a one-register read response (7 bytes) start the same way; both are tried, the
shape the bus expects first (a request is pending: response first), and the CRC decides. A
frame-shaped candidate with a bad CRC is reported as a frame only where it is plausible as one
(the stream ends right after it, a timing gap follows it, or a valid frame starts right after
it); otherwise its first byte is garbage and the search goes on one byte later. Timing gaps
only ever help; nothing needs them.

CRC-16 collides structurally between readings one or two bytes apart (a good frame followed by
00 is a good frame one byte longer; one frame in 256 has a good prefix one byte shorter), so a
reading within two bytes of the chosen one is checked too, and when both hold, what the
readings say and what follows them settles it (``ModbusRtuDecoder._decide``). That is why a
read request of 1024-1279 (01 03 04 ..) waits for the next byte before it is decided, unless
the source knows the direction.

Direction. The bus is half duplex: requests and responses alternate. The shape decides for
reads (8 bytes: request; 5 + 2N: response), write multiple (9 + 2N: request; 8: response) and
exceptions; a write single (request and response identical) is the response of the pending
request it echoes, else a request. A direction the source knows (``direction_hint``) wins
where the shape cannot decide.

Registers are named from ``registers`` in both numberings (1010, or 10 as some hosts send it,
section 4; the first register's numbering, as ``registers.by_modbus`` resolves it, holds for a
whole range). A read response is named from its pending request; one without a known request
shows its values by index.

Speed: decoded frames are memoised by (bytes, pending request, direction hint), so a polling
loop costs a dictionary lookup and a Record per frame once values repeat; register values are
memoised per register, so a response with new values costs little more.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from typing import Any, Final

import crcmod.predefined

from .framing import NEED_MORE, ByteStreamDecoder
from .model import FRAME, MODBUS_RTU, REQUEST, RESPONSE, Record
from .registers import (
    BY_NUMBER,
    FIRST,
    LAST,
    SAVE_REGISTERS,
    Register,
    by_modbus,
    undocumented,
)

crc16: Final = crcmod.predefined.mkCrcFun("modbus")  # CRC-16/MODBUS (C extension)


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

CRC_SWAPPED: Final = "CRC byte order swapped (high byte first)"
NO_REQUEST: Final = "read response without a known request: registers unknown"
SHORT_NOTE: Final = "the host leaves out the 1000 offset, as some clients do"

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
FUNCTION_NAME: Final[dict[int, str]] = {
    READ_COILS: "READ_COILS",
    READ_DISCRETE: "READ_DISCRETE_INPUTS",
    WRITE_COIL: "WRITE_SINGLE_COIL",
    WRITE_COILS: "WRITE_MULTIPLE_COILS",
}
EXCEPTION_TEXT: Final[dict[int, str]] = {
    1: "illegal function",
    2: "illegal data address",
    3: "illegal data value",
    4: "server device failure",
    5: "acknowledge",
    6: "server device busy",
    8: "memory parity error",
    10: "gateway path unavailable",
    11: "gateway target device failed to respond",
}
EG2_FUNCTIONS: Final = frozenset({READ_HOLDING, WRITE_SINGLE, WRITE_MULTIPLE})

# what a function code byte announces: 0 nothing we frame, else one of these shapes
_READ, _SINGLE, _MULTI, _EXC = 1, 2, 3, 4
_kind = bytearray(256)
for _fc in (READ_COILS, READ_DISCRETE, READ_HOLDING, READ_INPUT):
    _kind[_fc] = _READ
for _fc in (WRITE_COIL, WRITE_SINGLE):
    _kind[_fc] = _SINGLE
for _fc in (WRITE_COILS, WRITE_MULTIPLE):
    _kind[_fc] = _MULTI
for _fc in FUNCTION_TEXT:
    _kind[_fc | 0x80] = _EXC
KIND: Final = bytes(_kind)

BROADCAST: Final = 0
NO_ADDRESS: Final = 0xFF  # never a slave address (the gripper takes 1-254, 0 is broadcast)
MEMO_LIMIT: Final = 50_000
CLOSE: Final = 2  # candidate lengths this near each other can collide structurally (_decide)

# (slave, function, first PDU word, second PDU word, its CRC held) of the request awaiting its
# response. A request with a bad CRC still names the registers of a response that fits it (the
# slave answered, so it read the request; the damage was on the tap's side or in the CRC alone).
Pending = tuple[int, int, int, int, bool]
UNTRUSTED: Final = "registers named from a request with a CRC error"


def _read_response_len(fc: int, bc: int) -> int:
    """Length of a read response with byte count bc, 0 if bc cannot be one."""
    if bc == 0 or (fc >= READ_HOLDING and bc & 1):
        return 0
    return 5 + bc


def _write_request_len(fc: int, count: int, bc: int) -> int:
    """Length of a write-multiple request, 0 if count and byte count disagree."""
    if count == 0:
        return 0
    if fc == WRITE_MULTIPLE:
        return 9 + bc if bc == 2 * count else 0
    return 9 + bc if bc == (count + 7) >> 3 else 0


def candidates(buf: bytes | bytearray, pos: int, n: int, kind: int, resp_first: bool) -> list[int]:
    """Candidate frame lengths at pos, preferred first; -1 where the length is not known yet."""
    fc = buf[pos + 1]
    if kind == _READ:
        resp = _read_response_len(fc, buf[pos + 2]) if pos + 2 < n else -1
        if resp == 0 or resp == 8:
            return [8]
        return [resp, 8] if resp_first else [8, resp]
    if kind == _MULTI:
        if pos + 6 < n:
            req = _write_request_len(fc, buf[pos + 4] << 8 | buf[pos + 5], buf[pos + 6])
        else:
            req = -1
        if req == 0:
            return [8]
        return [8, req] if resp_first else [req, 8]
    if kind == _SINGLE:
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


def crc_bytes(body: bytes) -> bytes:
    """The two CRC bytes that follow body on the wire (low byte first)."""
    c = crc16(body)
    return bytes((c & 0xFF, c >> 8))


def with_crc(body: bytes) -> bytes:
    """body followed by its CRC, as a frame on the wire."""
    return body + crc_bytes(body)


# -- the register side -----------------------------------------------------------------------


def _register(number: int) -> Register:
    """The register at a full (1000-numbered) number; a placeholder where the map has none."""
    reg = BY_NUMBER.get(number)
    if reg is not None:
        return reg
    if FIRST <= number <= LAST:
        return undocumented(number)
    return undocumented(number, f"register {number}, outside the EG2 register map")


def _outside(reg: Register) -> bool:
    return not FIRST <= reg.number <= LAST


def _spans(numbers: list[int]) -> str:
    """1013, 1014, 1015, 1018 -> '1013-1015, 1018'."""
    parts: list[str] = []
    i = 0
    while i < len(numbers):
        j = i
        while j + 1 < len(numbers) and numbers[j + 1] == numbers[j] + 1:
            j += 1
        parts.append(str(numbers[i]) if i == j else f"{numbers[i]}-{numbers[j]}")
        i = j + 1
    return ", ".join(parts)


class _Plan:
    """The registers a (start, count) on the wire addresses, named once and memoised."""

    __slots__ = (
        "cells",
        "count",
        "extra",
        "items",
        "name",
        "names",
        "read_only",
        "regs",
        "response_fields",
        "save_names",
        "short",
        "start",
        "summary_keys",
        "unpack",
        "warnings",
    )

    def __init__(self, wire_start: int, count: int) -> None:
        # the numbering is the first register's (10 = 1010), as registers.by_modbus says
        first_lookup = by_modbus(wire_start)
        self.short = short = first_lookup is not None and first_lookup.short
        self.start = start = wire_start + 1000 if short else wire_start
        self.count = count
        # the fields every frame over these registers carries
        self.extra: dict[str, Any] = {"start": start, "count": count}
        if short:
            self.extra.update(numbering="short", address=wire_start)
        # a read response's fields, in order; slave and values filled in per frame
        self.response_fields: dict[str, Any] = {
            "slave": None,
            "function": READ_HOLDING,
            "byte_count": 2 * count,
            **self.extra,
            "values": None,
        }
        warnings: list[str] = []
        listed = min(count, 127)  # the most registers a byte count can carry
        self.regs = regs = tuple(_register(start + i) for i in range(listed))
        self.names = [r.name for r in regs]
        self.cells = tuple(_cell(r.number) for r in regs)
        self.items = tuple(zip(self.names, self.cells, regs, strict=True))
        self.unpack = struct.Struct(f">{listed}H").unpack_from
        if count == 0:
            self.name: str | None = None
            self.summary_keys = ""
        else:
            first, last = regs[0], _register(start + count - 1)
            self.name = first.name if count == 1 else f"{first.name}..{last.name}"
            self.summary_keys = first.key if count == 1 else f"{first.key}..{last.key}"
        if short:
            if count <= 1:
                warnings.append(f"short register number: {wire_start} means {start} ({SHORT_NOTE})")
            else:
                warnings.append(
                    f"short register numbers: {wire_start}-{wire_start + count - 1} mean "
                    f"{start}-{start + count - 1} ({SHORT_NOTE})"
                )
        undoc = [r.number for r in regs if not r.documented and not _outside(r)]
        if undoc:
            what = "register" if len(undoc) == 1 else "registers"
            warnings.append(f"undocumented {what} {_spans(undoc)} (not in the manual's map)")
        outside = [r.number for r in regs if _outside(r)]
        if count > listed:
            outside += [n for n in range(start + listed, start + count) if not FIRST <= n <= LAST]
        if outside:
            if len(outside) == 1:
                warnings.append(f"register {outside[0]} is outside the EG2 register map")
            else:
                warnings.append(f"registers {_spans(outside)} are outside the EG2 register map")
        self.warnings = tuple(warnings)
        # what a write to these registers needs to know
        read_only = [f"{r.number} ({r.name})" for r in regs if r.access == "ro"]
        self.read_only: str | None = None
        if read_only:
            what = "register" if len(read_only) == 1 else "registers"
            self.read_only = f"write to read-only {what} {', '.join(read_only)}"
        self.save_names = tuple(r.name for r in regs if r.number in SAVE_REGISTERS)

    def values(self, raw: bytes, at: int, end: int) -> tuple[dict[str, int], str, list[str]]:
        """Values in raw[at:end] as {name: value}, their texts joined, their range warnings."""
        if end - at >= 2 * len(self.regs):
            words: Iterable[int] = self.unpack(raw, at)
        else:
            words = _words(raw, at, end)
        values: dict[str, int] = {}
        texts: list[str] = []
        warns: list[str] = []
        for (name, cell, reg), w in zip(self.items, words):  # noqa: B905 (hot loop)
            v = cell.get(w)
            if v is None:
                v = _fill(cell, reg, w)
            values[name] = v[0]
            texts.append(v[1])
            if v[2] is not None:
                warns.append(v[2])
        return values, ", ".join(texts), warns


_plans: dict[tuple[int, int], _Plan] = {}


def plan(wire_start: int, count: int) -> _Plan:
    key = (wire_start, count)
    p = _plans.get(key)
    if p is None:
        if len(_plans) >= 4096:
            _plans.clear()
        p = _plans[key] = _Plan(wire_start, count)
    return p


# per register number: 16-bit wire value -> (value, "key=value unit", range warning)
Cell = dict[int, tuple[int, str, str | None]]
_cells: dict[int, Cell] = {}


def _cell(number: int) -> Cell:
    c = _cells.get(number)
    if c is None:
        if len(_cells) >= 4096:
            _cells.clear()
        c = _cells[number] = {}
    return c


def _fill(cell: Cell, reg: Register, raw: int) -> tuple[int, str, str | None]:
    if len(cell) >= 4096:
        cell.clear()
    value = reg.value(raw)
    v = cell[raw] = (value, reg.describe(value), reg.range_warning(value))
    return v


def _value(reg: Register, raw: int) -> tuple[int, str, str | None]:
    """(value, 'key=value unit', range warning) of a 16-bit wire value, memoised."""
    cell = _cell(reg.number)
    return cell.get(raw) or _fill(cell, reg, raw)


def _words(raw: bytes, lo: int, hi: int) -> list[int]:
    return [raw[i] << 8 | raw[i + 1] for i in range(lo, hi - 1, 2)]


# -- one frame's meaning ---------------------------------------------------------------------

# what make_record memoises: direction, name, fields, summary, errors, warnings, pair_key,
# expects_response, is_save, and the pending request after this frame
Entry = tuple[
    str | None,
    str | None,
    dict[str, Any],
    str,
    tuple[str, ...],
    tuple[str, ...],
    tuple[int, int] | None,
    bool,
    bool,
    Pending | None,
]


def _direction(raw: bytes, pending: Pending | None, hint: str | None) -> str | None:
    """request or response, from the shape where it decides, else from the hint or the bus."""
    n = len(raw)
    fc = raw[1]
    kind = KIND[fc]
    if kind == _EXC:
        return RESPONSE
    if kind == _READ:
        is_req = n == 8
        is_resp = _read_response_len(fc, raw[2]) == n
        if is_req != is_resp:
            return REQUEST if is_req else RESPONSE
    elif kind == _MULTI:
        return RESPONSE if n == 8 else REQUEST
    elif kind != _SINGLE:
        return None
    # the same bytes either way (a write single, or a coil read of 3 bytes)
    if hint is not None:
        return hint
    if (
        pending is not None
        and pending[0] == raw[0]
        and pending[1] == fc
        and (kind != _SINGLE or pending[2] == (raw[2] << 8 | raw[3]))
    ):
        return RESPONSE
    return REQUEST


def decode(
    raw: bytes, pending: Pending | None = None, hint: str | None = None, crc: int | None = None
) -> Entry:
    """The meaning of one frame (raw bytes with their CRC), given the pending request and
    the direction the source knows (if it does). ``crc``: the CRC state if already known."""
    n = len(raw)
    if (
        pending is not None
        and n > 5
        and raw[1] == READ_HOLDING
        and n == 5 + raw[2]
        and pending[1] == READ_HOLDING
        and pending[0] == raw[0] != BROADCAST
        and 2 * pending[3] == raw[2]
        and pending[4]
        and hint != REQUEST
    ):
        # the bulk of a polling capture: the answer to the read just seen (same result as
        # _decode, for a fraction of the work)
        if crc is None:
            crc = crc_state(raw, 0, n)
        if crc == CRC_OK:
            p = plan(pending[2], pending[3])
            values, texts, range_warnings = p.values(raw, 3, n - 2)
            slave = raw[0]
            fields = p.response_fields.copy()
            fields["slave"] = slave
            fields["values"] = values
            warnings = p.warnings + tuple(range_warnings) if range_warnings else p.warnings
            pair_key = (slave, READ_HOLDING)
            return (
                RESPONSE,
                p.name,
                fields,
                "-> " + texts,
                (),
                warnings,
                pair_key,
                False,
                False,
                None,
            )
    return _decode(raw, pending, hint, crc)


def _decode(raw: bytes, pending: Pending | None, hint: str | None, crc: int | None) -> Entry:
    errors: list[str] = []
    warnings: list[str] = []
    n = len(raw)
    if n < 4:
        errors.append(f"frame too short ({n} bytes)")
        short: dict[str, Any] = {"slave": raw[0] if raw else None}
        return (None, None, short, "", tuple(errors), (), None, False, False, None)
    kind = KIND[raw[1]]
    if not kind or n not in candidates(raw, 0, n, kind, False):
        what = FUNCTION_TEXT.get(raw[1] & 0x7F, f"function 0x{raw[1]:02X}") if kind else ""
        errors.append(f"{n} bytes are no Modbus frame shape ({what or f'code 0x{raw[1]:02X}'})")
        shapeless: dict[str, Any] = {"slave": raw[0], "function": raw[1] & 0x7F}
        return (None, None, shapeless, "", tuple(errors), (), None, False, False, None)
    if crc is None:
        crc = crc_state(raw, 0, n)
    valid = crc != CRC_BAD
    if crc == CRC_SWAPPED_ORDER:
        warnings.append(CRC_SWAPPED)
    elif not valid:
        c = crc16(raw[:-2])
        errors.append(
            f"CRC error: expected {c & 0xFF:02X} {c >> 8:02X}, got {raw[-2]:02X} {raw[-1]:02X}"
        )
    slave, fc = raw[0], raw[1]
    direction = _direction(raw, pending, hint)
    fields: dict[str, Any] = {"slave": slave, "function": fc & 0x7F}
    func = fc & 0x7F
    if kind and kind != _EXC and fc not in EG2_FUNCTIONS:
        warnings.append(
            f"function {fc} ({FUNCTION_TEXT[fc]}) is not one the EG2 documents (3, 6 and 16)"
        )
    if direction == RESPONSE and slave == BROADCAST:
        warnings.append("response from address 0 (broadcast requests get no response)")
    # a response is checked against the request it answers
    if direction == RESPONSE:
        answers = pending is not None and pending[0] == slave and pending[1] == func
        req = pending if answers else None
    else:
        req = None

    name: str | None = None
    summary = ""
    is_save = False
    if kind == _EXC:
        code = raw[2]
        text = EXCEPTION_TEXT.get(code, "")
        if not text:
            text = f"unknown exception code {code}"
            warnings.append(f"exception code {code} is not a standard Modbus exception")
        fields["exception_code"] = code
        fields["exception_text"] = text
        name = "EXCEPTION"
        summary = f"exception {code}: {text}"
        if n != 5:
            warnings.append(f"exception response of {n} bytes (5 expected)")
    elif kind == _READ and direction == REQUEST:
        start, count = raw[2] << 8 | raw[3], raw[4] << 8 | raw[5]
        name, summary = _read_request(fc, start, count, fields, warnings)
    elif kind == _READ:
        name, summary = _read_response(raw, fc, req, fields, warnings)
    elif kind == _SINGLE:
        name, summary, is_save = _write_single(raw, direction, req, fields, warnings)
    elif kind == _MULTI and direction == REQUEST:
        name, summary, is_save = _write_multiple(raw, fc, fields, warnings)
    elif kind == _MULTI:
        start, count = raw[2] << 8 | raw[3], raw[4] << 8 | raw[5]
        name, summary = _write_multiple_response(fc, start, count, req, fields, warnings)
    else:
        name = f"FUNCTION_{fc:02X}"
        summary = f"function 0x{fc:02X}"
        warnings.append(f"function code 0x{fc:02X} is not decoded")

    if direction == REQUEST:
        pair_key: tuple[int, int] | None = (slave, fc)
        expects = slave != BROADCAST
        nxt: Pending | None = None
        if expects and n >= 6:
            nxt = (slave, fc, raw[2] << 8 | raw[3], raw[4] << 8 | raw[5], valid)
    else:
        pair_key = (slave, func) if direction == RESPONSE else None
        expects = False
        nxt = None
        is_save = False
    return (
        direction,
        name,
        fields,
        summary,
        tuple(errors),
        tuple(warnings),
        pair_key,
        expects,
        is_save,
        nxt,
    )


def _read_request(
    fc: int, start: int, count: int, fields: dict[str, Any], warnings: list[str]
) -> tuple[str | None, str]:
    if fc <= READ_DISCRETE:  # coils and discrete inputs: bits, not EG2 registers
        what = "coils" if fc == READ_COILS else "discrete inputs"
        fields["start"] = start
        fields["count"] = count
        if not 1 <= count <= 2000:
            warnings.append(f"count {count} outside the Modbus limit of 1-2000 {what}")
        return FUNCTION_NAME[fc], f"read {count} {what} from {start}"
    p = plan(start, count)
    fields.update(p.extra)
    fields["registers"] = list(p.names)
    warnings.extend(p.warnings)
    if not 1 <= count <= 125:
        warnings.append(f"count {count} outside the Modbus limit of 1-125 registers")
    noun = "register" if count == 1 else "registers"
    keys = f" ({p.summary_keys})" if p.summary_keys else ""
    return p.name, f"read {count} {noun} from {p.start}{keys}"


def _read_response(
    raw: bytes, fc: int, req: Pending | None, fields: dict[str, Any], warnings: list[str]
) -> tuple[str | None, str]:
    bc = raw[2]
    fields["byte_count"] = bc
    data_end = min(3 + bc, len(raw) - 2)
    if fc <= READ_DISCRETE:
        data = raw[3:data_end]
        what = "coils" if fc == READ_COILS else "discrete inputs"
        if req is not None:
            count = req[3]
            bits = [(data[i >> 3] >> (i & 7)) & 1 for i in range(min(count, 8 * len(data)))]
            fields["start"] = req[2]
            fields["count"] = count
            fields["bits"] = bits
            return FUNCTION_NAME[fc], f"-> {what} " + "".join(map(str, bits))
        fields["values_raw"] = list(data)
        return FUNCTION_NAME[fc], f"-> {bc} bytes of {what}: {data.hex(' ').upper()}"
    if req is None or 2 * req[3] != bc:
        words = _words(raw, 3, data_end)
        if req is not None:
            warnings.append(
                f"read response with {len(words)} registers for a request of {req[3]}: "
                "registers unknown"
            )
        else:
            warnings.append(NO_REQUEST)
        fields["values_raw"] = words
        noun = "value" if len(words) == 1 else "values"
        return None, f"-> {len(words)} {noun} (registers unknown): " + ", ".join(map(str, words))
    p = plan(req[2], req[3])
    fields.update(p.extra)
    warnings.extend(p.warnings)
    if not req[4]:
        warnings.append(UNTRUSTED)
    values, texts, range_warnings = p.values(raw, 3, data_end)
    warnings += range_warnings
    fields["values"] = values
    return p.name, "-> " + texts


def _write_single(
    raw: bytes,
    direction: str | None,
    req: Pending | None,
    fields: dict[str, Any],
    warnings: list[str],
) -> tuple[str | None, str, bool]:
    fc = raw[1]
    addr, word = raw[2] << 8 | raw[3], raw[4] << 8 | raw[5]
    response = direction == RESPONSE
    if fc == WRITE_COIL:
        fields["coil"] = addr
        fields["value"] = word
        state = {0xFF00: "on", 0x0000: "off"}.get(word)
        if state is None:
            warnings.append(f"coil value 0x{word:04X} is neither 0xFF00 (on) nor 0x0000 (off)")
            state = f"0x{word:04X}"
        text = f"coil {addr} {state}"
        if response:
            return FUNCTION_NAME[fc], _echo(req, addr, word, text, warnings), False
        return FUNCTION_NAME[fc], f"write {text}", False
    p = plan(addr, 1)
    reg = p.regs[0]
    value, text, range_warn = _value(reg, word)
    fields["register"] = p.start
    fields["name"] = reg.name
    fields["value"] = value
    if p.short:
        fields["numbering"] = "short"
        fields["address"] = addr
    warnings.extend(p.warnings)
    if response:
        return reg.name, _echo(req, addr, word, text, warnings), False
    if range_warn is not None:
        warnings.append(range_warn)
    if p.read_only is not None:
        warnings.append(p.read_only)
    return reg.name, f"write {text}", reg.number in SAVE_REGISTERS and word == 1


def _echo(req: Pending | None, addr: int, word: int, text: str, warnings: list[str]) -> str:
    if req is None:
        warnings.append("write response without a known request")
        return f"-> echo {text}"
    if req[2] != addr or req[3] != word:
        warnings.append(
            f"the echo differs from the request (address {req[2]} value {req[3]}, "
            f"echo address {addr} value {word})"
        )
        return f"-> echo differs: {text}"
    return "-> ok (echo)"


def _write_multiple(
    raw: bytes, fc: int, fields: dict[str, Any], warnings: list[str]
) -> tuple[str | None, str, bool]:
    start, count, bc = raw[2] << 8 | raw[3], raw[4] << 8 | raw[5], raw[6]
    data_end = min(7 + bc, len(raw) - 2)
    fields["byte_count"] = bc
    if fc == WRITE_COILS:
        data = raw[7:data_end]
        bits = [(data[i >> 3] >> (i & 7)) & 1 for i in range(min(count, 8 * len(data)))]
        fields["start"] = start
        fields["count"] = count
        fields["bits"] = bits
        return (
            FUNCTION_NAME[fc],
            f"write {count} coils from {start}: " + "".join(map(str, bits)),
            False,
        )
    p = plan(start, count)
    fields.update(p.extra)
    warnings.extend(p.warnings)
    if not 1 <= count <= 123:
        warnings.append(f"count {count} outside the Modbus limit of 1-123 registers")
    values, texts, range_warnings = p.values(raw, 7, data_end)
    warnings += range_warnings
    if p.read_only is not None:
        warnings.append(p.read_only)
    save = False
    for name in p.save_names:
        if values.get(name) == 1:
            save = True
    fields["values"] = values
    noun = "register" if count == 1 else "registers"
    return p.name, f"write {count} {noun} from {p.start}: {texts}", save


def _write_multiple_response(
    fc: int,
    start: int,
    count: int,
    req: Pending | None,
    fields: dict[str, Any],
    warnings: list[str],
) -> tuple[str | None, str]:
    if req is None:
        warnings.append("write response without a known request")
    elif req[2] != start or req[3] != count:
        warnings.append(
            f"the response (start {start}, count {count}) does not match the request "
            f"(start {req[2]}, count {req[3]})"
        )
    if fc == WRITE_COILS:
        fields["start"] = start
        fields["count"] = count
        return FUNCTION_NAME[fc], f"-> wrote {count} coils from {start}"
    p = plan(start, count)
    fields.update(p.extra)
    warnings.extend(p.warnings)
    noun = "register" if count == 1 else "registers"
    return p.name, f"-> wrote {count} {noun} from {p.start}"


# -- the decoder ------------------------------------------------------------------------------


class ModbusRtuDecoder(ByteStreamDecoder):
    """Modbus RTU frames of one RS485 line, in stream order (feed Chunks, then finish)."""

    protocol = MODBUS_RTU
    max_frame = 9 + 255  # a write-multiple request with a full byte count

    def __init__(self, bus: str = "rs485") -> None:
        super().__init__(bus)
        self._pending: Pending | None = None
        self._memo: dict[tuple[bytes, Pending | None, str | None], Entry] = {}
        # (offset, length) of the last frame frame_at found valid with its CRC bytes swapped;
        # a frame's CRC state is a property of its bytes, so this never goes stale
        self._swapped: tuple[int, int] | None = None
        self._short_seen: set[int] = set()  # devices already said to use short numbers

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
        fc = buf[pos + 1]
        kind = KIND[fc]
        if kind in (_SINGLE, _EXC):  # one shape, either direction
            first = 8 if kind == _SINGLE else 5
            end = pos + first
            if end <= n:
                c = _crc(buf[pos : end - 2], 0xFFFF, _TABLE)
                got = buf[end - 2] | buf[end - 1] << 8
                if got == c:
                    return first
                if got == ((c >> 8) | (c & 0xFF) << 8):
                    self._swapped = (self._base + pos, first)  # for make_record
                    return first
            return self._decide(buf, pos, n, final, [first], False)
        if not kind:
            return 0
        hint = self.direction_hint
        if hint is None:
            p = self._pending
            resp_first = p is not None and p[0] == buf[pos]
        else:
            resp_first = hint == RESPONSE
        # the two candidates, preferred first, as candidates() orders them (inlined: this
        # runs once per frame); second == 0: none, -1: its length is not known yet
        if kind == _READ:
            if pos + 2 < n:
                bc = buf[pos + 2]
                other = 0 if bc == 0 or (fc >= READ_HOLDING and bc & 1) or bc == 3 else 5 + bc
            else:
                other = -1
            if resp_first and other:
                first, second = other, 8
            else:
                first, second = 8, other
        else:
            if pos + 6 < n:
                other = _write_request_len(fc, buf[pos + 4] << 8 | buf[pos + 5], buf[pos + 6])
            else:
                other = -1
            if resp_first or not other:
                first, second = 8, other
            else:
                first, second = other, 8
        # the common case: the expected shape checks, and no other reading is close enough
        # to it to collide (see _decide) or that reading fails its CRC; a known direction
        # settles the reading by itself
        end = pos + first
        if first > 0 and end <= n:
            c = _crc(buf[pos : end - 2], 0xFFFF, _TABLE)
            got = buf[end - 2] | buf[end - 1] << 8
            if got == c or got == ((c >> 8) | (c & 0xFF) << 8):
                d = second - first
                if second > 0 and hint is None and -CLOSE <= d <= CLOSE:
                    # a close reading: does it hold too? (then _decide settles it)
                    if d > 0 and got == c:
                        # exact shortcut: this frame's CRC residue is 0, so a reading d bytes
                        # longer holds exactly when the d bytes after it are 00
                        if end + d > n:
                            if not final:
                                return NEED_MORE
                        elif not buf[end] and (d == 1 or not buf[end + 1]):
                            return self._decide(buf, pos, n, final, [first, second], True)
                    elif pos + second > n:
                        if not final:
                            return NEED_MORE
                    elif crc_state(buf, pos, pos + second):
                        return self._decide(buf, pos, n, final, [first, second], True)
                if got != c:
                    self._swapped = (self._base + pos, first)  # for make_record
                return first
        cands = [first] if second == 0 else [first, second]
        return self._decide(buf, pos, n, final, cands, hint is None)

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
        best = -1
        for i, state in enumerate(states):
            if state is None:
                if not final:
                    return NEED_MORE  # a preferred reading is not complete yet
            elif state:
                best = i
                break
        if best >= 0:
            length = cands[best]
            contenders = [length]
            for c, state in zip(cands[best + 1 :], states[best + 1 :], strict=True):
                if rivals and (c < 0 or abs(c - length) <= CLOSE):
                    if state is None:
                        if not final:
                            return NEED_MORE
                    elif state:
                        contenders.append(c)
            if len(contenders) > 1:
                length = self._settle(buf, pos, n, final, contenders, cands[0])
                if length == NEED_MORE:
                    return NEED_MORE
            if states[cands.index(length)] == CRC_SWAPPED_ORDER:
                self._swapped = (self._base + pos, length)
            return length
        # every candidate failed its CRC, or the stream ended: the first candidate cut off by
        # the end makes a truncated frame (the base reports it on NEED_MORE when final); a bad
        # CRC makes a frame only where one plausibly ends
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
        if kind == _READ and length == 8:  # a read request
            count = buf[pos + 4] << 8 | buf[pos + 5]
            return int(1 <= count <= (125 if fc >= READ_HOLDING else 2000))
        if kind == _READ:  # a read response
            if not answers or p is None:
                return 1
            bc = buf[pos + 2]
            return int(bc == (2 * p[3] if fc >= READ_HOLDING else (p[3] + 7) >> 3))
        if kind == _MULTI and length == 8:  # a write-multiple response
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

    def make_record(self, raw: bytes, offset: int, t: float | None, valid: bool) -> Record:
        hint = self.direction_hint
        key = (raw, self._pending, hint)
        memo = self._memo
        e = memo.get(key)
        if e is None:
            if len(memo) >= MEMO_LIMIT:
                memo.clear()
            crc = None
            if valid:  # frame_at checked the CRC already
                swapped = self._swapped == (offset, len(raw))
                crc = CRC_SWAPPED_ORDER if swapped else CRC_OK
            e = memo[key] = decode(raw, self._pending, hint, crc)
        direction, name, fields, summary, errors, warnings, pair_key, expects, save, nxt = e
        self._pending = nxt
        if warnings and "numbering" in fields:
            warnings = self._short_numbering_once(raw[0], warnings)
        return Record(
            t,
            self.bus,
            MODBUS_RTU,
            FRAME,
            len(raw),
            raw,
            offset,
            None,
            direction,
            raw[0],
            raw[1],
            name,
            fields,
            list(errors) if errors else [],  # never shared: the lint stage appends
            list(warnings) if warnings else [],
            summary,
            -1,
            None,
            None,
            pair_key,
            expects,
            save,
        )

    def _short_numbering_once(self, slave: int, warnings: tuple[str, ...]) -> tuple[str, ...]:
        """A host that leaves out the 1000 offset does it on every frame: say so on its first
        frame per device; later frames keep ``numbering: "short"`` without the warning."""
        if slave not in self._short_seen:
            self._short_seen.add(slave)
            return tuple(
                w.replace("short register number", "this host uses short register number", 1)
                if w.startswith("short register number")
                else w
                for w in warnings
            )
        return tuple(w for w in warnings if not w.startswith("short register number"))

    def truncated_reason(self, raw: bytes) -> str:
        n = len(raw)
        text = f"truncated frame: the stream ended after {n} byte{'s' if n != 1 else ''}"
        kind = KIND[raw[1]] if n >= 2 else 0
        if not kind:
            return text
        func = FUNCTION_TEXT[raw[1] & 0x7F]
        what = f"exception response to {func}" if kind == _EXC else func
        lengths = sorted({c for c in candidates(raw, 0, n, kind, False) if c > n})
        if lengths:
            text = f"truncated frame: the stream ended after {n} of "
            text += " or ".join(map(str, lengths)) + " bytes"
        return f"{text} ({what})"
