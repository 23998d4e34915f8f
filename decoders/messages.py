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

# -- the serial protocol (decoders/eg2_serial.py) -------------------------------------------
SERIAL_FRAME_SHAPE: Final = Message(
    F.MALFORMED, "malformed frame: {length} bytes do not fit a header and its length byte"
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


def _catalogue() -> dict[str, dict[str, Message]]:
    """Flag code -> message name -> message, in the order the messages are written above."""
    out: dict[str, dict[str, Message]] = {}
    for name, value in globals().items():
        if isinstance(value, Message):
            out.setdefault(value.code, {})[name] = value
    return out


CATALOGUE: Final = _catalogue()
