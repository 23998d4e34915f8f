"""Source options shared by the live commands (live, record): CAN, serial, pair, bridge.

CAN options are python-can's, as ``can.logger`` takes them; serial ports are pyserial names or
URLs. Several sources may be given at once (a CAN bus and a serial line, say).
"""

from __future__ import annotations

import argparse
from typing import Any

from decoders.registry import resolve_protocol

from ..sources.live import Tap


def add_source_arguments(parser: argparse.ArgumentParser, bridge: bool = True) -> None:
    can = parser.add_argument_group("CAN source (python-can)")
    can.add_argument(
        "-i",
        "--interface",
        metavar="NAME",
        help="python-can interface: socketcan, pcan, kvaser, vector, slcan, "
        "virtual, ... (listen-only is requested where the interface allows)",
    )
    can.add_argument("-c", "--channel", metavar="CH", help="CAN channel, e.g. can0, PCAN_USBBUS1")
    can.add_argument(
        "-b",
        "--bitrate",
        type=int,
        metavar="BPS",
        help="bit rate (the EG2 uses 500000); leave unset to keep the bus's own",
    )
    can.add_argument(
        "--can-option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="extra python-can bus argument (repeatable)",
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
    if bridge:
        ser.add_argument(
            "--bridge",
            nargs=2,
            metavar=("HOST_PORT", "DEVICE_PORT"),
            help="inline tap: relay between the host's port and the gripper's "
            "port and decode both directions (not passive: it is in the line)",
        )
    parser.add_argument(
        "--protocol",
        "-p",
        default="auto",
        metavar="NAME",
        help="serial protocol: serial, modbus or auto (default: detected)",
    )
    parser.add_argument(
        "--bus",
        metavar="NAME",
        help="bus name in records (default: the CAN "
        "channel, 'rs232'/'rs485' style names for serial)",
    )


def parse_can_options(pairs: list[str]) -> dict[str, Any]:
    opts: dict[str, Any] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise ValueError(f"--can-option wants KEY=VALUE, got {pair!r}")
        low = value.lower()
        opts[key] = (
            True
            if low == "true"
            else False
            if low == "false"
            else int(value)
            if value.lstrip("-").isdigit()
            else value
        )
    return opts


def serial_bus_name(args: argparse.Namespace) -> str:
    if args.bus:
        return str(args.bus)
    protocol = None if args.protocol == "auto" else resolve_protocol(args.protocol)
    return {"modbus-rtu": "rs485", "eg2-serial": "rs232"}.get(protocol or "", "serial")


def open_taps(args: argparse.Namespace) -> list[Tap]:
    """The taps the options ask for; ValueError with a clear message when they ask for none."""
    from ..sources.can_tap import CanTap
    from ..sources.serial_tap import SerialBridge, SerialPairTap, SerialTap

    taps: list[Tap] = []
    if args.interface or args.channel:
        if not (args.interface and args.channel):
            raise ValueError(
                "a CAN source needs both --interface and --channel (e.g. -i socketcan -c can0)"
            )
        taps.append(
            CanTap(
                args.bus or args.channel,
                args.interface,
                args.channel,
                bitrate=args.bitrate,
                **parse_can_options(args.can_option),
            )
        )
    ports = list(args.serial)
    if len(ports) == 1:
        taps.append(SerialTap(serial_bus_name(args), ports[0], baudrate=args.baud))
    elif len(ports) == 2:
        taps.append(SerialPairTap(serial_bus_name(args), ports, baudrate=args.baud))
    elif len(ports) > 2:
        raise ValueError(
            "--serial takes one port (RS485, or both directions on one wire) or "
            "two (one adapter per RS232 wire)"
        )
    if getattr(args, "bridge", None):
        host, device = args.bridge
        taps.append(SerialBridge(serial_bus_name(args), host, device, baudrate=args.baud))
    if not taps:
        raise ValueError(
            "no source given: use -i/-c for CAN, --serial PORT, or --bridge "
            "HOST_PORT DEVICE_PORT (see --help)"
        )
    return taps
