"""Realistic EG2 traffic in bulk, for benchmarks: polling and motion, values that change."""

from __future__ import annotations

import random
from collections.abc import Iterator

from decoders import build as b
from decoders.model import CanFrame


def serial_frames(n: int, seed: int = 1) -> Iterator[bytes]:
    """n frames (requests and responses) of a host polling and moving three grippers."""
    rng = random.Random(seed)
    s = b.serial_frame
    count = 0
    while count < n:
        dev = rng.randint(1, 3)
        pos = rng.randint(0, 1000)
        kind = rng.random()
        if kind < 0.45:
            yield s(dev, 0x41)
            yield s(
                dev,
                0x41,
                bytes((rng.randint(1, 6), 0, rng.randint(30, 45))) + b.u16le(pos, 100),
                response=True,
            )
        elif kind < 0.8:
            yield s(dev, 0xD9)
            yield s(dev, 0xD9, b.u16le(pos), response=True)
        elif kind < 0.9:
            yield s(dev, 0x10, b.u16le(rng.randint(100, 1000), rng.randint(50, 1000)))
            yield s(dev, 0x10, b"\x01", response=True)
        else:
            yield s(dev, 0x54, b.u16le(pos))
            yield s(dev, 0x54, b"\x01", response=True)
        count += 2


def modbus_frames(n: int, seed: int = 2) -> Iterator[bytes]:
    rng = random.Random(seed)
    count = 0
    while count < n:
        dev = rng.randint(1, 3)
        kind = rng.random()
        if kind < 0.7:
            yield b.modbus_read_request(dev, 1061, 5)
            yield b.modbus_read_response(
                dev,
                [
                    rng.randint(0, 1000),
                    rng.randint(-50, 400),
                    rng.randint(30, 45),
                    0,
                    rng.randint(1, 6),
                ],
            )
        elif kind < 0.85:
            frame = b.modbus_write_single(dev, 1010, rng.randint(0, 1000))
            yield frame
            yield frame
        else:
            yield b.modbus_write_multiple(dev, 1010, [rng.randint(0, 1000), 500, 500])
            yield b.modbus_write_multiple_response(dev, 1010, 3)
        count += 2


def can_frames(n: int, seed: int = 3, t0: float = 1_763_700_000.0) -> Iterator[CanFrame]:
    """Polling at ~8k frames/s of bus time, as on a busy 1 Mbit/s bus."""
    rng = random.Random(seed)
    t = t0
    count = 0
    while count < n:
        dev = rng.randint(1, 3)
        t += 0.0001
        kind = rng.random()
        if kind < 0.5:
            yield b.can_read_request(dev, 1120, 8, t=t)
            t += 0.0001
            data = b.u16le(rng.randint(0, 1000), rng.randint(0, 1000), rng.randint(0, 400), 36)
            yield b.can_read_response(dev, 1120, data, t=t)
        elif kind < 0.85:
            yield b.can_read_request(dev, 1128, 4, t=t)
            t += 0.0001
            yield b.can_read_response(dev, 1128, b.u16le(0, rng.randint(1, 6)), t=t)
        else:
            yield b.can_write_request(dev, 1020, b.u16le(rng.randint(0, 1000), 500, 500), t=t)
            t += 0.0001
            yield b.can_write_response(dev, 1020, 6, t=t)
        count += 2
