"""A host and its grippers on one bus, written frame by frame with the project's frame encoders
(decoders/build.py), for the grip-cycle tests: commands and their answers, polls and the
readings they bring back, on each of the three protocols; then replayed through a real session
(either engine) into the cycles listener.

The same script reads alike on every protocol: ``catch``, ``release``, ``seek`` (Modbus and CAN:
writes of the target opening 0, 1000 or the position), ``stop``, and ``poll`` of what the host
reads (serial: the run state ``41`` for state, fault and opening, ``D9`` for the opening alone,
``14`` for the opening and force; Modbus: registers 1060-1065; CAN: 1120 and 1128).
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

from analyzer.cycles.listener import CyclesListener
from analyzer.cycles.model import Cycle
from analyzer.cycles.outputs import CycleOutput
from analyzer.model import Item
from analyzer.session.session import Session, SessionOptions
from analyzer.sources.source import Source
from decoders import build as b
from decoders.eg2_serial import Cmd
from decoders.model import EG2_CAN, EG2_SERIAL, MODBUS_RTU, Chunk

PROTOCOLS = (EG2_SERIAL, MODBUS_RTU, EG2_CAN)
BROADCAST = {EG2_SERIAL: 255, MODBUS_RTU: 0, EG2_CAN: 0x3FFF}
BUS = {EG2_SERIAL: "rs232", MODBUS_RTU: "rs485", EG2_CAN: "can0"}
GAP_S = 0.006  # between one exchange and the next (the manual's 5 ms, and some)
ANSWER_S = 0.0005


@dataclass
class Script:
    """Frames of one bus, each with its time. ``seq``: the record number the next frame gets
    (one record per frame: the scripts hold no damage)."""

    protocol: str
    t: float = 1000.0
    frames: list[tuple[float, Any]] = field(default_factory=list)

    @property
    def bus(self) -> str:
        return BUS[self.protocol]

    @property
    def seq(self) -> int:
        return len(self.frames)

    def wait(self, s: float) -> Script:
        self.t += s
        return self

    # -- commands ---------------------------------------------------------------------------

    def catch(self, device: int = 1, answer: str = "ok", continuous: bool = False) -> int:
        """Close with the force limit (Modbus, CAN: write target 0, speed and force)."""
        if self.protocol == EG2_SERIAL:
            cmd = Cmd.MOVE_CATCH2_XG if continuous else Cmd.MOVE_CATCH_XG
            return self._serial(device, cmd, b.u16le(500, 100), answer)
        return self._write(device, [0, 500, 100], answer)

    def release(self, device: int = 1, answer: str = "ok") -> int:
        if self.protocol == EG2_SERIAL:
            return self._serial(device, Cmd.MOVE_RELEASE, b.u16le(500), answer)
        return self._write(device, [1000, 500, 100], answer)

    def seek(self, position: int, device: int = 1, answer: str = "ok") -> int:
        if self.protocol == EG2_SERIAL:
            return self._serial(device, Cmd.SEEKPOS, b.u16le(position), answer)
        return self._write(device, [position], answer)

    def stop(self, device: int = 1, answer: str = "ok") -> int:
        if self.protocol == EG2_SERIAL:
            return self._serial(device, Cmd.MOVE_STOPHERE, b"", answer)
        if self.protocol == MODBUS_RTU:
            return self._modbus_write(device, 1006, [1], answer)
        return self._can_write(device, 1012, [1], answer)

    def _write(self, device: int, values: list[int], answer: str) -> int:
        if self.protocol == MODBUS_RTU:
            return self._modbus_write(device, 1010, values, answer)
        return self._can_write(device, 1020, values, answer)

    # -- polls ------------------------------------------------------------------------------

    def poll(
        self,
        device: int = 1,
        state: int | None = None,
        opening: int | None = None,
        force: int | None = None,
        fault: int = 0,
    ) -> int:
        """The host reads what is given (None: not read); the seq of the response that
        carries the state (without one: of the last frame)."""
        if self.protocol == EG2_SERIAL:
            return self._serial_poll(device, state, opening, force, fault)
        if self.protocol == MODBUS_RTU:
            return self._modbus_poll(device, state, opening, force, fault)
        return self._can_poll(device, state, opening, force, fault)

    def _serial_poll(
        self, device: int, state: int | None, opening: int | None, force: int | None, fault: int
    ) -> int:
        last = None
        if state is not None:
            data = bytes((state, fault, 35)) + b.u16le(opening or 0, 100)
            last = 1 + self._exchange(
                b.serial_frame(device, Cmd.READ_EG_RUNSTATE),
                b.serial_frame(device, Cmd.READ_EG_RUNSTATE, data, response=True),
            )
        if force is not None:
            data = b.u16le(opening or 0, force, 100)
            self._exchange(
                b.serial_frame(device, Cmd.READ_EG_STATE),
                b.serial_frame(device, Cmd.READ_EG_STATE, data, response=True),
            )
        elif opening is not None and state is None:
            self._exchange(
                b.serial_frame(device, Cmd.READ_ACTPOS),
                b.serial_frame(device, Cmd.READ_ACTPOS, b.u16le(opening), response=True),
            )
        return self.seq - 1 if last is None else last

    def _modbus_poll(
        self, device: int, state: int | None, opening: int | None, force: int | None, fault: int
    ) -> int:
        """Force alone (1060), then the opening and the state in one read (1061-1065, as
        hosts read them), or either alone."""
        if force is not None:
            self._modbus_read(device, 1060, [force])
        if opening is not None and state is not None:
            self._modbus_read(device, 1061, [opening, 0, 35, fault, state])
        elif opening is not None:
            self._modbus_read(device, 1061, [opening])
        elif state is not None:
            self._modbus_read(device, 1064, [fault, state])
        return self.seq - 1

    def _can_poll(
        self, device: int, state: int | None, opening: int | None, force: int | None, fault: int
    ) -> int:
        if force is not None or opening is not None:
            # 1120: force, opening, current, temperature (8 bytes); 1122: the opening alone
            address, data = 1120, b.u16le(force or 0, opening or 0, 0, 35)
            if force is None:
                address, data = 1122, data[2:4]
            elif opening is None:
                data = data[:2]
            self._exchange(
                b.can_read_request(device, address, len(data)),
                b.can_read_response(device, address, data),
            )
        if state is not None:
            self._exchange(
                b.can_read_request(device, 1128, 4),
                b.can_read_response(device, 1128, b.u16le(fault, state)),
            )
        return self.seq - 1

    # -- frames -----------------------------------------------------------------------------

    def _serial(self, device: int, cmd: int, data: bytes, answer: str) -> int:
        status = {"ok": b"\x01", "refused": b"\x55"}.get(answer)
        reply = None if status is None else b.serial_frame(device, cmd, status, response=True)
        return self._exchange(b.serial_frame(device, cmd, data), reply)

    def _modbus_write(self, device: int, start: int, values: list[int], answer: str) -> int:
        if len(values) == 1:
            request = b.modbus_write_single(device, start, values[0])
            ok, function = request, 6
        else:
            request = b.modbus_write_multiple(device, start, values)
            ok, function = b.modbus_write_multiple_response(device, start, len(values)), 0x10
        reply = {"ok": ok, "refused": b.modbus_exception(device, function, 4)}.get(answer)
        return self._exchange(request, reply)

    def _modbus_read(self, device: int, start: int, values: list[int]) -> None:
        self._exchange(
            b.modbus_read_request(device, start, len(values)),
            b.modbus_read_response(device, values),
        )

    def _can_write(self, device: int, address: int, values: list[int], answer: str) -> int:
        data = b.u16le(*values)
        reply = b.can_write_response(device, address, len(data)) if answer == "ok" else None
        return self._exchange(b.can_write_request(device, address, data), reply)

    def _exchange(self, request: Any, response: Any | None) -> int:
        """A request and its answer (None: none comes); the request's seq."""
        seq = self.seq
        self.frames.append((self.t, request))
        if response is not None:
            self.frames.append((self.t + ANSWER_S, response))
        self.t += GAP_S
        return seq

    # -- replay -----------------------------------------------------------------------------

    def items(self) -> list[Item]:
        out = []
        for t, frame in self.frames:
            if self.protocol == EG2_CAN:
                frame.t = t
                out.append(Item(self.bus, frame))
            else:
                out.append(Item(self.bus, Chunk(frame, t)))
        return out

    def cycles(self, engine: str = "python", size: int = 7) -> list[Cycle]:
        """The cycles a session on ``engine`` finds in the script (``size``: items a batch)."""
        return replay(self.items(), self.protocol, engine, size)


class Kept(CycleOutput):
    """Cycles kept in a list."""

    def __init__(self) -> None:
        self.cycles: list[Cycle] = []

    def write(self, cycles: list[Cycle]) -> None:
        self.cycles += cycles


class Replay(Source):
    """Items, in batches of ``size`` (a command and its readings may fall in different ones)."""

    def __init__(self, items: list[Item], kind: str, size: int) -> None:
        self.items = items
        self.kind = kind
        self.size = size

    def batches(self, stop: threading.Event) -> Iterator[list[Any]]:
        for i in range(0, len(self.items), self.size):
            yield self.items[i : i + self.size]


def replay(items: list[Item], protocol: str, engine: str = "python", size: int = 7) -> list[Cycle]:
    """The cycles of ``items`` of one bus speaking ``protocol``, through a real session."""
    kept = Kept()
    can = protocol == EG2_CAN
    options = SessionOptions(protocol=None if can else protocol, engine=engine)
    source = Replay(items, "can" if can else "bytes", size)
    Session(source, [CyclesListener(kept)], options).run()
    return kept.cycles
