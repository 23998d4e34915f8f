"""The EG2-4X0 CAN register protocol (reference section 3): CanFrame -> Record.

The 29-bit identifier packs ``reserved(1) | operation(2) | start address(12) | device(14)``.
Operation 0 reads N bytes of registers, 1 writes them, 2 and 3 ("finger positioning move",
"finger servo follow") are named by the manual with no payload layout and are shown raw. The
reserved bit 28 is 0 on every EG2 frame: a frame with it set is other traffic sharing the bus
(J1939 identifiers such as ``18FF50E5`` set it), never an EG2 device.

Requests and responses share one identifier and CAN frames carry no sender, so direction comes
from the frame's shape and from a table of pending requests per identifier:

- read request: DLC 1 with data[0] = N (1-8), or DLC 8 with the other 7 bytes zero;
  read response: DLC N, the register bytes, low byte first;
- write request: DLC N, the register bytes; write response: DLC 1 (or 8, zero padded) with
  data[0] = N.

A frame that fits both shapes (a DLC-1 write, a zero-padded 8-byte read) is a response when a
request of the matching length is pending on its identifier, else a request (and says what else
it could be). A response with nothing pending is decoded as a response when only the response
shape fits; the pairing stage flags it as unmatched. A host that times out and sends the same
request again before the answer counts as two pending requests, so both answers (when the
gripper sends two) are taken as responses. Broadcast requests (device 16383) are never pending,
and a pending request older than ``PENDING_TIMEOUT_S`` is forgotten when frames carry times.
``_Directions`` holds these rules.

N bytes from address A cover the registers at A, A+2, ... (little endian, signed where the
register is). An odd address or length is legal on the wire: it is flagged and the byte that
covers half a register is shown raw (``fields["partial"]``), read as CAN addresses counting
bytes (an odd address is the high byte of the register below it; inference).

Everything else on the bus (11-bit identifiers, reserved bit 28 set, remote, error and CAN FD
frames) is shown as a foreign ``can`` record (flag ``foreign``); nothing here raises. Every
warning and error carries its code in ``Record.flags`` (``decoders/flags.py``).

Speed: the decoded part of a record is built once per distinct frame. Frames without register
values (read requests, write responses) are memoised by (identifier, data, direction); frames
with values (read responses, write requests) keep the last frame per identifier, so an idle
gripper's answers cost a dict look-up, and a changing one reuses a per-identifier layout and a
per-register value cache. ``fields`` may be shared between records; ``errors``, ``warnings``
and ``flags`` are copied per record (later stages append to them).
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Any, Final

from . import flags as F
from . import messages as M
from .can_errors import error_class_words
from .model import EG2_CAN, FOREIGN_CAN, FRAME, REQUEST, RESPONSE, CanFrame, Record
from .notes import Notes
from .registers import (
    SAVE_REGISTERS,
    Register,
    by_can_address,
    fault_text,
    state_text,
)

OPERATIONS: Final = ("read", "write", "positioning move", "servo follow")
OP_READ: Final = 0
OP_WRITE: Final = 1
OP_POSITIONING_MOVE: Final = 2
OP_SERVO_FOLLOW: Final = 3

BROADCAST: Final = 0x3FFF  # device 16383
RESERVED_BIT: Final = 1 << 28  # 0 on every EG2 frame
MAX_ID: Final = 0x1FFFFFFF
MAP_FIRST, MAP_LAST = 1002, 1130  # CAN byte addresses of registers 1001 ... 1065

# A pending request older than this is forgotten (the slowest answer, to a save, takes about
# 850 ms; clients time out after 20-30 ms). Only applies when both frames carry a time.
PENDING_TIMEOUT_S: Final = 2.0
MEMO_LIMIT: Final = 50_000
PENDING_LIMIT: Final = 50_000

_ZERO7: Final = bytes(7)

# direction tags (part of the memo key)
_TAG_REQUEST: Final = 0
_TAG_RESPONSE: Final = 1
_TAG_NONE: Final = 2
# a response whose length does not match the pending request: _TAG_MISMATCH + expected length
_TAG_MISMATCH: Final = 16


def unpack_id(arbitration_id: int) -> tuple[int, int, int]:
    """(operation, start address, device) of an EG2 identifier (``build.can_id`` packs one)."""
    return (
        (arbitration_id >> 26) & 3,
        (arbitration_id >> 14) & 0xFFF,
        arbitration_id & 0x3FFF,
    )


def can_error_text(error_class: int) -> str:
    """An error frame's identifier (SocketCAN error class bits) in words."""
    words = error_class_words(error_class)
    if not words:
        return M.CAN_ERROR_FRAME.text()
    return M.CAN_ERROR_FRAME_CLASSES.text(classes=", ".join(words), error_class=error_class)


def _count_shaped(data: bytes) -> bool:
    """A read request's or write response's shape: one count byte 1-8, or 8 bytes zero padded."""
    n = len(data)
    return (n == 1 or (n == 8 and data.endswith(_ZERO7))) and 1 <= data[0] <= 8


# A pending request on one identifier: (length asked for or written, its data, its time,
# unanswered copies (a host's retransmissions), whether a copy has been answered)
_Pending = tuple[int, bytes, float | None, int, bool]


class _Directions:
    """Which way an EG2 read or write frame goes: its shape, then the request pending on its
    identifier (see the module docstring). Broadcasts are never pending."""

    __slots__ = ("_pending",)

    def __init__(self) -> None:
        self._pending: dict[int, _Pending] = {}  # arbitration id -> its pending request

    def __len__(self) -> int:
        return len(self._pending)

    def reset(self) -> None:
        self._pending.clear()

    def tag(self, aid: int, op: int, data: bytes, t: float | None) -> int:
        """The direction tag of a read (op 0) or write (op 1) frame, from its shape and the
        request pending on its identifier; `_note` keeps the pending table."""
        pend = self._pending.get(aid)
        if (
            pend is not None
            and t is not None
            and pend[2] is not None
            and t - pend[2] > PENDING_TIMEOUT_S
        ):
            pend = None  # too old to be answered
        n = len(data)
        # _count_shaped(data), inline: this runs for every frame
        count_shaped = (n == 1 or (n == 8 and data.endswith(_ZERO7))) and 1 <= data[0] <= 8
        if op == OP_READ:
            if pend is not None and pend[0] == n:
                tag = _TAG_RESPONSE
            elif count_shaped:
                tag = _TAG_REQUEST
                n = data[0]
            elif not n:
                return _TAG_NONE
            elif pend is None:
                return _TAG_RESPONSE  # nothing pending: the pairing stage says so
            else:
                tag = _TAG_MISMATCH + pend[0]
        elif pend is not None and count_shaped and data[0] == pend[0]:
            tag = _TAG_RESPONSE
        elif n:
            tag = _TAG_REQUEST
        else:
            return _TAG_NONE
        self._note(aid, tag, n, data, t, pend)
        return tag

    def _note(
        self, aid: int, tag: int, n: int, data: bytes, t: float | None, pend: _Pending | None
    ) -> None:
        """A request joins the pending table (nobody answers a broadcast); an answer takes
        one waiting copy off it."""
        pending = self._pending
        if tag == _TAG_REQUEST:
            if aid & 0x3FFF != BROADCAST:
                if pend is not None and pend[1] == data and not pend[4]:
                    # the same request again before any answer: a retransmission, one more due
                    pending[aid] = (n, data, t, pend[3] + 1, False)
                else:
                    if len(pending) >= PENDING_LIMIT:
                        pending.clear()
                    pending[aid] = (n, data, t, 1, False)
        elif pend is not None:  # an answer: one copy fewer is waiting
            if pend[3] > 1:
                pending[aid] = (pend[0], pend[1], pend[2], pend[3] - 1, True)
            else:
                del pending[aid]


def _register_at(address: int) -> Register:
    """The register at an even CAN address; a flagged placeholder outside the manual's map."""
    reg = by_can_address(address)
    if reg is not None:
        return reg
    number = 1000 + (address - 1000) // 2
    return Register(
        number,
        f"ADDR_{address}",
        f"addr_{address}",
        "?",
        None,
        None,
        documented=False,
        meaning=f"CAN address {address}, outside the register map",
    )


def _plural(n: int) -> str:
    return "1 byte" if n == 1 else f"{n} bytes"


def _hex(data: bytes) -> str:
    return data.hex(" ").upper()


def _span_registers(address: int, n: int) -> list[Register]:
    """Every register that a span of n bytes from address touches, in order."""
    first = address & ~1
    last = (address + n - 1) & ~1
    return [_register_at(a) for a in range(first, last + 1, 2)] if n > 0 else []


def _span_name(regs: list[Register]) -> str | None:
    if not regs:
        return None
    if len(regs) == 1:
        return regs[0].name
    return f"{regs[0].name}..{regs[-1].name}"


def _span_keys(regs: list[Register]) -> str:
    if len(regs) == 1:
        return regs[0].key
    return f"{regs[0].key}..{regs[-1].key}"


def _span_warnings(address: int, n: int, regs: list[Register], write: bool, notes: Notes) -> None:
    """Flag how a span is laid out: odd address or length, unknown or read-only registers."""
    if address & 1:
        reg = _register_at(address - 1)
        notes.warn_of(
            M.CAN_ODD_START, address=address, register=reg.name, register_address=address - 1
        )
    if (address + n) & 1 and n > 0:
        reg = _register_at(address + n - 1)
        notes.warn_of(
            M.CAN_ODD_END,
            bytes=_plural(n),
            address=address,
            register=reg.name,
            register_address=address + n - 1,
        )
    elif n & 1:
        notes.warn_of(M.CAN_ODD_LENGTH, length=n)
    for reg in regs:
        if not reg.documented:
            if MAP_FIRST <= reg.can_address <= MAP_LAST:
                notes.warn_of(
                    M.CAN_UNDOCUMENTED_ADDRESS, address=reg.can_address, number=reg.number
                )
            else:
                notes.warn_of(
                    M.CAN_OUTSIDE_MAP, address=reg.can_address, first=MAP_FIRST, last=MAP_LAST
                )
        elif write and reg.access == "ro":
            notes.warn_of(M.CAN_READ_ONLY_WRITE, name=reg.name, key=reg.key)


# (protocol, direction, device, code, name, fields, errors, warnings, summary, pair_key,
#  expects_response, is_save, flags)
_Template = tuple[
    str,
    str | None,
    int | None,
    int | None,
    str | None,
    dict[str, Any],
    list[str],
    list[str],
    str,
    tuple[Any, ...] | None,
    bool,
    bool,
    list[str],
]


# one register value, decoded once per (register, raw value): (value, summary text, special);
# special is None for the usual value, else (range warning, extra field such as state_text,
# whether it triggers a save)
_Special = tuple[str | None, tuple[str, Any] | None, bool]
_ValueEntry = tuple[int, str, _Special | None]
_VALUE_CACHE_LIMIT: Final = 4096


class _ValueCache(dict[int, _ValueEntry]):
    """raw value -> entry for one register, filled on first use (and emptied when full)."""

    __slots__ = ("reg",)

    def __init__(self, reg: Register) -> None:
        super().__init__()
        self.reg = reg

    def __missing__(self, raw: int) -> _ValueEntry:
        reg = self.reg
        value = reg.value(raw)
        extra: tuple[str, Any] | None = None
        if reg.key == "state":
            extra = ("state_text", state_text(value))
        elif reg.key == "fault":
            extra = ("fault_text", fault_text(value))
        problem = reg.range_warning(value)
        save = value == 1 and reg.number in SAVE_REGISTERS
        special = (problem, extra, save) if problem is not None or extra or save else None
        if len(self) >= _VALUE_CACHE_LIMIT:
            self.clear()
        entry = self[raw] = (value, reg.describe(value), special)
        return entry


_value_caches: dict[int, _ValueCache] = {}  # CAN address -> its register's value cache


def _value_cache(reg: Register) -> _ValueCache:
    cache = _value_caches.get(reg.can_address)
    if cache is None:
        cache = _value_caches[reg.can_address] = _ValueCache(reg)
    return cache


@dataclass(frozen=True, slots=True)
class _Layout:
    """Everything about a value-carrying frame (read response, write request) that its
    identifier, length and direction fix; only the register values vary."""

    direction: str
    device: int
    code: int
    name: str | None
    fields: dict[str, Any]
    warnings: list[str]
    flags: list[str]
    prefix: str  # of the summary
    pair_key: tuple[Any, ...]
    expects: bool
    ambiguity: str  # "read" / "write": the frame may also fit the other direction's shape
    head: Register | None  # odd start address: the first byte is this register's high byte
    start: int  # offset of the first whole register
    unpack: Callable[[bytes, int], tuple[Any, ...]]  # the whole registers, little endian
    slots: tuple[tuple[str, _ValueCache], ...]  # name and value cache of each whole register
    tail: Register | None  # the span ends inside this register: the last byte is its low byte


class Eg2CanDecoder:
    """Decode CAN frames of EG2-4X0 grippers: one Record per frame, in order.

    ``devices``, when given, limits EG2 decoding to those device IDs (plus broadcast); frames
    for any other device are shown as foreign ``can`` records.
    """

    def __init__(self, bus: str = "can0", *, devices: Collection[int] | None = None) -> None:
        self.bus = bus
        self.devices = frozenset(devices) if devices is not None else None
        self._directions = _Directions()
        self._direction = self._directions.tag  # bound once: it runs for every frame
        self._memo: dict[tuple[Any, ...], _Template] = {}
        # (arbitration id, length, direction tag) -> the last read response or write request:
        # (data, template, layout)
        self._last: dict[int, tuple[bytes, _Template, _Layout]] = {}

    def reset(self) -> None:
        """Forget pending requests (a new capture, or a gap in the stream)."""
        self._directions.reset()

    def decode(self, frame: CanFrame, index: int) -> Record:
        """The Record of one frame. Never raises."""
        try:
            data = frame.data
            if type(data) is not bytes:
                data = bytes(data)
            aid = frame.arbitration_id
            n = len(data)
            if (
                not frame.is_extended
                or frame.is_remote
                or frame.is_error
                or frame.is_fd
                or n > 8
                or (frame.dlc is not None and frame.dlc != n)
                or not 0 <= aid < RESERVED_BIT  # bit 28 set: not EG2 (J1939 and others)
                or (
                    self.devices is not None  # the device filter (broadcasts pass it)
                    and aid & 0x3FFF not in self.devices
                    and aid & 0x3FFF != BROADCAST
                )
            ):
                return self._foreign(frame, index, data)
            t = frame.t
            op = aid >> 26  # bit 28 is clear: the operation
            tag = self._direction(aid, op, data, t) if op <= OP_WRITE else _TAG_NONE
            # register values ride on read responses and write requests
            if tag != _TAG_NONE and (tag == _TAG_REQUEST) == (op == OP_WRITE):
                tpl = self._valued(aid, data, tag)
            else:
                tpl = self._other(aid, data, tag)
            return _from_template(tpl, t, self.bus, n, data, index)
        except Exception as exc:  # a decoder bug must not stop a capture: show it on the frame
            return self._internal_error(frame, index, exc)

    # -- the decoded part of a record, built once per distinct frame ------------------------

    def _valued(self, aid: int, data: bytes, tag: int) -> _Template:
        """A read response or write request: register values change from frame to frame, so
        keep the last frame per identifier, length and direction (an idle gripper answers the
        same bytes) with the layout that the three fix."""
        lkey = aid << 10 | len(data) << 6 | tag
        lasts = self._last
        last = lasts.get(lkey)
        if last is not None and last[0] == data:
            return last[1]
        if last is None:
            layout = _make_layout(aid, len(data), tag)
            if len(lasts) >= MEMO_LIMIT:
                lasts.clear()
        else:
            layout = last[2]
        tpl = _fill(layout, data)
        lasts[lkey] = (data, tpl, layout)
        return tpl

    def _other(self, aid: int, data: bytes, tag: int) -> _Template:
        """Frames without register values, memoised whole."""
        key = (aid, data, tag)
        memo = self._memo
        tpl = memo.get(key)
        if tpl is None:
            if len(memo) >= MEMO_LIMIT:
                memo.clear()
            tpl = memo[key] = _build_other(aid, data, tag)
        return tpl

    def _internal_error(self, frame: CanFrame, index: int, exc: Exception) -> Record:
        raw = bytes(getattr(frame, "data", b"") or b"")
        return Record(
            t=getattr(frame, "t", None),
            bus=self.bus,
            protocol=FOREIGN_CAN,
            kind=FRAME,
            length=len(raw),
            raw=raw,
            index=index,
            errors=[M.CAN_DECODER_ERROR.text(error=repr(exc))],
            summary="undecodable frame",
            flags=[F.FOREIGN, M.CAN_DECODER_ERROR.code],
        )

    # -- frames that are not EG2 ------------------------------------------------------------

    def _foreign(self, frame: CanFrame, index: int, data: bytes) -> Record:
        length = frame.length
        key = (
            "foreign",
            frame.arbitration_id,
            data,
            frame.is_extended,
            frame.is_remote,
            frame.is_error,
            frame.is_fd,
            length,
            self.devices is not None,
        )
        memo = self._memo
        tpl = memo.get(key)
        if tpl is None:
            if len(memo) >= MEMO_LIMIT:
                memo.clear()
            tpl = memo[key] = _build_foreign(frame, data, length, self.devices is not None)
        return _from_template(tpl, frame.t, self.bus, length, data, index)


def _id_fields(aid: int, n: int) -> tuple[dict[str, Any], Notes]:
    """The fields and notes every EG2 frame of this identifier and length has."""
    op, address, device = unpack_id(aid)
    fields: dict[str, Any] = {
        "op": OPERATIONS[op],
        "address": address,
        "id": f"0x{aid:08X}",
        "dlc": n,
    }
    notes = Notes()
    if device == 0:
        notes.warn_of(M.CAN_DEVICE_ZERO)
    if device == BROADCAST:
        fields["broadcast"] = True
    return fields, notes


def _make_layout(aid: int, n: int, tag: int) -> _Layout:
    """The fixed part of a read response or write request of n bytes."""
    op, address, device = unpack_id(aid)
    fields, notes = _id_fields(aid, n)
    regs = _span_registers(address, n)
    fields["length"] = n
    fields["registers"] = [r.name for r in regs]
    write = op == OP_WRITE
    if tag >= _TAG_MISMATCH:
        asked = tag - _TAG_MISMATCH
        notes.warn_of(M.CAN_LENGTH_MISMATCH, asked=_plural(asked), length=n)
    _span_warnings(address, n, regs, write, notes)
    head = _register_at(address - 1) if address & 1 else None
    start = 1 if head is not None else 0
    whole = (n - start) // 2
    slots = tuple(
        (reg.name, _value_cache(reg))
        for reg in (_register_at(address + start + 2 * k) for k in range(whole))
    )
    tail = _register_at(address + n - 1) if (n - start) & 1 else None
    return _Layout(
        direction=REQUEST if write else RESPONSE,
        device=device,
        code=op,
        name=_span_name(regs),
        fields=fields,
        warnings=notes.warnings,
        flags=notes.flags,
        prefix=f"write {_plural(n)} at {address}: " if write else "-> ",
        pair_key=(aid,),
        expects=write and device != BROADCAST,
        ambiguity="write" if write else "read",
        head=head,
        start=start,
        unpack=struct.Struct(f"<{whole}H").unpack_from,
        slots=slots,
        tail=tail,
    )


def _fill(layout: _Layout, data: bytes) -> _Template:
    """A layout with the register values of one frame."""
    fields = layout.fields.copy()
    notes = Notes()
    notes.warnings += layout.warnings
    notes.flags += layout.flags
    if _count_shaped(data):
        _note_ambiguity(layout, data[0], notes)
    parts: list[str] = []
    partial: list[dict[str, Any]] = []
    head = layout.head
    if head is not None:
        _half_byte(head.can_address + 1, data[0], head.name, "high", parts, partial)
    values, is_save = _fill_values(layout, data, fields, parts, notes)
    tail = layout.tail
    if tail is not None:
        _half_byte(tail.can_address, data[-1], tail.name, "low", parts, partial)
    fields["values"] = values
    if partial:
        fields["partial"] = partial
    return (
        EG2_CAN,
        layout.direction,
        layout.device,
        layout.code,
        layout.name,
        fields,
        [],
        notes.warnings,
        layout.prefix + ", ".join(parts),
        layout.pair_key,
        layout.expects,
        is_save,
        notes.flags,
    )


def _note_ambiguity(layout: _Layout, count: int, notes: Notes) -> None:
    """A value-carrying frame shaped like a count could also be the other direction."""
    if layout.ambiguity == "read":
        notes.warn_of(M.CAN_MAYBE_READ_REQUEST, bytes=_plural(count))
    else:
        notes.warn_of(M.CAN_MAYBE_WRITE_RESPONSE, bytes=_plural(count))


def _half_byte(
    address: int,
    byte: int,
    register: str,
    half: str,
    parts: list[str],
    partial: list[dict[str, Any]],
) -> None:
    """One byte of a register whose other half lies outside the frame."""
    partial.append({"address": address, "byte": f"{byte:02X}", "register": register, "half": half})
    parts.append(f"byte {address}=0x{byte:02X}")


def _fill_values(
    layout: _Layout, data: bytes, fields: dict[str, Any], parts: list[str], notes: Notes
) -> tuple[dict[str, int], bool]:
    """The register values of the frame (and whether one is a parameter save); their texts go
    to parts, their extra fields to fields."""
    values: dict[str, int] = {}
    is_save = False
    raws = layout.unpack(data, layout.start)
    i = 0  # a counter is about 10% faster than enumerate here
    for name, cache in layout.slots:
        value, text, special = cache[raws[i]]
        i += 1  # noqa: SIM113
        values[name] = value
        parts.append(text)
        if special is not None:
            problem, extra, save = special
            if problem is not None:  # VALUE_OUT_OF_RANGE's text, made once per value
                notes.warn(M.VALUE_OUT_OF_RANGE.code, problem)
            if extra is not None:
                fields[extra[0]] = extra[1]
            if save:
                is_save = True
    return values, is_save


def _build_other(aid: int, data: bytes, tag: int) -> _Template:
    """Frames that carry no register values: read requests, write responses, frames without
    data, and operations 2 and 3."""
    op, address, device = unpack_id(aid)
    n = len(data)
    fields, notes = _id_fields(aid, n)
    direction: str | None = None
    name: str | None = None
    if op == OP_READ and tag == _TAG_REQUEST:
        direction = REQUEST
        name, summary = _read_request(address, data, fields, notes)
    elif op == OP_WRITE and tag == _TAG_RESPONSE:
        direction = RESPONSE
        name, summary = _write_response(address, data, fields)
    elif op in (OP_READ, OP_WRITE):  # no data at all
        what = "read" if op == OP_READ else "write"
        notes.error_of(M.CAN_NO_DATA, what=what)
        summary = f"{what} at {address}: no data"
    else:
        name, summary = _raw_operation(op, address, data, fields, notes)
    pair_key = (aid,) if direction is not None else None
    expects = direction == REQUEST and device != BROADCAST
    return (
        EG2_CAN,
        direction,
        device,
        op,
        name,
        fields,
        notes.errors,
        notes.warnings,
        summary,
        pair_key,
        expects,
        False,
        notes.flags,
    )


def _read_request(
    address: int, data: bytes, fields: dict[str, Any], notes: Notes
) -> tuple[str | None, str]:
    """Name and summary of a read request; its span goes into fields."""
    count = data[0]
    regs = _span_registers(address, count)
    fields["length"] = count
    fields["registers"] = [r.name for r in regs]
    if len(data) == 8:
        fields["padded"] = True
    _span_warnings(address, count, regs, False, notes)
    return _span_name(regs), f"read {_plural(count)} at {address} ({_span_keys(regs)})"


def _write_response(address: int, data: bytes, fields: dict[str, Any]) -> tuple[str | None, str]:
    """Name and summary of a write response; its span goes into fields."""
    count = data[0]
    regs = _span_registers(address, count)
    fields["written_bytes"] = count
    fields["registers"] = [r.name for r in regs]
    if len(data) == 8:
        fields["padded"] = True
    return _span_name(regs), f"-> wrote {_plural(count)}"


def _raw_operation(
    op: int, address: int, data: bytes, fields: dict[str, Any], notes: Notes
) -> tuple[str, str]:
    """Name and summary of operations 2 and 3, whose payload the manual does not lay out."""
    fields["data"] = _hex(data)
    notes.warn_of(M.CAN_RAW_OPERATION, op=op, name=OPERATIONS[op])
    return OPERATIONS[op], f"{OPERATIONS[op]} at {address} [{len(data)}] {_hex(data)}".rstrip()


def _build_foreign(frame: CanFrame, data: bytes, length: int, filtered: bool) -> _Template:
    """A frame no EG2 sent (or one the device filter leaves out), shown as it is."""
    aid = frame.arbitration_id
    notes = Notes()
    notes.flag(F.FOREIGN)
    extended = frame.is_extended
    ident = f"0x{aid:08X}" if extended else f"0x{aid:03X}"
    fields: dict[str, Any] = {"id": ident, "dlc": length, "extended": extended}
    kind = "extended" if extended else "standard"
    if frame.is_error:
        summary = _error_frame(aid, data, fields, notes)
    else:
        if not 0 <= aid <= (MAX_ID if extended else 0x7FF):
            notes.warn_of(M.CAN_ID_TOO_WIDE, id=aid, bits=29 if extended else 11)
        if frame.is_remote:
            # not EG2 (it sends data frames only): the code is the record's own foreign
            notes.warn_of(M.CAN_REMOTE_FRAME)
            summary = f"remote {kind} {ident} [{length}]"
        else:
            summary = _data_frame(frame, data, f"{kind} {ident}", filtered, fields, notes)
        fields["data"] = _hex(data)
    return (
        FOREIGN_CAN,
        None,
        None,
        None,
        None,
        fields,
        notes.errors,
        notes.warnings,
        summary,
        None,
        False,
        False,
        notes.flags,
    )


def _error_frame(aid: int, data: bytes, fields: dict[str, Any], notes: Notes) -> str:
    """Summary of a CAN error frame (aid: its error class); its problem is noted."""
    text = can_error_text(aid)
    notes.error(M.CAN_ERROR_FRAME.code, text)  # can_error_text: the catalogue's words
    fields["error_class"] = aid
    fields["data"] = _hex(data)
    return f"{text} [{len(data)}] {_hex(data)}".rstrip()


def _data_frame(
    frame: CanFrame,
    data: bytes,
    title: str,
    filtered: bool,
    fields: dict[str, Any],
    notes: Notes,
) -> str:
    """Summary of a foreign data frame (title: its kind and identifier); what does not fit
    classic CAN is noted."""
    aid = frame.arbitration_id
    if frame.is_fd:
        fields["fd"] = True
        title = "FD " + title
    elif len(data) > 8:
        notes.warn_of(M.CAN_TOO_LONG, length=len(data))
    elif frame.dlc is not None and frame.dlc != len(data):
        notes.warn_of(M.CAN_DLC_MISMATCH, dlc=frame.dlc, length=len(data))
    elif frame.is_extended and filtered and 0 <= aid < RESERVED_BIT:
        fields["eg2_device"] = aid & 0x3FFF  # left out by the decoder's device filter
    return f"{title} [{len(data)}] {_hex(data)}".rstrip()


def _from_template(
    tpl: Any, t: float | None, bus: str, length: int, data: bytes, index: int
) -> Record:
    """A Record from a memoised decode; positional, as this is the hot path, with fresh
    errors/warnings/flags lists (later stages append to them)."""
    (pr, di, dv, co, na, fi, er, wa, su, pk, ex, sv, fl) = tpl
    return Record(
        t, bus, pr, FRAME, length, data, None, index, di, dv, co, na, fi,
        er.copy(), wa.copy(), su, -1, None, None, pk, ex, sv, fl.copy(),
    )  # fmt: skip
