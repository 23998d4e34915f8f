"""Regenerate the sample captures in this folder (deterministic): ``python captures/generate.py``.

Each capture is a short, scripted session that shows one protocol's normal traffic and the
faults a sniffer must report. captures/README.md says what each one shows.
"""

from __future__ import annotations

import random
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from decoders import build as b  # noqa: E402
from decoders.eg2_can import BROADCAST as CAN_BROADCAST  # noqa: E402
from decoders.eg2_serial import BROADCAST as SERIAL_BROADCAST  # noqa: E402
from decoders.eg2_serial import STATUS_FAILED, STATUS_OK, Cmd  # noqa: E402
from decoders.model import CanFrame  # noqa: E402

T0 = 1_763_700_000.0  # a fixed epoch so the files never change


def serial_session() -> bytes:
    """Regular serial protocol: the manual's worked exchanges, then a pick, with faults."""
    s = b.serial_frame
    out = bytearray()

    def ex(dev: int, cmd: int, req: bytes, resp: bytes | None) -> None:
        out.extend(s(dev, cmd, req))
        if resp is not None:
            out.extend(s(dev, cmd, resp, response=True))

    ok, failed = bytes((STATUS_OK,)), bytes((STATUS_FAILED,))
    ex(1, Cmd.READ_EG_RUNSTATE, b"", bytes((1, 0, 35)) + b.u16le(1000, 100))  # open, 35 °C
    ex(1, Cmd.READ_EG_PARA, b"", b.u16le(1000, 112))  # read limits
    ex(1, Cmd.MOVE_CATCH_XG, b.u16le(500, 100), ok)  # catch
    ex(1, Cmd.READ_ACTPOS, b"", b.u16le(497))  # read position
    out.extend(b"\x00\x13\x37\xff")  # line noise
    ex(1, Cmd.READ_ACTPOS, b"", b.u16le(430))
    bad = bytearray(s(1, Cmd.MOVE_RELEASE, b.u16le(500)))
    bad[-1] ^= 0x5A  # corrupted checksum
    out.extend(bad)
    ex(1, Cmd.MOVE_RELEASE, b.u16le(500), ok)  # the host resends: release
    ex(1, Cmd.SET_EG_PARA, b.u16le(1200, 50), failed)  # bad limits refused: failure status
    ex(2, Cmd.READ_EG_RUNSTATE, b"", None)  # ID 2 is not on the bus: no answer
    ex(1, Cmd.SEEKPOS, b.u16le(500), ok)  # seek 35 mm
    ex(1, Cmd.PARA_ID_SET, b.u16le(3), ok)  # set ID with a two-byte value (section 4)
    ex(SERIAL_BROADCAST, Cmd.MOVE_STOPHERE, b"", None)  # broadcast stop: nobody answers
    ex(1, Cmd.READ_EG_STATE, b"", b.u16le(500, 80, 100))  # read state: probable layout
    ex(1, 0x77, b"\x01\x02", ok)  # a command the manual does not list
    run_state = bytes((4, 1, 41)) + b.u16le(600, 100)
    out.extend(s(1, Cmd.READ_EG_RUNSTATE, run_state, response=True)[:9])
    return bytes(out)  # ends with a truncated response


def modbus_session() -> bytes:
    """Modbus RTU: polling, a move, the manual's swapped CRC, short register numbers, faults."""
    out = bytearray()
    out += b.modbus_write_multiple(1, 1010, [0, 1000, 1000])
    out += b.modbus_write_multiple_response(1, 1010, 3)
    for opening, current, temp in ((1000, 0, 36), (720, 310, 36), (400, 305, 37), (0, -2, 37)):
        out += b.modbus_read_request(1, 1061, 5)
        out += b.modbus_read_response(1, [opening, current, temp, 0, 4 if opening else 6])
    out += b.modbus_write_single(1, 1010, 500) * 2  # request and its echo
    out += b.with_crc(bytes.fromhex("01 06 03 F2 00 00"), swapped=True) * 2  # manual's order
    out += b.modbus_write_single(1, 10, 864) * 2  # xArm SDK: short register number 10
    out += b.modbus_read_request(1, 61, 1) + b.modbus_read_response(1, [864])
    out += b"\xff\xff\x00"  # noise on the line
    bad = bytearray(b.modbus_read_request(1, 1061, 4))
    bad[-2:] = b"\x86\x21"  # the manual's wrong CRC
    out += bad
    out += b.modbus_read_request(1, 1008, 1) + b.modbus_exception(1, 3, 2)  # undocumented
    out += b.modbus_write_single(1, 1011, 5000) + b.modbus_exception(1, 6, 3)  # out of range
    out += b.modbus_write_single(2, 1010, 0)  # device 2 is not there: no response
    out += b.modbus_read_request(1, 1061, 5)
    out += b.modbus_read_response(1, [0, 0, 37, 0, 6])[:7]  # capture cut mid-frame
    return bytes(out)


def can_session() -> list[CanFrame]:
    """CAN: two grippers through a pick-and-place cycle, polled, with foreign traffic."""
    rng = random.Random(7)
    frames: list[CanFrame] = []
    t = T0

    def add(frame: CanFrame, dt: float) -> None:
        nonlocal t
        t += dt
        frame.t = round(t, 6)
        frames.append(frame)

    def poll(dev: int, opening: int, force: int, temp: int, state: int) -> None:
        add(b.can_read_request(dev, 1120, 8), 0.006)
        data = b.u16le(force, opening, rng.randint(0, 400), temp)
        add(b.can_read_response(dev, 1120, data), 0.0004 + rng.random() * 0.0002)
        add(b.can_read_request(dev, 1128, 4, padded=dev == 2), 0.006)
        add(b.can_read_response(dev, 1128, b.u16le(0, state)), 0.0004)

    for dev in (1, 2):
        poll(dev, 1000, 0, 33, 1)
    for dev in (1, 2):  # close on the part: target 0, speed 500, force 500
        add(b.can_write_request(dev, 1020, b.u16le(0, 500, 500)), 0.005)
        add(b.can_write_response(dev, 1020, 6), 0.0005)
    for step in range(1, 9):
        for dev in (1, 2):
            opening = max(1000 - step * 140, 310 if dev == 1 else 280)
            state = 6 if opening in (310, 280) else 4
            poll(dev, opening, 480 if state == 6 else 20, 34, state)
        add(CanFrame(None, 0x123, b"\x01\x02\x03", is_extended=False), 0.001)  # someone else
    add(b.can_write_request(1, 1020, b.u16le(1000, 800, 300)), 0.005)  # open device 1
    add(b.can_write_response(1, 1020, 6), 0.0005)
    add(b.can_read_request(3, 1120, 8), 0.004)  # device 3 does not answer
    add(b.can_write_request(CAN_BROADCAST, 1012, b.u16le(1)), 0.02)  # broadcast stop
    add(b.can_read_request(1, 1120, 8), 0.004)
    add(b.can_read_response(1, 1120, bytes.fromhex("F3 00 03 E8 00 00 00 22")), 0.0004)
    add(CanFrame(None, 0x20000080, bytes(8), is_error=True), 0.002)  # error frame
    return frames


def main() -> None:
    (HERE / "serial_session.bin").write_bytes(serial_session())
    (HERE / "modbus_session.bin").write_bytes(modbus_session())
    frames = can_session()
    lines = [b.candump_line(f) for f in frames]
    (HERE / "can_pick_place.log").write_text("\n".join(lines) + "\n")
    print("wrote", ", ".join(p.name for p in sorted(HERE.glob("*_*.*")) if p.suffix != ".py"))


if __name__ == "__main__":
    main()
