"""The EG2-4X1 regular serial protocol (RS232), reference section 1.

Frame: ``EB 90 | ID | LEN | CMD | DATA (LEN-1) | SUM`` from the host, ``EE 16 ...`` from the
gripper; the whole frame is LEN + 5 bytes and SUM = (ID + LEN + CMD + DATA) & 0xFF. Values are
u16 little endian.

Built like a scapy/Wireshark dissector: ``COMMANDS`` is a table of messages keyed by CMD, each
with its manual name, a summary verb and its request and response layouts (lists of fields with
struct format, unit and documented range). The few payloads that a flat list cannot describe
(set ID by LEN, the run state, the undocumented 0x14 reply, the hand-compatible codes) have a
small decode function instead. A CMD in no table still decodes, as ``UNKNOWN_0xNN``. Every
error and warning is written with its flag code (``Notes``, ``decoders/flags.py``).

Speed: a live 115200-baud line carries under 2k frames/s, but a capture replay wants 300k/s.
Decoding is a pure function of the frame bytes and the same few dozen frames repeat all day, so
the decode is memoised by raw bytes; a hit costs one dict lookup plus building the Record. The
cached fields dict is shared by every Record of those bytes: later stages must not mutate it.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Callable
from dataclasses import dataclass
from dataclasses import fields as dataclass_fields
from enum import IntEnum
from functools import partial
from typing import Any, Final

from . import messages as M
from .framing import NEED_MORE, ByteStreamDecoder
from .model import EG2_SERIAL, FRAME, REQUEST, RESPONSE, Record
from .notes import Notes
from .registers import fault_text, opening_mm, state_text

__all__ = [
    "BROADCAST",
    "COMMANDS",
    "ID_RANGE",
    "REQUEST_HEADER",
    "RESPONSE_HEADER",
    "RUN_STATE",
    "STATUS_FAILED",
    "STATUS_OK",
    "Cmd",
    "Command",
    "Eg2SerialDecoder",
    "Field",
    "RunStateValue",
    "checksum",
]


class Cmd(IntEnum):
    """The CMD byte of the gripper's commands (the manual's names without ``CMD_MC_``); the
    one place the codes are written down (``COMMANDS`` below describes each). Frames are
    built by ``decoders.build.serial_frame``."""

    PARA_SAVE = 0x01
    PARA_ID_SET = 0x04
    MOVE_CATCH_XG = 0x10
    MOVE_RELEASE = 0x11
    SET_EG_PARA = 0x12
    READ_EG_PARA = 0x13
    READ_EG_STATE = 0x14
    MOVE_STOPHERE = 0x16
    ERROR_CLR = 0x17
    MOVE_CATCH2_XG = 0x18
    READ_EG_RUNSTATE = 0x41
    SET_DRVALL_SPEED = 0x51
    SET_DRVALL_YBP_THRESHOLD = 0x52
    SEEKPOS = 0x54
    READ_DRVALL_SPEED = 0xD2
    READ_DRVALL_YBP_THRESHOLD = 0xD3
    READ_DRVALL_SEEKGYHANGLE = 0xD7
    READ_ACTPOS = 0xD9
    READ_HAND_STATUS = 0xDC


REQUEST_HEADER: Final = b"\xeb\x90"  # host -> gripper
RESPONSE_HEADER: Final = b"\xee\x16"  # gripper -> host
BROADCAST: Final = 255  # every gripper executes it, none answers

_HEADER_PREFIXES: Final = (REQUEST_HEADER, RESPONSE_HEADER, b"\xeb", b"\xee")
# A header, or its first byte as the last byte held (the second may be on its way).
_HEADER_RE: Final = re.compile(rb"\xeb(?:\x90|\Z)|\xee(?:\x16|\Z)")

# The decode of one message body: (fields, summary); its errors and warnings go to the Notes
# passed in. The header-level parts (id, checksum, broadcast) are added by the caller.
Decoded = tuple[dict[str, Any], str]


def checksum(body: bytes | bytearray) -> int:
    """SUM over ID + LEN + CMD + DATA (everything between the header and SUM)."""
    return sum(body) & 0xFF


def _hex(data: bytes) -> str:
    return data.hex(" ").upper()


# Lookup tables for the decode's miss path (a moving gripper's replies rarely repeat).
_MM: Final = [opening_mm(v) for v in range(1001)]
_FAULT_WORDS: Final = [fault_text(b) for b in range(256)]  # shared lists: fields are read-only
_FAULT_SUMMARY: Final = [", ".join(words) or "no fault" for words in _FAULT_WORDS]
_MM_TEXT: Final = [str(mm) for mm in _MM]  # float formatting is the slow part of a summary
_STATE_TEXT: Final = [state_text(s) for s in range(256)]


def _mm(value: int) -> float:
    return _MM[value] if value <= 1000 else opening_mm(value)


def _mm_text(value: int) -> str:
    return _MM_TEXT[value] if value <= 1000 else str(opening_mm(value))


# -- the declarative part --------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Field:
    """One value in a payload. unit "mm" marks a 0-1000 opening, also shown in millimetres."""

    key: str  # name in Record.fields (vectors.json's names)
    fmt: str  # struct code, little endian: "B" u8, "H" u16
    label: str  # name in the summary line and in range warnings
    unit: str = ""
    lo: int | None = None  # documented range, None where the manual gives none
    hi: int | None = None


# A layout is a list of fields, or a function for a payload a flat list cannot describe.
CustomDecode = Callable[["Command", str, bytes, int, Notes], Decoded]
Layout = tuple[Field, ...] | CustomDecode


@dataclass(frozen=True, slots=True)
class Command:
    code: Cmd
    verb: str  # request summary ("catch", "read limits")
    request: Layout = ()
    response: Layout = ()  # () means the one status byte of a write/action command
    alias: str | None = None  # the hand's name for the same code (section 1.2)

    @property
    def name(self) -> str:
        """The manual's identifier (``CMD_MC_MOVE_CATCH_XG``)."""
        return "CMD_MC_" + self.code.name


SPEED = Field("speed", "H", "speed", "", 1, 1000)
FORCE = Field("force_g", "H", "force", "g", 50, 1000)
LIMIT_MAX = Field("max", "H", "max", "mm", 0, 1000)
LIMIT_MIN = Field("min", "H", "min", "mm", 0, 1000)
SEEK_POSITION = Field("position", "H", "position", "mm", 1, 1000)  # the 0x54 section: 1-1000
ACT_POSITION = Field("position", "H", "position", "mm", 0, 1000)


@dataclass(frozen=True, slots=True)
class RunStateValue:
    """One value of the 0x41 reply, in wire order: the one home of that layout (the tracker,
    the hex pane's spans and the native crate read it from here)."""

    key: str  # name in Record.fields
    fmt: str  # struct code, little endian: "B" u8, "H" u16
    state: str  # the device-state field it reports (analyzer/session/tracker.py)
    label: str  # name in range warnings
    lo: int | None = None  # documented range, None where the manual gives none
    hi: int | None = None


RUN_STATE: Final = (
    RunStateValue("state", "B", "state", "state", 1, 6),
    RunStateValue("fault", "B", "fault", "fault"),  # bits: a fault is warned of, not a range
    RunStateValue("temperature_c", "B", "temperature_c", "temperature"),
    RunStateValue("position", "H", "opening", "position", 0, 1000),
    RunStateValue("force_setting_g", "H", "force_setting", "force setting", 50, 1000),
)
_RUNSTATE = struct.Struct("<" + "".join(v.fmt for v in RUN_STATE))
ID_RANGE: Final = (1, 254)  # the IDs a gripper can be set to


def _words(n: int) -> str:
    return f"{n} data byte" + ("" if n == 1 else "s")


def _mismatch(cmd: Command, direction: str, expected: str, data: bytes, notes: Notes) -> Decoded:
    """A payload that does not fit the documented layout: show it raw, never guess."""
    fields: dict[str, Any] = {"data": _hex(data)}
    if cmd.alias is not None and len(data) >= 2:
        # the hand's form of this code carries a list of u16 (section 1.2)
        fields["values"] = _u16_list(data)[0]
    head = cmd.verb if direction == REQUEST else "->"
    notes.error_of(
        M.SERIAL_LAYOUT, name=cmd.name, direction=direction, expected=expected, length=len(data)
    )
    return fields, f"{head} unexpected data {_hex(data) or '(none)'}"


DecodeFn = Callable[[bytes, int, Notes], Decoded]


def _compile(cmd: Command, direction: str, layout: Layout) -> DecodeFn:
    """Turn a layout into a decode function (data, device, notes) -> Decoded.

    What does not depend on the values is worked out here, once (the struct, the summary
    labels, the ranges), so the decode of a reply that rarely repeats (a moving gripper's
    position) stays cheap.
    """
    if callable(layout):
        return partial(layout, cmd, direction)
    st = struct.Struct("<" + "".join(f.fmt for f in layout))
    expected = _words(st.size)
    head = cmd.verb if direction == REQUEST else "->"
    # per field: key, key of its millimetre twin or None, range (unbounded if none), label,
    # unit as a suffix
    plan = [
        (
            f.key,
            f.key + "_mm" if f.unit == "mm" else None,
            f.lo if f.lo is not None else -1,
            f.hi if f.hi is not None else 1 << 32,
            f.label,
            f" {f.unit}" if f.unit and f.unit != "mm" else "",
        )
        for f in layout
    ]

    def decode(data: bytes, device: int, notes: Notes) -> Decoded:
        if len(data) != st.size:
            return _mismatch(cmd, direction, expected, data, notes)
        fields: dict[str, Any] = {}
        parts = [head]
        for (key, mm_key, lo, hi, label, suffix), v in zip(plan, st.unpack(data), strict=False):
            fields[key] = v
            if mm_key is None:
                parts.append(f"{label}={v}{suffix}")
            else:
                fields[mm_key] = _mm(v)
                parts.append(f"{label}={v} ({_mm_text(v)} mm)")
            if not lo <= v <= hi:
                notes.warn_of(M.VALUE_OUT_OF_RANGE, label=label, lo=lo, hi=hi, value=v)
        return fields, " ".join(parts)

    return decode


# -- the payloads a field list cannot describe ---------------------------------------------


# the one status byte that answers a write or an action (section 1.1)
STATUS_OK: Final = 0x01
STATUS_FAILED: Final = 0x55  # "resend the command"


def _status(cmd: Command, direction: str, data: bytes, device: int, notes: Notes) -> Decoded:
    """The one status byte of a write/action response: 0x01 ok, 0x55 failure."""
    if len(data) != 1:
        return _mismatch(cmd, direction, "1 data byte (status)", data, notes)
    b = data[0]
    if b == STATUS_OK:
        return {"status": "ok"}, "-> ok"
    if b == STATUS_FAILED:
        notes.warn_of(M.SERIAL_WRITE_FAILED)
        return {"status": "failure"}, "-> FAILED (0x55)"
    # a status the manual does not list: not said to have failed, not said to be ok
    notes.warn_of(M.SERIAL_UNKNOWN_STATUS, status=b)
    return {"status": f"unknown 0x{b:02X}"}, f"-> unknown status 0x{b:02X}"


def _set_id(cmd: Command, direction: str, data: bytes, device: int, notes: Notes) -> Decoded:
    """New ID: one byte per the manual, a u16 LE in one client's code (section 4)."""
    if len(data) == 1:
        new_id, width = data[0], 1
    elif len(data) == 2:
        new_id, width = data[0] | data[1] << 8, 2
    else:
        return _mismatch(cmd, direction, "1 or 2 data bytes", data, notes)
    lo, hi = ID_RANGE
    if not lo <= new_id <= hi:
        notes.warn_of(M.VALUE_OUT_OF_RANGE, label="new_id", lo=lo, hi=hi, value=new_id)
    if device == BROADCAST:
        notes.warn_of(M.SERIAL_SET_ID_BROADCAST)
    summary = f"set ID {device} -> {new_id}" + (" (2-byte value)" if width == 2 else "")
    return {"new_id": new_id, "id_width": width}, summary


def _run_state(cmd: Command, direction: str, data: bytes, device: int, notes: Notes) -> Decoded:
    """0x41 reply: state u8, fault u8, temperature u8, position u16, force setting u16."""
    if len(data) != _RUNSTATE.size:
        return _mismatch(cmd, direction, _words(_RUNSTATE.size), data, notes)
    values = _RUNSTATE.unpack(data)
    state, fault, temp, pos, force = values
    text, mm = _STATE_TEXT[state], _mm(pos)
    fields = {
        "state": state,
        "state_text": text,
        "fault": fault,
        "fault_text": _FAULT_WORDS[fault],
        "temperature_c": temp,
        "position": pos,
        "position_mm": mm,
        "force_setting_g": force,
    }
    faults = _FAULT_SUMMARY[fault]
    summary = (
        f"-> state={state} {text}, {faults}, {temp} °C, "
        f"position={pos} ({_mm_text(pos)} mm), force setting={force} g"
    )
    for spec, value in zip(RUN_STATE, values, strict=True):
        if spec.key == "fault" and value:  # fault bits, not a range
            notes.warn_of(M.SERIAL_DEVICE_FAULT, faults=faults)
        elif spec.lo is not None and spec.hi is not None and not spec.lo <= value <= spec.hi:
            notes.warn_of(
                M.VALUE_OUT_OF_RANGE, label=spec.label, lo=spec.lo, hi=spec.hi, value=value
            )
    return fields, summary


def _eg_state(cmd: Command, direction: str, data: bytes, device: int, notes: Notes) -> Decoded:
    """0x14 reply: not documented. One client reads opening, force, threshold (section 4)."""
    fields: dict[str, Any] = {"data": _hex(data)}
    if len(data) != 6:
        return fields, f"-> {_words(len(data))} {_hex(data)} (layout not documented)"
    opening, force, threshold = struct.unpack("<HHH", data)
    fields["probable"] = {"opening": opening, "force": force, "force_threshold": threshold}
    summary = (
        f"-> {_hex(data)}, probable layout (unverified): "
        f"opening={opening} ({_mm_text(opening)} mm) force={force} force threshold={threshold}"
    )
    return fields, summary


def _u16_list(data: bytes) -> tuple[list[int], bytes]:
    even = len(data) & ~1
    return list(struct.unpack(f"<{even // 2}H", data[:even])), data[even:]


def _hand_values(cmd: Command, direction: str, data: bytes, device: int, notes: Notes) -> Decoded:
    """Hand-compatible codes: the gripper's payload lengths are unknown, so u16 values by LEN."""
    head = cmd.verb if direction == REQUEST else "->"
    if not data:
        return {}, head
    values, rest = _u16_list(data)
    fields: dict[str, Any] = {"values": values}
    summary = f"{head} values={','.join(map(str, values))}"
    if rest:
        fields["extra"] = _hex(rest)  # an odd byte left over
        summary += f" extra={fields['extra']}"
    return fields, summary


def _hand_write_reply(
    cmd: Command, direction: str, data: bytes, device: int, notes: Notes
) -> Decoded:
    """A hand-compatible write is answered like any write (one status byte), if it is short."""
    if len(data) == 1:
        return _status(cmd, direction, data, device, notes)
    return _hand_values(cmd, direction, data, device, notes)


def _hand(code: Cmd, verb: str, reply: CustomDecode | None = None) -> Command:
    """A code accepted for compatibility with the vendor's dexterous hand (section 1.2)."""
    return Command(code, f"{verb} (hand-compatible)", _hand_values, reply or _hand_values)


SEEK_ALIAS = "CMD_MC_SET_DRVALL_SEEKANGLE_GYH"
ACTPOS_ALIAS = "CMD_MC_READ_DRVALL_CURANGLE_GYH"

COMMANDS: Final[dict[int, Command]] = {
    c.code: c
    for c in (
        Command(Cmd.PARA_SAVE, "save parameters"),
        Command(Cmd.PARA_ID_SET, "set ID", _set_id),
        Command(Cmd.MOVE_CATCH_XG, "catch", (SPEED, FORCE)),
        Command(Cmd.MOVE_CATCH2_XG, "continuous catch", (SPEED, FORCE)),
        Command(Cmd.MOVE_RELEASE, "release", (SPEED,)),
        Command(Cmd.SEEKPOS, "seek", (SEEK_POSITION,), alias=SEEK_ALIAS),
        Command(Cmd.MOVE_STOPHERE, "stop"),
        Command(Cmd.SET_EG_PARA, "set limits", (LIMIT_MAX, LIMIT_MIN)),
        Command(Cmd.READ_EG_PARA, "read limits", (), (LIMIT_MAX, LIMIT_MIN)),
        Command(Cmd.READ_ACTPOS, "read position", (), (ACT_POSITION,), ACTPOS_ALIAS),
        Command(Cmd.READ_EG_STATE, "read state", (), _eg_state),
        Command(Cmd.READ_EG_RUNSTATE, "read run state", (), _run_state),
        Command(Cmd.ERROR_CLR, "clear faults"),
        _hand(Cmd.SET_DRVALL_SPEED, "set speed", _hand_write_reply),
        _hand(Cmd.SET_DRVALL_YBP_THRESHOLD, "set force threshold", _hand_write_reply),
        _hand(Cmd.READ_DRVALL_SEEKGYHANGLE, "read target position"),
        _hand(Cmd.READ_DRVALL_SPEED, "read speed"),
        _hand(Cmd.READ_DRVALL_YBP_THRESHOLD, "read force threshold"),
        _hand(Cmd.READ_HAND_STATUS, "read hand status"),
    )
}


def _response_layout(cmd: Command) -> Layout:
    # an empty response layout means the usual one status byte of a write/action
    return cmd.response if cmd.response != () else _status


# (direction, CMD) -> (name, hand alias, decode function), compiled once
_DISPATCH: Final[dict[tuple[str, int], tuple[str, str | None, DecodeFn]]] = {}
for _cmd in COMMANDS.values():
    _DISPATCH[REQUEST, _cmd.code] = (_cmd.name, _cmd.alias, _compile(_cmd, REQUEST, _cmd.request))
    _DISPATCH[RESPONSE, _cmd.code] = (
        _cmd.name,
        _cmd.alias,
        _compile(_cmd, RESPONSE, _response_layout(_cmd)),
    )


def _unknown(code: int, data: bytes, notes: Notes) -> Decoded:
    """A CMD in neither table: still a frame when SUM checks; show its bytes (section 1.2)."""
    summary = f"unknown command 0x{code:02X}" + (f": {_hex(data)}" if data else "")
    notes.warn_of(M.SERIAL_UNKNOWN_COMMAND, code=code)
    return {"data": _hex(data)}, summary


# -- the decode of one frame, memoised --------------------------------------------------------

# (direction, device, code, name, fields, summary, errors, warnings, pair_key, expects, is_save,
#  flags)
_Entry = tuple[
    str | None,
    int | None,
    int | None,
    str | None,
    dict[str, Any],
    str,
    tuple[str, ...],
    tuple[str, ...],
    tuple[Any, ...] | None,
    bool,
    bool,
    tuple[str, ...],
]

_CACHE: dict[bytes, _Entry] = {}
_CACHE_MAX: Final = 50_000  # cleared when full: a live bus repeats few frames, memory stays flat


def _decode(raw: bytes) -> _Entry:
    """Everything about a frame that depends only on its bytes."""
    if len(raw) < 6 or raw[3] + 5 != len(raw) or raw[:2] not in (REQUEST_HEADER, RESPONSE_HEADER):
        return _malformed(raw)  # the framer only hands over well-framed bytes
    direction = REQUEST if raw[0] == 0xEB else RESPONSE
    device, code, data = raw[2], raw[4], raw[5:-1]
    notes = Notes()
    _note_header(raw, direction, notes)  # the header's problems come first
    entry = _DISPATCH.get((direction, code))
    if entry is None:
        name, alias = f"UNKNOWN_0x{code:02X}", None
        body, summary = _unknown(code, data, notes)
    else:
        name, alias, decode = entry
        body, summary = decode(data, device, notes)
    fields: dict[str, Any] = {"id": device, **body}
    if alias is not None:
        fields["alias"] = alias
    return (
        direction,
        device,
        code,
        name,
        fields,
        summary,
        tuple(notes.errors),
        tuple(notes.warnings),
        (device, code),
        direction == REQUEST and device != BROADCAST,
        direction == REQUEST and code == Cmd.PARA_SAVE,
        tuple(notes.flags),
    )


def _malformed(raw: bytes) -> _Entry:
    """The entry of bytes that do not fit a header and its length byte (direct callers)."""
    error = M.SERIAL_FRAME_SHAPE.text(length=len(raw))
    return (
        None,
        None,
        None,
        None,
        {"data": _hex(raw)},
        "malformed frame",
        (error,),
        (),
        None,
        False,
        False,
        (M.SERIAL_FRAME_SHAPE.code,),
    )


def _note_header(raw: bytes, direction: str, notes: Notes) -> None:
    """The header's problems: a checksum that fails, an invalid or broadcast ID."""
    device = raw[2]
    expected, got = sum(raw[2:-1]) & 0xFF, raw[-1]
    if expected != got:
        notes.error_of(M.SERIAL_CHECKSUM, expected=expected, got=got)
    if device == 0:
        notes.warn_of(M.SERIAL_ID_ZERO)
    elif device == BROADCAST and direction == RESPONSE:
        notes.warn_of(M.SERIAL_BROADCAST_RESPONSE)


# Records are built positionally: keyword construction of the 22-field dataclass costs 2.5x as
# much, and it is the largest single cost per frame. Fail loudly if model.Record changes order.
_RECORD_ORDER: Final = (
    "t",
    "bus",
    "protocol",
    "kind",
    "length",
    "raw",
    "offset",
    "index",
    "direction",
    "device",
    "code",
    "name",
    "fields",
    "errors",
    "warnings",
    "summary",
    "seq",
    "pair",
    "latency_ms",
    "pair_key",
    "expects_response",
    "is_save",
    "flags",
)
if tuple(f.name for f in dataclass_fields(Record)) != _RECORD_ORDER:
    raise RuntimeError("decoders.model.Record changed its field order; update eg2_serial.py")


def _short_candidate(buf: bytearray, pos: int) -> int:
    """frame_at for fewer than 4 bytes: 0 as soon as the header is wrong, else wait."""
    return NEED_MORE if bytes(buf[pos : pos + 2]) in _HEADER_PREFIXES else 0


class Eg2SerialDecoder(ByteStreamDecoder):
    """Feed Chunks of an RS232 tap (either or both directions interleaved), get Records."""

    protocol = EG2_SERIAL

    def __init__(self, bus: str = "serial", *, byte_time_s: float | None = None) -> None:
        super().__init__(bus, byte_time_s=byte_time_s)

    def frame_at(self, buf: bytearray, pos: int, final: bool) -> int:
        try:
            b0, b1, size = buf[pos], buf[pos + 1], buf[pos + 3] + 5
        except IndexError:  # fewer than 4 bytes: the length is not known yet
            return _short_candidate(buf, pos)
        if not ((b0 == 0xEB and b1 == 0x90) or (b0 == 0xEE and b1 == 0x16)):
            return 0
        if size == 5:  # LEN 0: no CMD, not a frame
            return 0
        end = pos + size - 1  # index of SUM
        if end >= len(buf):
            return NEED_MORE
        if sum(buf[pos + 2 : end]) & 0xFF == buf[end]:
            return size
        return -size

    def next_start(self, buf: bytearray, pos: int) -> int:
        # fast path: back-to-back frames start right here
        if pos + 1 < len(buf):
            b0 = buf[pos]
            if (b0 == 0xEB and buf[pos + 1] == 0x90) or (b0 == 0xEE and buf[pos + 1] == 0x16):
                return pos
        m = _HEADER_RE.search(buf, pos)
        return m.start() if m is not None else len(buf)

    def make_record(self, raw: bytes, offset: int, t: float | None, valid: bool) -> Record:
        # valid is implied by raw (the checksum is part of it), so the cache key is raw alone
        entry = _CACHE.get(raw)
        if entry is None:
            if len(_CACHE) >= _CACHE_MAX:
                _CACHE.clear()
            entry = _CACHE[raw] = _decode(raw)
        (
            direction,
            device,
            code,
            name,
            fields,
            summary,
            errors,
            warnings,
            key,
            expects,
            save,
            flags,
        ) = entry
        # fresh error/warning/flag lists: the pairing and lint stages append to them; fields
        # is shared between records of equal bytes and must be treated as read-only
        return Record(
            t,
            self.bus,
            EG2_SERIAL,
            FRAME,
            len(raw),
            raw,
            offset,
            None,
            direction,
            device,
            code,
            name,
            fields,
            list(errors),
            list(warnings),
            summary,
            -1,
            None,
            None,
            key,
            expects,
            save,
            list(flags),
        )

    def truncated_reason(self, raw: bytes) -> str:
        if len(raw) < 4:
            return M.SERIAL_TRUNCATED_HEADER.text(length=len(raw))
        return M.SERIAL_TRUNCATED_BODY.text(len_byte=raw[3], needed=raw[3] + 5, length=len(raw))
