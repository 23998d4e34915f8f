"""Source options shared by the live commands (live, record, plot, tui; bridge takes the
serial ones): CAN, serial, pair, bridge, and ``--wait``.

CAN options are python-can's own (``can.cli.add_bus_arguments``: ``-i/-c/-b``, ``--fd``,
``--data-bitrate``, ``--timing``, ``--bus-kwargs KEY=VALUE ...``), completed from python-can's
configuration (``CAN_INTERFACE``/``CAN_CHANNEL``, ``~/can.ini``) as ``can.logger`` does;
serial ports are pyserial names or URLs. Several sources may be given at once (a CAN bus and a
serial line, say). Options that can never work (an unknown interface, an impossible baud rate,
a malformed channel, an unknown protocol) are usage errors here, before anything is opened. A
device that does not open fails the command at once (``SourceError``, exit 1), unless
``--wait`` asks to wait for it.
"""

from __future__ import annotations

import argparse
from typing import Any

import can
import can.cli

from decoders.model import EG2_CAN
from decoders.registry import resolve_protocol

from ..errors import UsageError
from ..sources.live import Tap
from ..sources.naming import BUS_BY_PROTOCOL, UNNAMED

# the namespace keys add_bus_arguments fills (create_bus_from_namespace reads the same)
CAN_KEYS = ("interface", "channel", "bitrate", "fd", "data_bitrate", "timing")
LINE_STATES = {"low": False, "high": True}


def add_source_arguments(parser: argparse.ArgumentParser, bridge: bool = True) -> None:
    can.cli.add_bus_arguments(
        parser,
        group_title="CAN source (python-can; listen-only is requested where the interface "
        "allows; the EG2 uses -b 500000)",
    )
    ser = parser.add_argument_group("serial source (pyserial)")
    ser.add_argument(
        "--serial",
        "-s",
        action="append",
        default=[],
        metavar="PORT",
        help="serial port or pyserial URL to watch (never written to); give it "
        "twice to watch one adapter per RS232 wire",
    )
    ser.add_argument("--baud", type=int, default=115200, help="serial baud rate (default 115200)")
    add_line_arguments(ser)
    if bridge:
        ser.add_argument(
            "--bridge",
            nargs=2,
            metavar=("HOST_PORT", "DEVICE_PORT"),
            help="inline tap: relay between the host's port and the gripper's "
            "port and decode both directions (not passive: it is in the line)",
        )
    add_naming_arguments(parser)
    add_wait_argument(parser)


def serial_protocol_type(text: str) -> str | None:
    """argparse type: a serial line's protocol or "auto" (None: detected); CAN is no choice
    for a serial line."""
    if text.lower() == "auto":
        return None
    try:
        protocol = resolve_protocol(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{exc}, or auto (detected)") from None
    if protocol == EG2_CAN:
        raise argparse.ArgumentTypeError(
            "--protocol is a serial line's: serial, modbus or auto (a CAN source is always CAN)"
        )
    return protocol


def add_naming_arguments(parser: argparse.ArgumentParser, can: bool = True) -> None:
    """``--protocol`` and ``--bus`` of a serial source (``can``: of a CAN one too)."""
    serial = (
        "by protocol: rs232 for the regular serial protocol, rs485 for Modbus RTU, named when "
        "it is detected"
    )
    parser.add_argument(
        "--protocol",
        "-p",
        type=serial_protocol_type,
        default=None,
        metavar="NAME",
        help="serial protocol: serial (the regular serial protocol), modbus (Modbus RTU) or "
        "auto (default: detected from the bytes)",
    )
    parser.add_argument(
        "--bus",
        metavar="NAME",
        help=f"bus name in records (default: the CAN channel; for serial, {serial})"
        if can
        else f"bus name in records (default: {serial})",
    )


def add_wait_argument(parser: Any) -> None:
    parser.add_argument(
        "--wait",
        action="store_true",
        help="wait for a port or CAN interface that is not there yet (an adapter not "
        "plugged in), retrying with back-off; without it a source that does not open "
        "fails at once (exit 1)",
    )


def add_line_arguments(parser: Any) -> None:
    """``--rts``/``--dtr``: the serial modem lines' state from the moment a port opens."""
    for name in ("rts", "dtr"):
        parser.add_argument(
            f"--{name}",
            choices=tuple(LINE_STATES),
            default="low",
            help=f"{name.upper()} line state while the port is open (default low: never "
            "raised, so an RS485 adapter that drives its transmitter from it stays silent)",
        )


def line_states(args: argparse.Namespace) -> tuple[bool, bool]:
    """The serial taps' ``rts`` and ``dtr`` (True: high), from ``--rts``/``--dtr``."""
    return LINE_STATES[getattr(args, "rts", "low")], LINE_STATES[getattr(args, "dtr", "low")]


def can_bus_config(args: argparse.Namespace) -> dict[str, Any] | None:
    """The CAN bus the options ask for (python-can's configuration filling in what is not
    given), or None when no CAN option was given."""
    given = {key: getattr(args, key) for key in CAN_KEYS if key in args}
    bus_kwargs: dict[str, Any] = dict(getattr(args, "bus_kwargs", {}) or {})
    if not given and not bus_kwargs:
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
    config.update(bus_kwargs)
    return config


def serial_bus_name(args: argparse.Namespace) -> str | None:
    """``--bus``, else the name of the protocol given; None: named by the protocol detected
    (sources/naming.py)."""
    if args.bus:
        return str(args.bus)
    return BUS_BY_PROTOCOL.get(args.protocol)


def named_serial_tap(tap: Tap, name: str | None) -> Tap:
    """``tap``, marked to be named by its protocol when ``name`` is None."""
    tap.named_by_protocol = name is None
    return tap


def open_taps(args: argparse.Namespace) -> list[Tap]:
    """The taps the options ask for. UsageError (a ValueError) with a clear message when they
    ask for none, or for something that can never work; nothing is opened yet."""
    from ..sources.can_tap import CanTap
    from ..sources.serial_tap import SerialBridge, SerialPairTap, SerialTap

    taps: list[Tap] = []
    wait = bool(getattr(args, "wait", False))
    config = can_bus_config(args)
    if config is not None:
        interface, channel = config.pop("interface"), config.pop("channel")
        bitrate = config.pop("bitrate", None)
        can_bus = args.bus or str(channel)
        taps.append(CanTap(can_bus, interface, channel, bitrate, wait=wait, **config))
    ports = list(args.serial)
    rts, dtr = line_states(args)
    name = serial_bus_name(args)
    bus = name or UNNAMED
    if len(ports) == 1:
        tap: Tap = SerialTap(bus, ports[0], args.baud, rts=rts, dtr=dtr, wait=wait)
        taps.append(named_serial_tap(tap, name))
    elif len(ports) == 2:
        tap = SerialPairTap(bus, ports, args.baud, rts=rts, dtr=dtr, wait=wait)
        taps.append(named_serial_tap(tap, name))
    elif len(ports) > 2:
        raise UsageError(
            "--serial takes one port (RS485, or both directions on one wire) or "
            "two (one adapter per RS232 wire)"
        )
    if getattr(args, "bridge", None):
        host, device = args.bridge
        tap = SerialBridge(bus, host, device, args.baud, rts=rts, dtr=dtr, wait=wait)
        taps.append(named_serial_tap(tap, name))
    if not taps:
        raise UsageError(
            "no source given: use -i/-c for CAN, --serial PORT, or --bridge "
            "HOST_PORT DEVICE_PORT (see --help)"
        )
    return taps
