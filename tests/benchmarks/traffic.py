"""Realistic EG2 traffic in bulk, for benchmarks.

Each gripper is a small state machine: it idles (answering the same readings), then moves toward
a new target a little per poll (the opening changes, the force rises on contact, the state goes
closing -> stopped by the force limit -> opening -> open), as a real gripper reports itself. The
host honours the manual's timing: on CAN, enough grippers share the bus that each one is polled
at most every 5 ms while the bus runs near saturation (about 8-10k frames/s).
"""

from __future__ import annotations

import random
from collections.abc import Iterator

from decoders import build as b
from decoders.model import CanFrame


class Gripper:
    """Opening 0-1000, force, state 1-6, temperature: what a poll reads back."""

    def __init__(self, rng: random.Random) -> None:
        self.rng = rng
        self.opening = 1000
        self.target = 1000
        self.force = 0
        self.state = 1
        self.temperature = 35
        self.idle = rng.randint(5, 40)

    def step(self) -> None:
        rng = self.rng
        if self.opening != self.target:
            delta = max(-25, min(25, self.target - self.opening))
            self.opening += delta
            self.state = 4 if delta < 0 else 5
            self.force = 0
            if self.opening == self.target:
                closing = delta < 0 and self.target > 0
                self.state = 6 if closing else (1 if self.opening == 1000 else 3)
                self.force = rng.choice((100, 300, 500)) if closing else 0
                self.idle = rng.randint(5, 40)
        elif self.idle:
            self.idle -= 1
        else:
            self.target = 1000 if self.opening < 1000 else rng.randint(200, 700)
        if rng.random() < 0.001:
            self.temperature = min(60, self.temperature + 1)

    @property
    def current(self) -> int:
        return 300 if self.state in (4, 5) else (150 if self.state == 6 else -2)


def serial_frames(n: int, seed: int = 1, devices: int = 3) -> Iterator[bytes]:
    """n frames (requests and responses): a host polling and moving grippers on RS232."""
    rng = random.Random(seed)
    grippers = [Gripper(rng) for _ in range(devices)]
    s = b.serial_frame
    count = 0
    while count < n:
        dev = count // 2 % devices
        g = grippers[dev]
        target_before = g.target
        g.step()
        dev += 1
        if g.target != target_before:  # a new move: catch or release
            if g.target < g.opening:
                yield s(dev, 0x10, b.u16le(500, 100))
                yield s(dev, 0x10, b"\x01", response=True)
            else:
                yield s(dev, 0x11, b.u16le(500))
                yield s(dev, 0x11, b"\x01", response=True)
        elif count // 2 % 4 == 0:
            yield s(dev, 0xD9)
            yield s(dev, 0xD9, b.u16le(g.opening), response=True)
        else:
            yield s(dev, 0x41)
            data = bytes((g.state, 0, g.temperature)) + b.u16le(g.opening, 100)
            yield s(dev, 0x41, data, response=True)
        count += 2


def modbus_frames(n: int, seed: int = 2, devices: int = 3) -> Iterator[bytes]:
    """n frames on RS485: polls of 1061-1065 and writes of the target."""
    rng = random.Random(seed)
    grippers = [Gripper(rng) for _ in range(devices)]
    count = 0
    while count < n:
        dev = count // 2 % devices
        g = grippers[dev]
        target_before = g.target
        g.step()
        dev += 1
        if g.target != target_before:
            frame = b.modbus_write_single(dev, 1010, g.target)
            yield frame
            yield frame
        else:
            yield b.modbus_read_request(dev, 1061, 5)
            values = [g.opening, g.current, g.temperature, 0, g.state]
            yield b.modbus_read_response(dev, values)
        count += 2


def can_frames(
    n: int, seed: int = 3, t0: float = 1_763_700_000.0, devices: int = 24
) -> Iterator[CanFrame]:
    """A saturated bus: each of ``devices`` grippers polled in turn (1120 x8, 1128 x4), one
    frame every ~0.12 ms, so each gripper sees a command about every 6 ms."""
    rng = random.Random(seed)
    grippers = [Gripper(rng) for _ in range(devices)]
    t = t0
    count = 0
    turn = 0
    while count < n:
        dev = turn % devices
        turn += 1
        g = grippers[dev]
        target_before = g.target
        g.step()
        dev += 1
        t += 0.00012
        if g.target != target_before:
            yield b.can_write_request(dev, 1020, b.u16le(g.target, 500, 500), t=t)
            t += 0.00012
            yield b.can_write_response(dev, 1020, 6, t=t)
        elif turn // devices % 2:
            yield b.can_read_request(dev, 1120, 8, t=t)
            t += 0.00012
            data = b.u16le(g.force, g.opening, g.current, g.temperature)
            yield b.can_read_response(dev, 1120, data, t=t)
        else:
            yield b.can_read_request(dev, 1128, 4, t=t)
            t += 0.00012
            yield b.can_read_response(dev, 1128, b.u16le(0, g.state), t=t)
        count += 2


UNDOCUMENTED_CAN_ADDRESS = 1200  # in no register of the manual's map


def warning_can_frames(
    n: int, seed: int = 4, t0: float = 1_763_700_000.0, devices: int = 4
) -> Iterator[CanFrame]:
    """A host that breaks the manual's rules on every command: ``devices`` grippers addressed in
    turn 0.25 ms apart (each sees a command every ``devices`` x 0.25 ms, well inside the 5 ms
    the manual asks for), interleaving polls of 1120 and 1128, moves written at 1020,
    broadcast writes (device 16383, unanswered) and reads of an undocumented address. Every
    request draws at least one warning; the replies still carry readings to plot."""
    rng = random.Random(seed)
    grippers = [Gripper(rng) for _ in range(devices)]
    t = t0
    count = 0
    turn = 0
    while count < n:
        dev = turn % devices
        kind = turn // devices % 5
        turn += 1
        g = grippers[dev]
        g.step()
        dev += 1
        t += 0.00025
        answer = t + 0.0001
        if kind == 0:
            yield b.can_read_request(dev, 1120, 8, t=t)
            data = b.u16le(g.force, g.opening, g.current, g.temperature)
            yield b.can_read_response(dev, 1120, data, t=answer)
        elif kind == 1:
            yield b.can_read_request(dev, 1128, 4, t=t)
            yield b.can_read_response(dev, 1128, b.u16le(0, g.state), t=answer)
        elif kind == 2:
            yield b.can_write_request(dev, 1020, b.u16le(g.target, 500, 500), t=t)
            yield b.can_write_response(dev, 1020, 6, t=answer)
        elif kind == 3:
            yield b.can_write_request(0x3FFF, 1020, b.u16le(g.target, 500, 500), t=t)
            count -= 1  # nobody answers a broadcast
        else:
            yield b.can_read_request(dev, UNDOCUMENTED_CAN_ADDRESS, 2, t=t)
            yield b.can_read_response(dev, UNDOCUMENTED_CAN_ADDRESS, b.u16le(7), t=answer)
        count += 2
