"""The health of one bus, all its figures together as ``stats --format json`` gives them under
``buses`` (docs/contracts.md): the keys every bus has first, then its kind's."""

from __future__ import annotations

import math
from typing import Any, Final

from decoders.can_errors import ERROR_ACTIVE

from .can_load import CanLoad, Second
from .error_frames import ErrorFrameLog
from .rates import Rate
from .seconds import SecondLog
from .serial_line import SerialLine

CAN: Final = "can"
SERIAL: Final = "serial"
NO_TIMING: Final = "no timing in this capture"


class CanBusHealth:
    """A CAN bus: its load and its error frames."""

    kind = CAN

    def __init__(self, bus: str, bitrate: Rate, seconds: bool = False) -> None:
        self.bus = bus
        self.rate = bitrate
        self.load = CanLoad()
        self.errors = ErrorFrameLog()
        self.log = SecondLog(bus, CAN, bitrate.value, ERROR_ACTIVE) if seconds else None

    def add(self, second: Second) -> None:
        """One bus's frames in one second (``can_load.Second``)."""
        self.load.add(second)
        sec = second[1]
        if self.log is not None and sec is not None:
            self.log.frames(sec, second[2], second[3])

    def add_error(self, t: float | None, error_class: int, data: bytes) -> None:
        report = self.errors.add(t, error_class, data)
        if self.log is not None and t is not None:
            self.log.controller(math.floor(t), report)

    @property
    def timing(self) -> str | None:
        """``NO_TIMING`` when the bus's frames have no times (None: timed, or no frames)."""
        timed = self.load.last_t is not None or self.errors.last_t is not None
        return None if timed or not self.load.frames else NO_TIMING

    def figures(self) -> dict[str, Any]:
        load = self.load.figures(self.rate.value)
        return {
            "bus": self.bus,
            "kind": CAN,
            "bitrate": self.rate.value,
            "bitrate_from": self.rate.source,
            "timing": self.timing,
            **load,
            **self.errors.figures(self.load.last_t),
        }


class SerialBusHealth:
    """A serial line: its use, gaps, turnaround and read times."""

    kind = SERIAL

    def __init__(
        self, bus: str, baud: Rate, port: str | None = None, seconds: bool = False
    ) -> None:
        self.bus = bus
        self.rate = baud
        log = SecondLog(bus, SERIAL, baud.value, None) if seconds else None
        self.line = SerialLine(baud.value, port, log)

    @property
    def log(self) -> SecondLog | None:
        return self.line.log

    @property
    def timing(self) -> str | None:
        """``NO_TIMING`` when the line's reads have no times (None: timed, or no bytes)."""
        line = self.line
        return None if line.last_t is not None or not line.bytes else NO_TIMING

    def figures(self) -> dict[str, Any]:
        return {
            "bus": self.bus,
            "kind": SERIAL,
            "baud": self.rate.value,
            "baud_from": self.rate.source,
            "timing": self.timing,
            **self.line.figures(),
        }


BusHealth = CanBusHealth | SerialBusHealth
