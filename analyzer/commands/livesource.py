"""Source options shared by the live commands (live, record, plot, tui; bridge takes the
serial ones): CAN, serial, pair, bridge, and ``--wait``; ``tap_options`` hands them on typed
(the taps are made from them in analyzer/sources/tap_options.py).

CAN options are python-can's own (``can.cli.add_bus_arguments``: ``-i/-c/-b``, ``--fd``,
``--data-bitrate``, ``--timing``, ``--bus-kwargs KEY=VALUE ...``); serial ports are pyserial
names or URLs. Several sources may be given at once (a CAN bus and a serial line, say).
Options that can never work (an unknown interface, an impossible baud rate, a malformed
channel, an unknown protocol) are usage errors, before anything is opened. A device that does
not open fails the command at once (``SourceError``, exit 1), unless ``--wait`` asks to wait
for it.
"""

from __future__ import annotations

import argparse
from typing import Any

import can.cli

from decoders.model import EG2_CAN
from decoders.registry import resolve_protocol

from ..health.rates import DEFAULT_BAUD
from ..sources.tap_options import TapOptions

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
    # None when not given: tui and plot tell a capture's own rate from one given for it
    ser.add_argument("--baud", type=int, help=f"serial baud rate (default {DEFAULT_BAUD})")
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


def tap_options(args: argparse.Namespace) -> TapOptions:
    """The source options of a live command's arguments, typed (a command without an option
    gets its default)."""
    bridge = getattr(args, "bridge", None)
    return TapOptions(
        can={key: getattr(args, key) for key in CAN_KEYS if key in args},
        bus_kwargs=dict(getattr(args, "bus_kwargs", {}) or {}),
        serial=tuple(getattr(args, "serial", ())),
        baud=DEFAULT_BAUD if args.baud is None else args.baud,
        rts=LINE_STATES[getattr(args, "rts", "low")],
        dtr=LINE_STATES[getattr(args, "dtr", "low")],
        bridge=None if not bridge else (bridge[0], bridge[1]),
        protocol=args.protocol,
        bus=args.bus,
        wait=bool(getattr(args, "wait", False)),
    )
