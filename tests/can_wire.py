"""A CAN frame's bits on the wire, counted a second way for the tests (decoders/can_bits.py is
the first): the frame written as a string of named fields, ISO 11898-1's bit-serial CRC-15
shift register (no table, no crcmod), the stuff bits inserted into the string. Shares no code
with decoders/can_bits.py or native/src/decoders/can_bits.rs."""

from __future__ import annotations


def reference_unstuffed(aid: int, extended: bool, remote: bool, dlc: int, data: bytes) -> str:
    """SOF through the data field, "0" dominant, written field by field from ISO 11898-1."""
    rtr = "1" if remote else "0"
    if extended:
        base, extension = divmod(aid, 1 << 18)
        # SOF, base id, SRR=1, IDE=1, id extension, RTR, r1=0, r0=0, DLC
        head = "0" + f"{base:011b}" + "1" + "1" + f"{extension:018b}" + rtr + "0" + "0"
    else:
        # SOF, id, RTR, IDE=0, r0=0, DLC
        head = "0" + f"{aid:011b}" + rtr + "0" + "0"
    payload = "" if remote else "".join(f"{byte:08b}" for byte in data)
    return head + f"{dlc:04b}" + payload


def reference_crc(bits: str) -> int:
    """ISO 11898-1's CRC-15 shift register, one bit at a time."""
    register = 0
    for bit in bits:
        feedback = int(bit) ^ (register >> 14)
        register = (register << 1) & 0x7FFF
        if feedback:
            register ^= 0x4599
    return register


def reference_stuff(bits: str) -> str:
    """``bits`` as sent: after every 5 equal bits (stuff bits among them) their complement."""
    sent = ""
    for bit in bits:
        sent += bit
        if sent[-5:] in ("00000", "11111"):
            sent += "1" if bit == "0" else "0"
    return sent


def reference_wire(aid: int, extended: bool, remote: bool, dlc: int, data: bytes) -> str:
    """SOF through the CRC sequence as sent, stuff bits included."""
    unstuffed = reference_unstuffed(aid, extended, remote, dlc, data)
    return reference_stuff(unstuffed + f"{reference_crc(unstuffed):015b}")


def reference_bits(aid: int, extended: bool, remote: bool, dlc: int, data: bytes) -> int:
    # + CRC delimiter, ACK slot, ACK delimiter, 7 EOF, 3 intermission
    return len(reference_wire(aid, extended, remote, dlc, data)) + 13
