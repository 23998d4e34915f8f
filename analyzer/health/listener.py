"""``HealthListener``: the health of every bus of a session, from its raw input (CAN frames,
serial reads with their times) and, for byte streams, the records found in them.

CAN frames are counted a batch at a time by ``can_load.can_seconds``, which takes the native
core's ``FrameBatch`` as it takes a list of Items, so the listener says
``reads_frame_batches``: a candump log is still read natively under it. Records are read only
for serial buses (their frames delimit the gaps and turnaround); a CAN-only session's records,
a native ``RecordBatch``, are never touched.
"""

from __future__ import annotations

from typing import Any

from decoders.model import CanFrame

from ..session.listener import Listener
from .bus import BusHealth, CanBusHealth, SerialBusHealth
from .can_load import can_seconds
from .rates import BusRates
from .seconds import HealthSecond


class HealthListener(Listener):
    wants_raw = True
    reads_frame_batches = True

    def __init__(self, rates: BusRates | None = None, seconds: bool = False) -> None:
        self.rates = rates or BusRates()
        self.seconds = seconds  # keep the second-by-second rows (``take_seconds``)
        self.label = "bus health"
        self.can: dict[str, CanBusHealth] = {}
        self.serial: dict[str, SerialBusHealth] = {}

    def on_raw(self, items: Any) -> None:
        seconds, errors, others = can_seconds(items)
        for second in seconds:
            self._can(second[0]).add(second)
        for bus, t, error_class, data in errors:
            self._can(bus).add_error(t, error_class, data)
        if others:  # byte chunks among the items (never in a native FrameBatch)
            for item in items:
                chunk = item.payload
                if not isinstance(chunk, CanFrame):
                    self._serial(item.bus).line.add_read(item.stream, chunk)

    def on_records(self, records: Any) -> None:
        lines = self.serial
        if not lines:
            return  # CAN records: the frames said it all
        if len(lines) == 1:  # a raw dump's one line takes its untimed records in bulk
            bus, only = next(iter(lines.items()))
            if only.line.untimed and records.count_of("bus", bus) == len(records):
                only.line.add_untimed(records)
                return
        for rec in records:
            health = lines.get(rec.bus)
            if health is not None:
                health.line.add_record(rec)

    def buses(self) -> list[dict[str, Any]]:
        """Every bus's figures, by bus name."""
        every: list[BusHealth] = [*self.can.values(), *self.serial.values()]
        return [b.figures() for b in sorted(every, key=_order)]

    def take_seconds(self, final: bool = False) -> list[HealthSecond]:
        """The seconds every bus has completed since the last call (with ``final``, the open
        ones too: at the end), by bus and second; empty unless made with ``seconds=True``."""
        rows: list[HealthSecond] = []
        every: list[BusHealth] = [*self.can.values(), *self.serial.values()]
        for health in sorted(every, key=_order):
            if health.log is not None:
                rows += health.log.take(final)
        return rows

    def _can(self, bus: str) -> CanBusHealth:
        health = self.can.get(bus)
        if health is None:
            health = self.can[bus] = CanBusHealth(bus, self.rates.can(bus), self.seconds)
        return health

    def _serial(self, bus: str) -> SerialBusHealth:
        health = self.serial.get(bus)
        if health is None:
            rate = self.rates.serial(bus)
            port = self.rates.ports.get(bus)
            health = self.serial[bus] = SerialBusHealth(bus, rate, port, self.seconds)
        return health


def _order(health: BusHealth) -> tuple[str, str]:
    return health.bus, health.kind
