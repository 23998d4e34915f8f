"""The health of one bus, all its figures together as ``stats --format json`` gives them under
``buses`` (docs/contracts.md): the keys every bus has first, then its kind's."""

from __future__ import annotations

from typing import Any, Final

from .can_load import CanLoad
from .error_frames import ErrorFrameLog
from .rates import Rate
from .serial_line import SerialLine

CAN: Final = "can"
SERIAL: Final = "serial"
NO_TIMING: Final = "no timing in this capture"


class CanBusHealth:
    """A CAN bus: its load and its error frames."""

    kind = CAN

    def __init__(self, bus: str, bitrate: Rate) -> None:
        self.bus = bus
        self.rate = bitrate
        self.load = CanLoad()
        self.errors = ErrorFrameLog()

    def figures(self) -> dict[str, Any]:
        load = self.load.figures(self.rate.value)
        timed = self.load.last_t is not None or self.errors.last_t is not None
        return {
            "bus": self.bus,
            "kind": CAN,
            "bitrate": self.rate.value,
            "bitrate_from": self.rate.source,
            "timing": None if timed or not self.load.frames else NO_TIMING,
            **load,
            **self.errors.figures(self.load.last_t),
        }


class SerialBusHealth:
    """A serial line: its use, gaps, turnaround and read times."""

    kind = SERIAL

    def __init__(self, bus: str, baud: Rate, port: str | None = None) -> None:
        self.bus = bus
        self.rate = baud
        self.line = SerialLine(baud.value, port)

    def figures(self) -> dict[str, Any]:
        line = self.line
        return {
            "bus": self.bus,
            "kind": SERIAL,
            "baud": self.rate.value,
            "baud_from": self.rate.source,
            "timing": None if line.last_t is not None or not line.bytes else NO_TIMING,
            **line.figures(),
        }


BusHealth = CanBusHealth | SerialBusHealth
