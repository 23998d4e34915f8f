"""The bits a classic CAN 2.0 frame occupies on the wire: what a CAN bus's load is made of.

Counted as the Linux kernel (include/linux/can/length.h, can_frame_bits()) and can-utils
``canbusload -e`` (canframelen.c, CFL_EXACT) count them: start-of-frame through the CRC sequence
with the stuff bits the transmitter inserts there, plus 13 bits that are never stuffed (CRC
delimiter, ACK slot, ACK delimiter, 7 end-of-frame bits, 3 intermission bits). Written from the
ISO 11898-1 frame layout and checked against those two sources; none of their code is copied.

Where the two differ this module follows the kernel, which follows the wire: a remote frame has
no data field whatever its DLC (canframelen.c counts DLC bytes of data for one), and a DLC of
9-15 sends 8 data bytes. Error frames count 0 bits (``frame_bits`` says why). CAN FD frames are
refused (ValueError): their exact length needs the stuff-count field and the fixed stuff bits of
ISO CAN FD and depends on two bit rates, and ``canbusload -e`` does not count them either.
"""

from __future__ import annotations

from typing import Final

import crcmod

from .model import CanFrame

MAX_DATA_BYTES: Final = 8
MAX_DLC: Final = 15  # the DLC field has 4 bits; 9-15 still mean 8 data bytes
SFF_ID_BITS: Final = 11
EFF_EXTENSION_BITS: Final = 18  # a 29-bit identifier: 11 base bits, then these 18
STUFF_RUN: Final = 5  # equal bits after which the transmitter inserts their complement

# SOF, identifier (11), RTR, IDE, r0, DLC (4)
SFF_HEADER_BITS: Final = 19
# SOF, base identifier (11), SRR, IDE, identifier extension (18), RTR, r1, r0, DLC (4)
EFF_HEADER_BITS: Final = 39
CRC_BITS: Final = 15
CRC_DELIMITER_BITS: Final = 1
FOOTER_BITS: Final = 9  # ACK slot, ACK delimiter, EOF (7): the kernel's CAN_FRAME_FOOTER_BITS
INTERMISSION_BITS: Final = 3  # must pass before the next frame may start
# after the CRC sequence, never stuffed
TRAILER_BITS: Final = CRC_DELIMITER_BITS + FOOTER_BITS + INTERMISSION_BITS

# An error frame is the controller's report of an error (class and details in its identifier
# and data), not a frame on the wire, so it adds no bits: see frame_bits.
ERROR_FRAME_BITS: Final = 0

# CRC-15/CAN: x^15 + x^14 + x^10 + x^8 + x^7 + x^4 + x^3 + 1, no initial value, no final xor
CRC15_POLYNOMIAL: Final = 0x4599
# crcmod computes CRCs of 8, 16, 24, 32 or 64 bits only. The CRC-16 of the polynomial x*g(x)
# is x times the CRC-15 of g(x) (M*x^16 mod x*g = x * (M*x^15 mod g)), so it is shifted back.
_crc16_of_x_times_g = crcmod.mkCrcFun(
    (1 << 16) | (CRC15_POLYNOMIAL << 1), initCrc=0, rev=False, xorOut=0
)


def crc15(value: int, width: int) -> int:
    """CAN's CRC of the ``width``-bit number ``value``, sent most significant bit first.

    Zero bits put in front leave a CRC with no initial value unchanged, so the bits are padded
    to whole bytes for crcmod's C code.
    """
    octets = value.to_bytes((width + 7) // 8, "big")
    return _crc16_of_x_times_g(octets) >> 1


def stuff_bit_count(bits: str) -> int:
    """How many stuff bits a transmitter inserts into ``bits`` (a string of "0" and "1").

    After 5 equal bits comes their complement, which opens the next run: 0000011111 needs two.
    A run completed by the last bit gets its stuff bit too, as the CRC's last bits do on the
    wire (canframelen.c counts it as well).
    """
    inserted = 0
    run_bit, run = "", 0
    for bit in bits:
        run = run + 1 if bit == run_bit else 1
        run_bit = bit
        if run == STUFF_RUN:
            inserted += 1
            run_bit, run = ("1" if bit == "0" else "0"), 1
    return inserted


def _header(arbitration_id: int, extended: bool, remote: bool, dlc: int) -> list[tuple[int, int]]:
    """The (value, width) fields from SOF through DLC; dominant is 0."""
    rtr = int(remote)
    if not extended:
        # SOF, identifier, RTR, IDE and r0 (dominant: a standard frame), DLC
        return [(0, 1), (arbitration_id, SFF_ID_BITS), (rtr, 1), (0, 2), (dlc, 4)]
    base = arbitration_id >> EFF_EXTENSION_BITS
    extension = arbitration_id & ((1 << EFF_EXTENSION_BITS) - 1)
    # SOF, base identifier, SRR and IDE (recessive), extension, RTR, r1 and r0, DLC
    return [(0, 1), (base, SFF_ID_BITS), (0b11, 2), (extension, EFF_EXTENSION_BITS), (rtr, 1),
            (0, 2), (dlc, 4)]  # fmt: skip


def _pack(fields: list[tuple[int, int]]) -> tuple[int, int]:
    """The fields as one number, first field in the high bits, and its width."""
    value = width = 0
    for field_value, field_width in fields:
        value = (value << field_width) | field_value
        width += field_width
    return value, width


def _check(arbitration_id: int, data: bytes, extended: bool, remote: bool, dlc: int) -> None:
    """ValueError for what a classic CAN frame cannot be, so no count is silently wrong."""
    id_bits = SFF_ID_BITS + (EFF_EXTENSION_BITS if extended else 0)
    if not 0 <= arbitration_id < 1 << id_bits:
        raise ValueError(f"identifier {arbitration_id:#x} does not fit in {id_bits} bits")
    if len(data) > MAX_DATA_BYTES:
        raise ValueError(f"{len(data)} data bytes: a CAN FD frame, whose bits are not counted")
    if not 0 <= dlc <= MAX_DLC:
        raise ValueError(f"DLC {dlc} does not fit in the 4-bit DLC field")
    if remote and data:
        raise ValueError("a remote frame carries no data")
    if not remote and len(data) != min(dlc, MAX_DATA_BYTES):
        raise ValueError(f"DLC {dlc} but {len(data)} data bytes")


def exact_bits(
    arbitration_id: int,
    data: bytes = b"",
    *,
    extended: bool,
    remote: bool = False,
    dlc: int | None = None,
) -> int:
    """The bits the frame takes on the bus, stuff bits and the 3 intermission bits included.

    ``dlc`` defaults to the number of data bytes; a remote frame gives its DLC and no data.
    """
    dlc = len(data) if dlc is None else dlc
    _check(arbitration_id, data, extended, remote, dlc)
    fields = _header(arbitration_id, extended, remote, dlc)
    fields.append((int.from_bytes(data, "big"), 8 * len(data)))
    value, width = _pack(fields)
    stuffed_span = format((value << CRC_BITS) | crc15(value, width), f"0{width + CRC_BITS}b")
    return len(stuffed_span) + stuff_bit_count(stuffed_span) + TRAILER_BITS


def _data_bits(data_len: int) -> int:
    """Data field bits; ValueError past a classic frame's 8 bytes (CAN FD is not counted)."""
    if not 0 <= data_len <= MAX_DATA_BYTES:
        raise ValueError(f"{data_len} data bytes: not a classic CAN frame")
    return 8 * data_len


def unstuffed_bits(extended: bool, data_len: int) -> int:
    """The fewest bits a frame can take: no stuff bits at all. The kernel's
    can_frame_bits(false, is_eff, false, true, len) and canbusload -i; its CAN_FRAME_LEN_MAX is
    the 8-byte extended figure in whole bytes. A remote frame has data_len 0."""
    header = EFF_HEADER_BITS if extended else SFF_HEADER_BITS
    return header + _data_bits(data_len) + CRC_BITS + TRAILER_BITS


def worst_case_bits(extended: bool, data_len: int) -> int:
    """The most bits a frame can take: a stuff bit after the first 5 bits, then after every 4.
    The kernel's can_frame_bits(false, is_eff, true, true, len) and canbusload's default. As in
    the kernel the CRC delimiter sits in the stuffed span here, which changes nothing for classic
    frames (the span is never a multiple of 4 bits long)."""
    header = EFF_HEADER_BITS if extended else SFF_HEADER_BITS
    destuffed = header + _data_bits(data_len) + CRC_BITS + CRC_DELIMITER_BITS
    return destuffed + (destuffed - 1) // 4 + FOOTER_BITS + INTERMISSION_BITS


def frame_bits(frame: CanFrame) -> int:
    """``exact_bits`` of a captured frame, for bus load.

    Error frames count ERROR_FRAME_BITS (0), as in canbusload, whose raw socket never asks for
    error frames (no CAN_RAW_ERR_FILTER), and the kernel, whose drivers count no rx statistics
    for them (commit 676068db69b8): the report carries an error class, not the error flag and
    the cut-off frame that were on the wire, whose lengths it does not give. A remote frame's
    data, if any, is not on the wire (the kernel counts none either, commit 8e674ca74244).
    ValueError for CAN FD frames and for frames no classic controller sends.
    """
    if frame.is_error:
        return ERROR_FRAME_BITS
    if frame.is_fd:
        raise ValueError("CAN FD frame: its bits are not counted (classic CAN only)")
    data = b"" if frame.is_remote else frame.data
    return exact_bits(
        frame.arbitration_id,
        data,
        extended=frame.is_extended,
        remote=frame.is_remote,
        dlc=frame.length,
    )
