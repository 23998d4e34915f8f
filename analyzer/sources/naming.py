"""Live serial buses named by their protocol, as the EG2 speaks them: ``rs232`` for the regular
serial protocol, ``rs485`` for Modbus RTU.

A serial tap whose protocol is given is named when it is made (``BUS_BY_PROTOCOL``). One whose
protocol is detected (``--protocol auto`` and no ``--bus``: ``Tap.named_by_protocol``) cannot
be: its items are held here, in order, until its bytes show a protocol (the first valid frame,
by ``decoders.registry.detect_protocol``, as the decoding detects it live), then released under
its name after an event saying so; later items and events are renamed on the way. Its events
meanwhile (passive, opened, waiting for the port) are passed on at once under ``UNNAMED``, so a
person sees them as they happen, except a loss or a close: those decide the name first (the bytes
before them end there, under the bus's name). A line that shows no frame in ``DETECT_BYTES``
bytes, or by a loss or the end, is named as the decoding decides such a line (the regular serial
protocol); a tap that captured nothing keeps ``UNNAMED``. The protocol found is handed to the
session (``protocols``), so its decoding uses the protocol the name says.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from typing import Final

from decoders.model import EG2_SERIAL, MODBUS_RTU
from decoders.registry import detect_protocol

from ..model import INFO, Item, SourceEvent
from ..session.stage import DETECT_BYTES
from .live import CLOSED, LOST, Tap

BUS_BY_PROTOCOL: Final = {EG2_SERIAL: "rs232", MODBUS_RTU: "rs485"}
UNNAMED: Final = "serial"  # a tap's bus until its protocol shows
PROTOCOL_WORDS: Final = {EG2_SERIAL: "the regular serial protocol", MODBUS_RTU: "Modbus RTU"}

Held = Item | SourceEvent


class BusNamer:
    """Holds the items and events of the taps to be named, names them, renames what follows."""

    def __init__(self, taps: Iterable[Tap]) -> None:
        self.unnamed: dict[str, Tap] = {t.bus: t for t in taps if t.named_by_protocol}
        self.renamed: dict[str, str] = {}  # provisional bus -> its name
        self.protocols: dict[str, str] = {}  # bus named here -> the protocol it was named for
        self._held: dict[str, list[Item]] = {bus: [] for bus in self.unnamed}
        self._samples: dict[tuple[str, str], bytearray] = {}

    def sort(self, batch: list[Held]) -> list[Held]:
        """``batch`` with the items and events of unnamed buses taken out (held), and those
        of buses named meanwhile released (and renamed)."""
        if not self.unnamed and not self.renamed:
            return batch
        out: list[Held] = []
        grown: set[str] = set()
        for x in batch:
            bus = x.bus
            if bus in self.renamed:
                out.append(_renamed(x, self.renamed[bus]))
            elif bus not in self.unnamed:
                out.append(x)
            elif isinstance(x, Item):
                self._hold(x)
                grown.add(bus)
            elif x.kind in (LOST, CLOSED):  # the bytes before it end here: name them now
                out += self._decide(bus)
                out.append(_renamed(x, self.renamed.get(bus, bus)))
            else:
                out.append(x)
        for bus in grown & set(self.unnamed):
            protocol = self._detected(bus, final=False)
            if protocol is not None:
                out += self._name(bus, protocol)
        return out

    def finish(self) -> list[Held]:
        """The capture ended: every bus still unnamed is named from what it holds."""
        out: list[Held] = []
        for bus in list(self.unnamed):
            out += self._decide(bus)
        return out

    # -- internals -----------------------------------------------------------------------------

    def _decide(self, bus: str) -> list[Held]:
        """Name ``bus`` from what it holds now, if it holds anything; its held items."""
        protocol = self._detected(bus, final=True)
        if protocol is not None:
            return self._name(bus, protocol)
        return []  # nothing captured yet: nothing to name, nothing held

    def _hold(self, x: Item) -> None:
        self._held[x.bus].append(x)
        sample = self._samples.setdefault((x.bus, x.stream), bytearray())
        if len(sample) < DETECT_BYTES:
            sample += x.payload.data

    def _detected(self, bus: str, final: bool) -> str | None:
        """The protocol the bus's bytes show; at ``final`` or with a full sample and no frame,
        the decoding's choice for such a line; None while it cannot tell yet."""
        samples = [s for (b, _), s in self._samples.items() if b == bus and s]
        for sample in samples:
            protocol = detect_protocol(bytes(sample))
            if protocol is not None:
                return protocol
        if samples and (final or any(len(s) >= DETECT_BYTES for s in samples)):
            return EG2_SERIAL
        return None

    def _name(self, bus: str, protocol: str) -> list[Held]:
        tap = self.unnamed.pop(bus)
        name = BUS_BY_PROTOCOL[protocol]
        tap.bus = name
        self.renamed[bus] = name
        self.protocols[name] = protocol
        for key in [k for k in self._samples if k[0] == bus]:
            del self._samples[key]
        held = [Item(name, x.payload, x.stream) for x in self._held.pop(bus)]
        t = held[0].payload.t if held else None  # said where the data begins, at its time
        words = PROTOCOL_WORDS[protocol]
        named = SourceEvent(t or time.time(), name, INFO, f"{words} detected: bus named {name}")
        return [named, *held]


def _renamed(x: Held, bus: str) -> Held:
    if type(x) is Item:
        return Item(bus, x.payload, x.stream)
    assert isinstance(x, SourceEvent)
    return SourceEvent(x.t, bus, x.level, x.message, x.kind, x.count)
