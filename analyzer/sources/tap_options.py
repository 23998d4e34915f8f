"""The taps a live command's source options ask for (live, record, bridge, plot, tui), made from
those options typed: CAN, serial, pair, bridge, and waiting for a device.

CAN options are python-can's own, completed from python-can's configuration
(``CAN_INTERFACE``/``CAN_CHANNEL``, ``~/can.ini``) as ``can.logger`` does; serial ports are
pyserial names or URLs. Several sources may be given at once (a CAN bus and a serial line,
say). Options that can never work (an unknown interface, a malformed channel, no source at
all) are usage errors here, before anything is opened.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import can

from ..errors import UsageError
from .live import Tap
from .naming import BUS_BY_PROTOCOL, UNNAMED


@dataclass(frozen=True)
class TapOptions:
    """A live command's source options, typed. ``can``: the CAN options given, by python-can's
    names (interface, channel, bitrate, fd, data_bitrate, timing); ``bus_kwargs``: more of the
    CAN bus's arguments; ``serial``: the ports to watch (one, or one per RS232 wire);
    ``bridge``: the host's and the gripper's ports of an inline tap; ``rts``/``dtr``: the
    serial modem lines' state (True: high); ``protocol``: the serial protocol (None: detected);
    ``bus``: the bus name in records; ``wait``: wait for a device that is not there yet."""

    can: dict[str, Any] = field(default_factory=dict)
    bus_kwargs: dict[str, Any] = field(default_factory=dict)
    serial: tuple[str, ...] = ()
    baud: int = 115200
    rts: bool = False
    dtr: bool = False
    bridge: tuple[str, str] | None = None
    protocol: str | None = None
    bus: str | None = None
    wait: bool = False

    @property
    def given(self) -> bool:
        """Whether the options name any source."""
        return bool(self.can or self.bus_kwargs or self.serial or self.bridge)


def can_bus_config(opts: TapOptions) -> dict[str, Any] | None:
    """The CAN bus the options ask for (python-can's configuration filling in what is not
    given), or None when no CAN option was given."""
    given = dict(opts.can)
    if not given and not opts.bus_kwargs:
        return None
    try:
        config: dict[str, Any] = dict(can.util.load_config(config=given))
    except (can.CanInterfaceNotImplementedError, ValueError, TypeError) as exc:
        known = ", ".join(sorted(can.VALID_INTERFACES))
        if "interface" not in given:
            raise UsageError(
                "a CAN source needs an interface: -i NAME (or python-can's configuration: "
                f"CAN_INTERFACE, ~/can.ini); python-can has: {known}"
            ) from None
        raise UsageError(f"bad CAN options: {exc}") from None
    if config.get("channel") is None:
        raise UsageError("a CAN source needs a channel: -c NAME (e.g. -i socketcan -c can0)")
    config.update(opts.bus_kwargs)
    return config


def serial_bus_name(opts: TapOptions) -> str | None:
    """``bus``, else the name of the protocol given; None: named by the protocol detected
    (sources/naming.py)."""
    if opts.bus:
        return opts.bus
    return None if opts.protocol is None else BUS_BY_PROTOCOL.get(opts.protocol)


def named_serial_tap(tap: Tap, name: str | None) -> Tap:
    """``tap``, marked to be named by its protocol when ``name`` is None."""
    tap.named_by_protocol = name is None
    return tap


def make_taps(opts: TapOptions) -> list[Tap]:
    """The taps the options ask for. UsageError (a ValueError) with a clear message when they
    ask for none, or for something that can never work; nothing is opened yet."""
    taps = can_taps(opts) + serial_taps(opts)
    if not taps:
        raise UsageError(
            "no source given: use -i/-c for CAN, --serial PORT, or --bridge "
            "HOST_PORT DEVICE_PORT (see --help)"
        )
    return taps


def can_taps(opts: TapOptions) -> list[Tap]:
    """The CAN tap the options ask for, if any."""
    from .can_tap import CanTap

    config = can_bus_config(opts)
    if config is None:
        return []
    interface, channel = config.pop("interface"), config.pop("channel")
    bitrate = config.pop("bitrate", None)
    can_bus = opts.bus or str(channel)
    return [CanTap(can_bus, interface, channel, bitrate, wait=opts.wait, **config)]


def serial_taps(opts: TapOptions) -> list[Tap]:
    """The serial taps the options ask for: a port or a pair of ports, and an inline bridge."""
    from .serial_tap import SerialBridge, SerialPairTap, SerialTap

    name = serial_bus_name(opts)
    bus, ports, baud = name or UNNAMED, opts.serial, opts.baud
    rts, dtr, wait = opts.rts, opts.dtr, opts.wait
    taps: list[Tap] = []
    if len(ports) == 1:
        taps.append(SerialTap(bus, ports[0], baud, rts=rts, dtr=dtr, wait=wait))
    elif len(ports) == 2:
        taps.append(SerialPairTap(bus, ports, baud, rts=rts, dtr=dtr, wait=wait))
    elif len(ports) > 2:
        raise UsageError(
            "--serial takes one port (RS485, or both directions on one wire) or "
            "two (one adapter per RS232 wire)"
        )
    if opts.bridge:
        host, device = opts.bridge
        taps.append(SerialBridge(bus, host, device, baud, rts=rts, dtr=dtr, wait=wait))
    return [named_serial_tap(tap, name) for tap in taps]
