"""The decoder registry: protocol names and aliases to decoder classes (as python-can keys its
interfaces by name), and protocol detection for byte streams.
"""

from __future__ import annotations

from .eg2_serial import Eg2SerialDecoder
from .framing import ByteStreamDecoder
from .modbus_rtu import ModbusRtuDecoder
from .model import EG2_CAN, EG2_SERIAL, MODBUS_RTU, Chunk

# each is made as cls(bus, byte_time_s=...): byte_time_s (10 bits / baud) when the line's baud is
# known, so times inside a read are estimated (decoders/framing.py)
STREAM_DECODERS: dict[str, type[ByteStreamDecoder]] = {
    EG2_SERIAL: Eg2SerialDecoder,
    MODBUS_RTU: ModbusRtuDecoder,
}

ALIASES: dict[str, str] = {
    "serial": EG2_SERIAL,
    "eg2-serial": EG2_SERIAL,
    "rs232": EG2_SERIAL,
    "modbus": MODBUS_RTU,
    "modbus-rtu": MODBUS_RTU,
    "rs485": MODBUS_RTU,
    "can": EG2_CAN,
    "eg2-can": EG2_CAN,
}


#: a protocol in words, for messages
PROTOCOL_WORDS: dict[str, str] = {
    EG2_SERIAL: "EG2 serial",
    MODBUS_RTU: "Modbus RTU",
    EG2_CAN: "CAN",
}


def short_name(protocol: str) -> str:
    """The shortest name ``--protocol`` takes for a protocol (``serial`` for eg2-serial)."""
    return next(alias for alias, name in ALIASES.items() if name == protocol)


def resolve_protocol(name: str) -> str:
    """A protocol name or alias to its canonical name; ValueError lists the choices."""
    try:
        return ALIASES[name.lower()]
    except KeyError:
        raise ValueError(
            f"unknown protocol {name!r}; choose one of: {', '.join(sorted(ALIASES))}"
        ) from None


def valid_frames(sample: bytes) -> dict[str, int]:
    """How many valid frames each byte-stream decoder finds in a sample of a line."""
    counts = {}
    for name, cls in STREAM_DECODERS.items():
        dec = cls()
        records = dec.feed(Chunk(sample)) + dec.finish()
        counts[name] = sum(1 for r in records if r.ok)
    return counts


def detect_protocol(sample: bytes) -> str | None:
    """Which byte-stream protocol a sample of a line holds: the one that finds the most
    valid frames in it (None if neither finds any)."""
    best, best_count = None, 0
    for name, count in valid_frames(sample).items():
        if count > best_count:
            best, best_count = name, count
    return best
