"""``eg2scope bridge HOST_PORT DEVICE_PORT``: an inline tap between a host and a gripper."""

from __future__ import annotations

import argparse
from dataclasses import replace
from typing import Any

from ..live_runner import run_session
from ..sources.tap_options import make_taps
from .common import add_session_arguments, live_options
from .helptext import LIVE_EXIT_STATUS, HelpFormatter, epilog
from .livesource import add_line_arguments, add_naming_arguments, add_wait_argument, tap_options


def add_subparser(sub: Any) -> None:
    parser = sub.add_parser(
        "bridge",
        help="relay between two serial ports and decode both directions",
        description=(
            "An inline tap for lines a passive tap cannot reach: connect the host to "
            "HOST_PORT and the gripper to DEVICE_PORT; every byte is relayed unchanged, as soon "
            "as it arrives, and decoded with its direction known. Unlike the other taps this "
            "one is in the line (not passive). Ctrl-C or SIGTERM ends it."
        ),
        epilog=epilog(
            "example:\n  eg2scope bridge /dev/ttyUSB0 /dev/ttyUSB1 -o run.mcap", LIVE_EXIT_STATUS
        ),
        formatter_class=HelpFormatter,
    )
    parser.add_argument("host_port", metavar="HOST_PORT", help="port the host controller is on")
    parser.add_argument("device_port", metavar="DEVICE_PORT", help="port the gripper is on")
    parser.add_argument("--baud", type=int, default=115200, help="baud rate (default 115200)")
    add_naming_arguments(parser, can=False)
    add_wait_argument(parser)
    parser.add_argument(
        "--format",
        "-f",
        choices=("text", "jsonl"),
        default="text",
        help="stdout format: text, for people (default), or jsonl, one JSON record per line",
    )
    add_line_arguments(parser)
    add_session_arguments(parser, record_required=False)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    taps = replace(tap_options(args), bridge=(args.host_port, args.device_port))
    return run_session(live_options(args), make_taps(taps), show=args.format)
