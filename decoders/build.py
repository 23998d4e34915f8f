"""Frame builders for the three protocols: the inverse of the decoders, and the one place
frames are encoded.

Used by the simulated gripper, the sample-capture generator, tests and benchmarks. Pure, like
the decoders: bytes and CanFrames out, no I/O. The protocol facts (headers, checksum, CRC,
identifier layout) come from the decoders that read them.
"""

from __future__ import annotations

import struct
from typing import Final

from .eg2_can import OP_READ, OP_WRITE
from .eg2_serial import REQUEST_HEADER, RESPONSE_HEADER, checksum
from .modbus_framing import crc16
from .model import CanFrame

# -- regular serial protocol ----------------------------------------------------------------


def serial_frame(device: int, cmd: int, data: bytes = b"", response: bool = False) -> bytes:
    """``EB 90 | ID | LEN | CMD | DATA | SUM`` (or ``EE 16 ...`` for a response)."""
    body = bytes((device & 0xFF, len(data) + 1, cmd)) + data
    header = RESPONSE_HEADER if response else REQUEST_HEADER
    return header + body + bytes((checksum(body),))


def u16le(*values: int) -> bytes:
    """16-bit words, low byte first (serial DATA and CAN register bytes); negative values
    as two's complement."""
    return b"".join(struct.pack("<H", v & 0xFFFF) for v in values)


# -- Modbus RTU -----------------------------------------------------------------------------


def with_crc(pdu: bytes, swapped: bool = False) -> bytes:
    """Append the CRC-16/MODBUS, low byte first (or high first, as the manual prints it)."""
    crc = crc16(pdu)
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
    """The 29-bit identifier ``op << 26 | address << 14 | device`` (bit 28, reserved, is 0):
    ``can_id(1, 1020, 1) == 0x04FF0001``, a write at address 1020 on device 1. Raises
    ValueError for an operation outside 0-3, an address outside 0-4095 or a device outside
    0-16383 (16383 is broadcast)."""
    if not 0 <= op <= 3:
        raise ValueError(f"operation must be 0-3, not {op}")
    if not 0 <= address <= 0xFFF:
        raise ValueError(f"address must be 0-4095, not {address}")
    if not 0 <= device <= 0x3FFF:
        raise ValueError(f"device must be 0-16383, not {device}")
    return op << 26 | address << 14 | device


def can_read_request(
    device: int, address: int, n: int, t: float | None = None, padded: bool = False
) -> CanFrame:
    """Read n bytes from address: DLC 1 with data[0] = n (DLC 8, zero padded, if padded)."""
    data = bytes((n,)) + (bytes(7) if padded else b"")
    return CanFrame(t, can_id(OP_READ, address, device), data)


def can_read_response(device: int, address: int, data: bytes, t: float | None = None) -> CanFrame:
    return CanFrame(t, can_id(OP_READ, address, device), data)


def can_write_request(device: int, address: int, data: bytes, t: float | None = None) -> CanFrame:
    return CanFrame(t, can_id(OP_WRITE, address, device), data)


def can_write_response(
    device: int, address: int, n: int, t: float | None = None, padded: bool = False
) -> CanFrame:
    """The answer to a write of n bytes: DLC 1 with data[0] = n (DLC 8 if padded)."""
    data = bytes((n,)) + (bytes(7) if padded else b"")
    return CanFrame(t, can_id(OP_WRITE, address, device), data)


# -- SocketCAN error frames (linux/can/error.h) ----------------------------------------------

# classes, in the identifier
CAN_ERR_CRTL: Final = 0x004  # controller problem: data[1] says which
CAN_ERR_PROT: Final = 0x008  # protocol violation: data[2] its type, data[3] where
CAN_ERR_BUSOFF: Final = 0x040
CAN_ERR_BUSERROR: Final = 0x080
CAN_ERR_RESTARTED: Final = 0x100
CAN_ERR_CNT: Final = 0x200  # the TX and RX error counters are in data[6] and data[7]
# data[1]: the controller's status
CAN_ERR_CRTL_TX_WARNING: Final = 0x08
CAN_ERR_CRTL_TX_PASSIVE: Final = 0x20
CAN_ERR_CRTL_ACTIVE: Final = 0x40
# data[2]: the protocol violation
CAN_ERR_PROT_BIT0: Final = 0x08  # could not send a dominant bit
CAN_ERR_PROT_TX: Final = 0x80  # the error came while transmitting


def can_error_frame(
    error_class: int,
    *,
    controller: int = 0,
    protocol: int = 0,
    counters: tuple[int, int] | None = None,
    t: float | None = None,
) -> CanFrame:
    """A SocketCAN error frame (DLC 8): the class bits in the identifier, the controller status
    in data[1], the protocol violation in data[2]; ``counters`` (TX, RX) set CAN_ERR_CNT and
    go in data[6] and data[7]."""
    data = bytearray(8)
    data[1], data[2] = controller, protocol
    if counters is not None:
        error_class |= CAN_ERR_CNT
        data[6], data[7] = (min(255, c) for c in counters)
    return CanFrame(t, error_class, bytes(data), is_extended=False, is_error=True)


def candump_line(frame: CanFrame, channel: str = "can0") -> str:
    """One line of ``candump -L`` format."""
    t = frame.t or 0.0
    width = 8 if frame.is_extended else 3
    return f"({t:.6f}) {channel} {frame.arbitration_id:0{width}X}#{frame.data.hex().upper()}"
