"""Frame builders for the three protocols: the inverse of the decoders.

Used by the simulated gripper, the sample-capture generator, tests and benchmarks. Pure, like
the decoders: bytes and CanFrames out, no I/O.
"""

from __future__ import annotations

import struct

import crcmod.predefined

from .model import CanFrame

SERIAL_REQUEST = b"\xeb\x90"
SERIAL_RESPONSE = b"\xee\x16"

modbus_crc = crcmod.predefined.mkCrcFun("modbus")

CAN_BROADCAST = 0x3FFF
OP_READ, OP_WRITE, OP_MOVE, OP_FOLLOW = 0, 1, 2, 3


# -- regular serial protocol ----------------------------------------------------------------


def serial_frame(device: int, cmd: int, data: bytes = b"", response: bool = False) -> bytes:
    """``EB 90 | ID | LEN | CMD | DATA | SUM`` (or ``EE 16 ...`` for a response)."""
    body = bytes((device & 0xFF, len(data) + 1, cmd)) + data
    header = SERIAL_RESPONSE if response else SERIAL_REQUEST
    return header + body + bytes((sum(body) & 0xFF,))


def u16le(*values: int) -> bytes:
    return b"".join(struct.pack("<H", v & 0xFFFF) for v in values)


# -- Modbus RTU -----------------------------------------------------------------------------


def with_crc(pdu: bytes, swapped: bool = False) -> bytes:
    """Append the CRC-16/MODBUS, low byte first (or high first, as the manual prints it)."""
    crc = modbus_crc(pdu)
    return pdu + (struct.pack(">H", crc) if swapped else struct.pack("<H", crc))


def modbus_read_request(slave: int, start: int, count: int) -> bytes:
    return with_crc(struct.pack(">BBHH", slave, 3, start, count))


def modbus_read_response(slave: int, values: list[int]) -> bytes:
    data = b"".join(struct.pack(">H", v & 0xFFFF) for v in values)
    return with_crc(bytes((slave, 3, len(data))) + data)


def modbus_write_single(slave: int, register: int, value: int) -> bytes:
    """The request; the response is the same bytes."""
    return with_crc(struct.pack(">BBHH", slave, 6, register, value & 0xFFFF))


def modbus_write_multiple(slave: int, start: int, values: list[int]) -> bytes:
    data = b"".join(struct.pack(">H", v & 0xFFFF) for v in values)
    return with_crc(struct.pack(">BBHHB", slave, 0x10, start, len(values), len(data)) + data)


def modbus_write_multiple_response(slave: int, start: int, count: int) -> bytes:
    return with_crc(struct.pack(">BBHH", slave, 0x10, start, count))


def modbus_exception(slave: int, function: int, code: int) -> bytes:
    return with_crc(bytes((slave, function | 0x80, code)))


# -- CAN register protocol ------------------------------------------------------------------


def can_id(op: int, address: int, device: int) -> int:
    """``(op << 26) | (address << 14) | device``: 0x04FF0001 = write, address 1020, device 1."""
    return ((op & 0x3) << 26) | ((address & 0xFFF) << 14) | (device & 0x3FFF)


def can_id_fields(arbitration_id: int) -> tuple[int, int, int]:
    """(operation, address, device) from a 29-bit identifier."""
    return (arbitration_id >> 26) & 0x3, (arbitration_id >> 14) & 0xFFF, arbitration_id & 0x3FFF


def can_read_request(
    device: int, address: int, n: int, t: float | None = None, padded: bool = False
) -> CanFrame:
    data = bytes((n,)) + (bytes(7) if padded else b"")
    return CanFrame(t, can_id(OP_READ, address, device), data)


def can_read_response(device: int, address: int, data: bytes, t: float | None = None) -> CanFrame:
    return CanFrame(t, can_id(OP_READ, address, device), data)


def can_write_request(device: int, address: int, data: bytes, t: float | None = None) -> CanFrame:
    return CanFrame(t, can_id(OP_WRITE, address, device), data)


def can_write_response(device: int, address: int, n: int, t: float | None = None) -> CanFrame:
    return CanFrame(t, can_id(OP_WRITE, address, device), bytes((n,)))


def candump_line(frame: CanFrame, channel: str = "can0") -> str:
    """One line of ``candump -L`` format."""
    t = frame.t or 0.0
    width = 8 if frame.is_extended else 3
    return f"({t:.6f}) {channel} {frame.arbitration_id:0{width}X}#{frame.data.hex().upper()}"
