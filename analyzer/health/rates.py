"""The bit rate of each CAN bus and the baud of each serial line, and where each figure came
from: an option (``--bitrate``, ``--baud``), the capture (a recording's metadata says what each
tap was opened at), or the EG2's default (500 kbit/s on CAN, 115200 baud on serial)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Final

DEFAULT_BITRATE: Final = 500_000  # the EG2-4X0's CAN bit rate (docs/protocol.md)
DEFAULT_BAUD: Final = 115_200  # the EG2's serial default (register 1004 = 0)

# where a rate came from, as the output says it
FROM_OPTION_BITRATE: Final = "--bitrate"
FROM_OPTION_BAUD: Final = "--baud"
FROM_CAPTURE: Final = "recording"
FROM_DEFAULT: Final = "default"


@dataclass(frozen=True)
class Rate:
    """Bits per second (a CAN bit rate or a baud), and where the figure came from."""

    value: int
    source: str


@dataclass(frozen=True)
class RateOptions:
    """The rates the options give a capture's buses (``--bitrate``, ``--baud``), each for every
    bus of its kind; None: not given (the capture's own, else the default)."""

    bitrate: int | None = None
    baud: int | None = None


@dataclass(frozen=True)
class BusRates:
    """The rate of every bus: an option's for all buses of its kind, else the capture's for the
    bus (``known``), else the default. ``ports``: each serial bus's device, where known."""

    bitrate: int | None = None
    baud: int | None = None
    known: Mapping[str, int] = field(default_factory=dict)
    ports: Mapping[str, str] = field(default_factory=dict)

    def can(self, bus: str) -> Rate:
        return self._rate(bus, self.bitrate, FROM_OPTION_BITRATE, DEFAULT_BITRATE)

    def serial(self, bus: str) -> Rate:
        return self._rate(bus, self.baud, FROM_OPTION_BAUD, DEFAULT_BAUD)

    def _rate(self, bus: str, option: int | None, said: str, default: int) -> Rate:
        if option is not None:
            return Rate(option, said)
        if bus in self.known:
            return Rate(self.known[bus], FROM_CAPTURE)
        return Rate(default, FROM_DEFAULT)


def rates_of_capture(
    metadata: Mapping[str, Any], bitrate: int | None = None, baud: int | None = None
) -> BusRates:
    """The rates a capture's metadata gives its buses (a recording's ``sources``: each tap's
    ``bus`` and ``bitrate`` or ``baudrate``; a virtual CAN bus has none; other captures say
    nothing), under the options given."""
    known: dict[str, int] = {}
    ports: dict[str, str] = {}
    sources = metadata.get("sources")
    for source in sources if isinstance(sources, list) else []:
        if not isinstance(source, dict) or not isinstance(source.get("bus"), str):
            continue  # a serial tap named after its protocol later has no name here
        bus = source["bus"]
        rate = source.get("bitrate", source.get("baudrate"))
        if isinstance(rate, int) and not isinstance(rate, bool) and rate > 0:
            known[bus] = rate
        if isinstance(source.get("port"), str):
            ports[bus] = source["port"]
    return BusRates(bitrate, baud, known, ports)
