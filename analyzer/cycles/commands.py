"""The commands that start and stop a gripper's motion, found in the records of each protocol.

- Regular serial: catch (``10``), continuous catch (``18``), release (``11``) and seek (``54``)
  start a motion; stop (``16``) ends it (``decoders.eg2_serial.Cmd``).
- Modbus RTU and CAN: a write that sets the target opening (register 1010, CAN address 1020,
  alone or with the speed and force beside it) starts a motion, as it does on the gripper;
  a write of 1 to the stop register (1006, CAN 1012) ends it (``decoders/registers.py``). CAN
  operations 2 and 3 have no documented layout: they start nothing.

Only requests without errors count: a frame whose checksum fails is ignored by the gripper. The
answers that matter are the responses to these writes: an ok, or a refusal (serial status
``55``, a Modbus exception). ``CODES`` are the record codes of all of them, so a listener picks
the few candidates out of a batch by one column (``RecordSequence.column("code")``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Final

from decoders import eg2_can, eg2_serial, modbus_pdu
from decoders.eg2_serial import Cmd
from decoders.flags import CUT_OFF, EXCEPTION_RESPONSE, RETRANSMISSION, WRITE_FAILED
from decoders.flags import UNANSWERED as UNANSWERED_FLAG
from decoders.model import EG2_CAN, EG2_SERIAL, MODBUS_RTU, REQUEST, RESPONSE, Record
from decoders.registers import opening_mm

# what a command does
CATCH: Final = "catch"  # close with the force limit
RELEASE: Final = "release"  # open fully
MOVE: Final = "move"  # go to an opening (serial seek, a Modbus or CAN target write)
STOP: Final = "stop"

# the fate of a command's request, as pairing left it on the record
ANSWERED: Final = "answered"
NOT_ANSWERED: Final = "unanswered"
STOPPED_FIRST: Final = "cut_off"  # the capture was stopped before an answer could come
NOBODY: Final = "broadcast"  # nobody answers a broadcast

_SERIAL: Final[dict[int, str]] = {
    Cmd.MOVE_CATCH_XG: CATCH,
    Cmd.MOVE_CATCH2_XG: CATCH,
    Cmd.MOVE_RELEASE: RELEASE,
    Cmd.SEEKPOS: MOVE,
    Cmd.MOVE_STOPHERE: STOP,
}
_MODBUS_WRITES: Final = frozenset({0x06, 0x10})
_MODBUS_EXCEPTIONS: Final = frozenset({0x86, 0x90})
_CAN_WRITE: Final = 1  # the operation of a CAN write (its record's code)
_REGISTER_WRITES: Final = {MODBUS_RTU: _MODBUS_WRITES, EG2_CAN: frozenset({_CAN_WRITE})}
# the device number every gripper of a bus executes (and none answers), by protocol
_BROADCAST: Final = {
    EG2_SERIAL: eg2_serial.BROADCAST,
    MODBUS_RTU: modbus_pdu.BROADCAST,
    EG2_CAN: eg2_can.BROADCAST,
}
TARGET: Final = "CMD_OPENLEN_SET"
_STOP_REGISTER: Final = "CMD_STOP"
_WORDS: Final = (("CMD_SPEED_SET", "speed={}"), ("CMD_FORCE_SET", "force={} g"))

#: the record codes of every candidate (a serial CMD, a Modbus function, a CAN operation):
#: the protocols share numbers, so a candidate is checked again by ``command_of``/``answer_of``
CODES: Final = frozenset({*_SERIAL, *_MODBUS_WRITES, *_MODBUS_EXCEPTIONS, _CAN_WRITE})


@dataclass(frozen=True, slots=True)
class Command:
    """A motion or stop command to one gripper (``device``; ``broadcast``: to every gripper
    of the bus). ``target``: the opening aimed at (0-1000), None for a catch or a release (the
    gripper's limits) and a stop. ``fate``: how pairing left the request; ``answer``: the seq
    of its response, if any. ``same``: what a resent copy repeats (the command's bytes)."""

    seq: int
    t: float | None
    bus: str
    device: int
    kind: str
    words: str
    target: int | None
    fate: str
    answer: int | None
    broadcast: bool
    retransmission: bool
    same: bytes


@dataclass(frozen=True, slots=True)
class Answer:
    """A response to a command: ``refused`` when the gripper said no (serial status ``55``, a
    Modbus exception), ``garbled`` when the response itself is damaged."""

    seq: int
    t: float | None
    bus: str
    device: int
    request: int
    refused: bool
    garbled: bool


def command_of(rec: Record) -> Command | None:
    """The motion or stop command a request carries, if it carries one."""
    if rec.direction != REQUEST or rec.errors or rec.device is None:
        return None
    if rec.protocol == EG2_SERIAL:
        found = _serial(rec)
    elif rec.code in _REGISTER_WRITES.get(rec.protocol, ()):
        found = _registers(rec)
    else:
        found = None
    if found is None:
        return None
    kind, target, words = found
    broadcast = rec.device == _BROADCAST[rec.protocol]
    return Command(
        rec.seq,
        rec.t,
        rec.bus,
        rec.device,
        kind,
        words,
        target,
        NOBODY if broadcast else _fate(rec),
        rec.pair,
        broadcast,
        RETRANSMISSION in rec.flags,
        rec.raw,
    )


def answer_of(rec: Record) -> Answer | None:
    """The response to a request, if ``rec`` is one (which request: ``rec.pair``)."""
    if rec.direction != RESPONSE or rec.pair is None or rec.device is None:
        return None
    refused = WRITE_FAILED in rec.flags or EXCEPTION_RESPONSE in rec.flags
    return Answer(rec.seq, rec.t, rec.bus, rec.device, rec.pair, refused, bool(rec.errors))


def _fate(rec: Record) -> str:
    if rec.pair is not None:
        return ANSWERED
    if UNANSWERED_FLAG in rec.flags:
        return NOT_ANSWERED
    if CUT_OFF in rec.flags:
        return STOPPED_FIRST
    return ANSWERED  # still held by a live pairing (never, today): not said to be unanswered


def _serial(rec: Record) -> tuple[str, int | None, str] | None:
    kind = _SERIAL.get(rec.code) if rec.code is not None else None
    if kind is None:
        return None
    target = rec.fields.get("position") if kind == MOVE else None
    if kind == MOVE and not isinstance(target, int):
        return None  # a seek without its position (a hand-compatible payload): no target
    return kind, target, rec.summary


def _registers(rec: Record) -> tuple[str, int | None, str] | None:
    """A register write that moves (the target opening) or stops (stop = 1) the gripper."""
    values = _written(rec.fields)
    target = values.get(TARGET)
    if isinstance(target, int):
        words = [f"move to {opening_mm(target)} mm"]
        words += [text.format(values[name]) for name, text in _WORDS if name in values]
        return MOVE, target, " ".join(words)
    if values.get(_STOP_REGISTER) == 1:
        return STOP, None, "stop"
    return None


def _written(fields: dict[str, Any]) -> dict[str, Any]:
    """The registers a write request sets, by name (several, or a Modbus single write's one)."""
    values = fields.get("values")
    if isinstance(values, dict):
        return values
    name = fields.get("name")
    if isinstance(name, str) and "value" in fields:
        return {name: fields["value"]}
    return {}
