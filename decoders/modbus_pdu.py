"""Modbus RTU PDUs: what a frame of the EG2-4X2's RS485 line means (reference section 2).

Direction. The bus is half duplex: requests and responses alternate. The shape decides for
reads (8 bytes: request; 5 + 2N: response), write multiple (9 + 2N: request; 8: response) and
exceptions; a write single (request and response identical) is the response of the pending
request it echoes, else a request. A direction the source knows (``hint``) wins where the shape
cannot decide.

Registers are named by ``modbus_registers``. A read response is named from its pending request;
one without a known request shows its values by index.

Every error and warning carries its flag code (``decoders/flags.py``).
"""

from __future__ import annotations

from typing import Any, Final

from . import flags as F
from . import messages as M
from .modbus_framing import (
    CRC_BAD,
    CRC_OK,
    CRC_SWAPPED_ORDER,
    FUNCTION_TEXT,
    KIND,
    KIND_EXCEPTION,
    KIND_MULTI,
    KIND_READ,
    KIND_SINGLE,
    READ_COILS,
    READ_DISCRETE,
    READ_HOLDING,
    WRITE_COIL,
    WRITE_COILS,
    WRITE_MULTIPLE,
    WRITE_SINGLE,
    Pending,
    candidates,
    crc16,
    crc_state,
    read_response_len,
)
from .modbus_registers import plan, value_of, words
from .model import REQUEST, RESPONSE
from .notes import Notes
from .registers import SAVE_REGISTERS

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

BROADCAST: Final = 0

# -- one frame's meaning ---------------------------------------------------------------------

# what make_record memoises: direction, name, fields, summary, errors, warnings, pair_key,
# expects_response, is_save, the pending request after this frame, and the flag codes
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
    tuple[str, ...],
]
_RANGE_FLAG: Final = (M.VALUE_OUT_OF_RANGE.code,)


def _direction(raw: bytes, pending: Pending | None, hint: str | None) -> str | None:
    """request or response, from the shape where it decides, else from the hint or the bus."""
    n = len(raw)
    fc = raw[1]
    kind = KIND[fc]
    if kind == KIND_EXCEPTION:
        return RESPONSE
    if kind == KIND_READ:
        is_req = n == 8
        is_resp = read_response_len(fc, raw[2]) == n
        if is_req != is_resp:
            return REQUEST if is_req else RESPONSE
    elif kind == KIND_MULTI:
        return RESPONSE if n == 8 else REQUEST
    elif kind != KIND_SINGLE:
        return None
    # the same bytes either way (a write single, or a coil read of 3 bytes)
    if hint is not None:
        return hint
    if (
        pending is not None
        and pending[0] == raw[0]
        and pending[1] == fc
        and (kind != KIND_SINGLE or pending[2] == (raw[2] << 8 | raw[3]))
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
            warnings, flags = p.warnings, p.flags
            if range_warnings:
                warnings = warnings + tuple(range_warnings)
                flags = flags + _RANGE_FLAG
            return (
                RESPONSE,
                p.name,
                fields,
                "-> " + texts,
                (),
                warnings,
                (slave, READ_HOLDING),
                False,
                False,
                None,
                flags,
            )
    return _decode(raw, pending, hint, crc)


def _shapeless(raw: bytes) -> Entry | None:
    """The entry of bytes no framer would hand over (decode() is public), else None."""
    n = len(raw)
    if n < 4:
        fields: dict[str, Any] = {"slave": raw[0] if raw else None}
        error = M.MODBUS_TOO_SHORT.text(length=n)
    else:
        kind = KIND[raw[1]]
        if kind and n in candidates(raw, 0, n, kind, False):
            return None
        what = FUNCTION_TEXT.get(raw[1] & 0x7F, f"function 0x{raw[1]:02X}") if kind else ""
        fields = {"slave": raw[0], "function": raw[1] & 0x7F}
        error = M.MODBUS_NO_SHAPE.text(length=n, what=what or f"code 0x{raw[1]:02X}")
    return (None, None, fields, "", (error,), (), None, False, False, None, (F.MALFORMED,))


def _decode(raw: bytes, pending: Pending | None, hint: str | None, crc: int | None) -> Entry:
    shapeless = _shapeless(raw)
    if shapeless is not None:
        return shapeless
    notes = Notes()
    slave, fc = raw[0], raw[1]
    func = fc & 0x7F
    kind = KIND[fc]
    if crc is None:
        crc = crc_state(raw, 0, len(raw))
    _note_crc(raw, crc, notes)
    direction = _direction(raw, pending, hint)
    _note_unexpected(raw, kind, direction, notes)
    # a response is checked against the request it answers
    answers = pending is not None and pending[0] == slave and pending[1] == func
    req = pending if direction == RESPONSE and answers else None
    fields: dict[str, Any] = {"slave": slave, "function": func}
    name, summary, is_save = _body(raw, kind, direction, req, fields, notes)
    pair_key, expects, nxt = _pairing(raw, direction, crc)
    return (
        direction,
        name,
        fields,
        summary,
        tuple(notes.errors),
        tuple(notes.warnings),
        pair_key,
        expects,
        is_save and direction == REQUEST,
        nxt,
        tuple(notes.flags),
    )


def _note_crc(raw: bytes, crc: int, notes: Notes) -> None:
    """A CRC that fails, or holds with its two bytes swapped, is noted."""
    if crc == CRC_SWAPPED_ORDER:
        notes.warn_of(M.MODBUS_CRC_SWAPPED)
    elif crc == CRC_BAD:
        c = crc16(raw[:-2])
        notes.error_of(
            M.MODBUS_CRC, expected_lo=c & 0xFF, expected_hi=c >> 8, got_lo=raw[-2], got_hi=raw[-1]
        )


def _note_unexpected(raw: bytes, kind: int, direction: str | None, notes: Notes) -> None:
    """A function the EG2 does not document, or a response from the broadcast address."""
    slave, fc = raw[0], raw[1]
    if kind != KIND_EXCEPTION and fc not in EG2_FUNCTIONS:
        notes.warn_of(M.MODBUS_UNDOCUMENTED_FUNCTION, code=fc, name=FUNCTION_TEXT[fc])
    if direction == RESPONSE and slave == BROADCAST:
        notes.warn_of(M.MODBUS_BROADCAST_RESPONSE)


def _pairing(
    raw: bytes, direction: str | None, crc: int
) -> tuple[tuple[int, int] | None, bool, Pending | None]:
    """(pair key, expects a response, the request now pending) of a frame."""
    slave, fc = raw[0], raw[1]
    if direction != REQUEST:
        return ((slave, fc & 0x7F) if direction == RESPONSE else None), False, None
    if slave == BROADCAST:
        return (slave, fc), False, None
    return (
        (slave, fc),
        True,
        (slave, fc, raw[2] << 8 | raw[3], raw[4] << 8 | raw[5], crc != CRC_BAD),
    )


def _body(
    raw: bytes,
    kind: int,
    direction: str | None,
    req: Pending | None,
    fields: dict[str, Any],
    notes: Notes,
) -> tuple[str | None, str, bool]:
    """Name, summary and is_save of a well-shaped frame; its values go into fields."""
    fc = raw[1]
    if kind == KIND_EXCEPTION:
        return _exception(raw, fields, notes)
    if kind == KIND_READ and direction == REQUEST:
        start, count = raw[2] << 8 | raw[3], raw[4] << 8 | raw[5]
        return (*_read_request(fc, start, count, fields, notes), False)
    if kind == KIND_READ:
        return (*_read_response(raw, fc, req, fields, notes), False)
    if kind == KIND_SINGLE:
        return _write_single(raw, direction, req, fields, notes)
    if direction == REQUEST:
        return _write_multiple(raw, fc, fields, notes)
    start, count = raw[2] << 8 | raw[3], raw[4] << 8 | raw[5]
    return (*_write_multiple_response(fc, start, count, req, fields, notes), False)


def _exception(raw: bytes, fields: dict[str, Any], notes: Notes) -> tuple[str, str, bool]:
    code = raw[2]
    text = EXCEPTION_TEXT.get(code, "")
    notes.flag(F.EXCEPTION_RESPONSE)  # the summary says it in words
    if not text:
        text = f"unknown exception code {code}"
        notes.warn_of(M.MODBUS_UNKNOWN_EXCEPTION, code=code)
    fields["exception_code"] = code
    fields["exception_text"] = text
    return "EXCEPTION", f"exception {code}: {text}", False


def _read_request(
    fc: int, start: int, count: int, fields: dict[str, Any], notes: Notes
) -> tuple[str | None, str]:
    if fc <= READ_DISCRETE:  # coils and discrete inputs: bits, not EG2 registers
        what = "coils" if fc == READ_COILS else "discrete inputs"
        fields["start"] = start
        fields["count"] = count
        if not 1 <= count <= 2000:
            notes.warn_of(M.MODBUS_COUNT, count=count, limit=2000, what=what)
        return FUNCTION_NAME[fc], f"read {count} {what} from {start}"
    p = plan(start, count)
    fields.update(p.extra)
    fields["registers"] = list(p.names)
    p.note(notes)
    if not 1 <= count <= 125:
        notes.warn_of(M.MODBUS_COUNT, count=count, limit=125, what="registers")
    noun = "register" if count == 1 else "registers"
    keys = f" ({p.summary_keys})" if p.summary_keys else ""
    return p.name, f"read {count} {noun} from {p.start}{keys}"


def _read_response(
    raw: bytes, fc: int, req: Pending | None, fields: dict[str, Any], notes: Notes
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
        values_raw = words(raw, 3, data_end)
        n = len(values_raw)
        if req is not None:
            notes.warn_of(M.MODBUS_READ_LENGTH, count=n, asked=req[3])
        else:
            notes.warn_of(M.MODBUS_NO_REQUEST)
        fields["values_raw"] = values_raw
        noun = "value" if n == 1 else "values"
        return None, f"-> {n} {noun} (registers unknown): " + ", ".join(map(str, values_raw))
    p = plan(req[2], req[3])
    fields.update(p.extra)
    p.note(notes)
    if not req[4]:
        notes.warn_of(M.MODBUS_UNTRUSTED)
    values, texts, range_warnings = p.values(raw, 3, data_end)
    for text in range_warnings:
        notes.warn(M.VALUE_OUT_OF_RANGE.code, text)
    fields["values"] = values
    return p.name, "-> " + texts


def _write_single(
    raw: bytes,
    direction: str | None,
    req: Pending | None,
    fields: dict[str, Any],
    notes: Notes,
) -> tuple[str | None, str, bool]:
    fc = raw[1]
    addr, word = raw[2] << 8 | raw[3], raw[4] << 8 | raw[5]
    response = direction == RESPONSE
    if fc == WRITE_COIL:
        fields["coil"] = addr
        fields["value"] = word
        state = {0xFF00: "on", 0x0000: "off"}.get(word)
        if state is None:
            notes.warn_of(M.MODBUS_COIL_VALUE, value=word)
            state = f"0x{word:04X}"
        text = f"coil {addr} {state}"
        if response:
            return FUNCTION_NAME[fc], _echo(req, addr, word, text, notes), False
        return FUNCTION_NAME[fc], f"write {text}", False
    p = plan(addr, 1)
    reg = p.regs[0]
    value, text, range_warn = value_of(reg, word)
    fields["register"] = p.start
    fields["name"] = reg.name
    fields["value"] = value
    if p.short:
        fields["numbering"] = "short"
        fields["address"] = addr
    p.note(notes)
    if response:
        return reg.name, _echo(req, addr, word, text, notes), False
    if range_warn is not None:
        notes.warn(M.VALUE_OUT_OF_RANGE.code, range_warn)
    if p.read_only is not None:
        notes.warn(M.MODBUS_READ_ONLY_WRITE.code, p.read_only)
    return reg.name, f"write {text}", reg.number in SAVE_REGISTERS and word == 1


def _echo(req: Pending | None, addr: int, word: int, text: str, notes: Notes) -> str:
    if req is None:
        notes.warn_of(M.MODBUS_WRITE_NO_REQUEST)
        return f"-> echo {text}"
    if req[2] != addr or req[3] != word:
        notes.warn_of(
            M.MODBUS_ECHO_DIFFERS,
            address=req[2],
            value=req[3],
            echo_address=addr,
            echo_value=word,
        )
        return f"-> echo differs: {text}"
    return "-> ok (echo)"


def _write_multiple(
    raw: bytes, fc: int, fields: dict[str, Any], notes: Notes
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
    p.note(notes)
    if not 1 <= count <= 123:
        notes.warn_of(M.MODBUS_COUNT, count=count, limit=123, what="registers")
    values, texts, range_warnings = p.values(raw, 7, data_end)
    for text in range_warnings:
        notes.warn(M.VALUE_OUT_OF_RANGE.code, text)
    if p.read_only is not None:
        notes.warn(M.MODBUS_READ_ONLY_WRITE.code, p.read_only)
    save = any(values.get(name) == 1 for name in p.save_names)
    fields["values"] = values
    noun = "register" if count == 1 else "registers"
    return p.name, f"write {count} {noun} from {p.start}: {texts}", save


def _write_multiple_response(
    fc: int,
    start: int,
    count: int,
    req: Pending | None,
    fields: dict[str, Any],
    notes: Notes,
) -> tuple[str | None, str]:
    if req is None:
        notes.warn_of(M.MODBUS_WRITE_NO_REQUEST)
    elif req[2] != start or req[3] != count:
        notes.warn_of(
            M.MODBUS_WRITE_DIFFERS,
            start=start,
            count=count,
            asked_start=req[2],
            asked_count=req[3],
        )
    if fc == WRITE_COILS:
        fields["start"] = start
        fields["count"] = count
        return FUNCTION_NAME[fc], f"-> wrote {count} coils from {start}"
    p = plan(start, count)
    fields.update(p.extra)
    p.note(notes)
    noun = "register" if count == 1 else "registers"
    return p.name, f"-> wrote {count} {noun} from {p.start}"
