"""The words of the errors and warnings the decoders write, keyed by flag code: one home for
the texts both engines say (``native/codegen.py`` writes the crate's copy from this catalogue).

A message is a ``str.format`` template with named fields; the crate gets a constant for a
message without fields and a macro around ``format!`` for the others (the generator maps the
format specs, which must print the same in both: ``{x:02X}``, ``{x:#x}``, ``{x:.1f}``). A float
field without a spec prints differently (Python ``1.0``, Rust ``1``): pass such a number as a
string formatted by the caller. The catalogue is grouped by protocol (names start with it); a
decoder's summary lines are not messages. A message marked ``native=False`` is said by the
Python decoders only (the crate has no such case) and gets no Rust copy.
"""

from __future__ import annotations

import string
from dataclasses import dataclass
from typing import Final

from . import flags as F


@dataclass(frozen=True, slots=True)
class Message:
    code: str  # the flag code written with the text (decoders/flags.py)
    template: str  # str.format, named fields only
    native: bool = True  # the crate says it too (False: the Python decoders only)

    def text(self, **values: object) -> str:
        return self.template.format(**values) if values else self.template

    @property
    def fields(self) -> tuple[str, ...]:
        """The template's field names, in order of first use."""
        names = (name for _, name, _, _ in string.Formatter().parse(self.template) if name)
        return tuple(dict.fromkeys(names))


# -- every protocol (decoders/registers.py: Register.range_warning) --------------------------
VALUE_OUT_OF_RANGE: Final = Message(F.OUT_OF_RANGE, "{label} out of range ({lo}-{hi}): {value}")

# -- byte-stream framing (decoders/framing.py) ----------------------------------------------
FRAMING_GARBAGE: Final = Message(F.GARBAGE, "garbage: {length} bytes belong to no frame ({why})")
# the reasons FRAMING_GARBAGE gives ({why})
GARBAGE_NO_HEADER: Final = "no frame header"
GARBAGE_NO_FRAME: Final = "no frame starts here"
GARBAGE_INCOMPLETE: Final = "incomplete frame followed by a valid one"
GARBAGE_BAD_CHECKSUM: Final = "bytes of a frame-shaped candidate with a bad checksum"
FRAMING_TRUNCATED: Final = Message(
    F.TRUNCATED, "truncated frame: stream ended after {length} bytes"
)
FRAMING_CUT_OFF: Final = Message(
    F.CUT_OFF,
    "cut off by the stop: the capture was stopped {bytes} into this frame",
)

# -- the serial protocol (decoders/eg2_serial.py) -------------------------------------------
SERIAL_FRAME_SHAPE: Final = Message(
    F.MALFORMED, "malformed frame: {length} bytes do not fit a header and its length byte"
)
SERIAL_TRUNCATED_HEADER: Final = Message(
    F.TRUNCATED, "truncated frame: stream ended {length} bytes in, before the length byte"
)
SERIAL_TRUNCATED_BODY: Final = Message(
    F.TRUNCATED,
    "truncated frame: LEN {len_byte} needs {needed} bytes, stream ended after {length}",
)
SERIAL_CHECKSUM: Final = Message(
    F.BAD_CHECKSUM, "checksum error: expected 0x{expected:02X}, got 0x{got:02X}"
)
SERIAL_ID_ZERO: Final = Message(F.INVALID_ID, "ID 0 is not a valid ID")
SERIAL_BROADCAST_RESPONSE: Final = Message(
    F.BROADCAST, "response from broadcast ID 255 (broadcasts get no response)"
)
SERIAL_UNKNOWN_COMMAND: Final = Message(
    F.UNDOCUMENTED,
    "unknown command 0x{code:02X} (in neither the gripper's nor the hand's table)",
)
SERIAL_LAYOUT: Final = Message(F.MALFORMED, "{name} {direction}: expected {expected}, got {length}")
SERIAL_WRITE_FAILED: Final = Message(
    F.WRITE_FAILED, "write failure status 0x55 (the host should resend)"
)
SERIAL_UNKNOWN_STATUS: Final = Message(
    F.UNDOCUMENTED, "unknown status byte 0x{status:02X} (0x01 is ok, 0x55 failure)"
)
SERIAL_SET_ID_BROADCAST: Final = Message(
    F.BROADCAST, "set ID sent to broadcast: every gripper on the bus takes the new ID"
)
SERIAL_DEVICE_FAULT: Final = Message(F.DEVICE_FAULT, "gripper reports fault: {faults}")

# -- Modbus RTU (decoders/modbus_framing.py, modbus_pdu.py, modbus_registers.py, modbus_rtu.py)
MODBUS_TRUNCATED: Final = Message(F.TRUNCATED, "truncated frame: the stream ended after {bytes}")
MODBUS_TRUNCATED_FUNCTION: Final = Message(
    F.TRUNCATED, "truncated frame: the stream ended after {bytes} ({what})"
)
MODBUS_TRUNCATED_LENGTHS: Final = Message(
    F.TRUNCATED, "truncated frame: the stream ended after {length} of {lengths} bytes ({what})"
)
MODBUS_TOO_SHORT: Final = Message(F.MALFORMED, "frame too short ({length} bytes)")
MODBUS_NO_SHAPE: Final = Message(F.MALFORMED, "{length} bytes are no Modbus frame shape ({what})")
MODBUS_CRC: Final = Message(
    F.BAD_CHECKSUM,
    "CRC error: expected {expected_lo:02X} {expected_hi:02X}, got {got_lo:02X} {got_hi:02X}",
)
MODBUS_CRC_SWAPPED: Final = Message(F.SWAPPED_CRC, "CRC byte order swapped (high byte first)")
MODBUS_UNDOCUMENTED_FUNCTION: Final = Message(
    F.UNDOCUMENTED, "function {code} ({name}) is not one the EG2 documents (3, 6 and 16)"
)
MODBUS_BROADCAST_RESPONSE: Final = Message(
    F.BROADCAST, "response from address 0 (broadcast requests get no response)"
)
MODBUS_UNKNOWN_EXCEPTION: Final = Message(
    F.UNDOCUMENTED, "exception code {code} is not a standard Modbus exception"
)
MODBUS_COUNT: Final = Message(
    F.OUT_OF_RANGE, "count {count} outside the Modbus limit of 1-{limit} {what}"
)
MODBUS_COIL_VALUE: Final = Message(
    F.OUT_OF_RANGE, "coil value 0x{value:04X} is neither 0xFF00 (on) nor 0x0000 (off)"
)
MODBUS_NO_REQUEST: Final = Message(
    F.ORPHAN_RESPONSE, "read response without a known request: registers unknown"
)
MODBUS_WRITE_NO_REQUEST: Final = Message(
    F.ORPHAN_RESPONSE, "write response without a known request"
)
MODBUS_READ_LENGTH: Final = Message(
    F.LENGTH_MISMATCH,
    "read response with {count} registers for a request of {asked}: registers unknown",
)
MODBUS_ECHO_DIFFERS: Final = Message(
    F.RESPONSE_MISMATCH,
    "the echo differs from the request (address {address} value {value}, "
    "echo address {echo_address} value {echo_value})",
)
MODBUS_WRITE_DIFFERS: Final = Message(
    F.RESPONSE_MISMATCH,
    "the response (start {start}, count {count}) does not match the request "
    "(start {asked_start}, count {asked_count})",
)
MODBUS_UNTRUSTED: Final = Message(
    F.UNTRUSTED_REQUEST, "registers named from a request with a CRC error"
)
MODBUS_SHORT_NUMBER: Final = Message(
    F.SHORT_REGISTER_NUMBERS,
    "short register number: {wire} means {number} "
    "(the host leaves out the 1000 offset, as some clients do)",
)
MODBUS_SHORT_NUMBERS: Final = Message(
    F.SHORT_REGISTER_NUMBERS,
    "short register numbers: {wire_first}-{wire_last} mean {first}-{last} "
    "(the host leaves out the 1000 offset, as some clients do)",
)
# a device's first frame with short numbers says it of the host (modbus_rtu.py)
MODBUS_HOST_SHORT_NUMBERS: Final = Message(F.SHORT_REGISTER_NUMBERS, "this host uses {warning}")
MODBUS_UNDOCUMENTED_REGISTERS: Final = Message(
    F.UNDOCUMENTED, "undocumented {what} {numbers} (not in the manual's map)"
)
MODBUS_OUTSIDE_MAP: Final = Message(
    F.UNDOCUMENTED, "register {number} is outside the EG2 register map"
)
MODBUS_OUTSIDE_MAP_SPANS: Final = Message(
    F.UNDOCUMENTED, "registers {numbers} are outside the EG2 register map"
)
MODBUS_READ_ONLY_WRITE: Final = Message(F.READ_ONLY_WRITE, "write to read-only {what} {registers}")

# -- the CAN register protocol (decoders/eg2_can.py) -----------------------------------------
CAN_DEVICE_ZERO: Final = Message(F.INVALID_ID, "device 0 is outside the settable IDs 1-16382")
CAN_ODD_START: Final = Message(
    F.ODD_SPAN,
    "odd start address {address}: the first byte is the high byte of {register} "
    "(address {register_address})",
)
CAN_ODD_END: Final = Message(
    F.ODD_SPAN,
    "the span ends inside a register ({bytes} from {address}): the last byte is the low byte "
    "of {register} (address {register_address})",
)
CAN_ODD_LENGTH: Final = Message(F.ODD_SPAN, "odd length {length}: registers are 2 bytes")
CAN_UNDOCUMENTED_ADDRESS: Final = Message(
    F.UNDOCUMENTED, "undocumented address {address} (register {number})"
)
CAN_OUTSIDE_MAP: Final = Message(
    F.UNDOCUMENTED, "address {address} is outside the register map ({first}-{last})"
)
CAN_READ_ONLY_WRITE: Final = Message(
    F.READ_ONLY_WRITE, "write to read-only register {name} ({key})"
)
CAN_LENGTH_MISMATCH: Final = Message(
    F.LENGTH_MISMATCH,
    "response length mismatch: the pending request asked for {asked}, "
    "the response carries {length}",
)
CAN_MAYBE_READ_REQUEST: Final = Message(
    F.AMBIGUOUS_DIRECTION,
    "could also be a repeated read request of {bytes} "
    "(taken as the response to the pending request)",
)
CAN_MAYBE_WRITE_RESPONSE: Final = Message(
    F.AMBIGUOUS_DIRECTION,
    "could also be the response to a write of {bytes} whose request was not seen",
)
CAN_NO_DATA: Final = Message(
    F.MALFORMED, "{what} frame without data: neither a request nor a response"
)
CAN_RAW_OPERATION: Final = Message(
    F.UNDOCUMENTED,
    "operation {op} ({name}): the manual gives no payload layout, shown raw",
)
CAN_ID_TOO_WIDE: Final = Message(F.MALFORMED, "identifier {id:#x} does not fit in {bits} bits")
CAN_REMOTE_FRAME: Final = Message(F.FOREIGN, "remote frame")
CAN_TOO_LONG: Final = Message(F.MALFORMED, "{length} data bytes in a classic CAN frame")
CAN_DLC_MISMATCH: Final = Message(F.MALFORMED, "DLC {dlc} with {length} data bytes")
CAN_ERROR_FRAME: Final = Message(F.CAN_ERROR_FRAME, "CAN error frame")
CAN_ERROR_FRAME_CLASSES: Final = Message(
    F.CAN_ERROR_FRAME, "CAN error frame: {classes} (class 0x{error_class:03X})"
)
CAN_DECODER_ERROR: Final = Message(F.DECODER_ERROR, "internal decoder error: {error}", native=False)

# -- request/response pairing (decoders/pairing.py) ------------------------------------------
PAIRING_RETRANSMISSION: Final = Message(
    F.RETRANSMISSION, "retransmission: the same request again before the first was answered"
)
PAIRING_NO_REQUEST: Final = Message(F.ORPHAN_RESPONSE, "response without a request")
PAIRING_NEXT_REQUEST: Final = Message(F.UNANSWERED, "no response before the next request")
PAIRING_NEXT_SAME_ID: Final = Message(
    F.UNANSWERED, "no response before the next request with the same ID"
)
PAIRING_TIMEOUT: Final = Message(F.UNANSWERED, "no response within {ms:.0f} ms")
PAIRING_WINDOW: Final = Message(F.UNANSWERED, "no response within the pairing window")
PAIRING_END: Final = Message(F.UNANSWERED, "no response before the end of the capture")
PAIRING_SOURCE_LOST: Final = Message(F.UNANSWERED, "no response before the source was lost")
PAIRING_STOPPED: Final = Message(F.CUT_OFF, "no response before the capture was stopped")

# -- the manual's timing rules (decoders/lint.py) --------------------------------------------
LINT_DURING_SAVE: Final = Message(
    F.DURING_SAVE,
    # wait: the pause as Python's f"{s:g}" writes it (1.0 -> "1")
    "command {ms:.0f} ms after a parameter save (the manual asks to wait more than {wait} s)",
)
LINT_TOO_CLOSE: Final = Message(
    F.CLOSER_THAN_5MS,
    "command {ms:.2f} ms after the previous one to this device "
    "(the manual asks for at least {min_gap_ms:.0f} ms)",
)


# -- a capture file's damage: a compressed file cut short or damaged (analyzer/sources/
# compressed.py; the crate's candump and .gz readers). No flag code: the reader's ``errors``
CAPTURE_GZIP_CUT: Final = "the compressed file is cut short"
CAPTURE_GZIP_DAMAGED: Final = "the compressed data is damaged"
CAPTURE_NOT_GZIP: Final = "not gzip data, though its name ends in .gz"
CAPTURE_REST_LOST: Final = "the rest is lost"


def _catalogue() -> dict[str, dict[str, Message]]:
    """Flag code -> message name -> message, in the order the messages are written above."""
    out: dict[str, dict[str, Message]] = {}
    for name, value in globals().items():
        if isinstance(value, Message):
            out.setdefault(value.code, {})[name] = value
    return out


CATALOGUE: Final = _catalogue()
