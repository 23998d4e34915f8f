"""``eg2scope live``: watch a CAN bus or a serial line and print what it says, decoded."""

from __future__ import annotations

import argparse
from typing import Any

from ..live_runner import run_session
from ..sources.tap_options import make_taps
from .common import add_rerun_argument, add_session_arguments, live_options
from .helptext import LIVE_EXIT_STATUS, HelpFormatter, epilog
from .livesource import add_source_arguments, tap_options


def add_subparser(sub: Any) -> None:
    parser = sub.add_parser(
        "live",
        help="watch a live CAN bus or serial line, decoded",
        description=(
            "Watch a live bus passively and print every frame decoded, as it happens. The "
            "CAN tap requests listen-only where the interface allows and never sends; serial "
            "taps never write to the ports they watch. A port or interface that does not open "
            "fails at once (--wait waits for it); one that goes away is reported and reopened "
            "when it comes back, and the gap is marked. Ctrl-C or SIGTERM ends it."
        ),
        epilog=epilog(
            "examples:\n"
            "  eg2scope live -i socketcan -c can0 -b 500000\n"
            "  eg2scope live --serial /dev/ttyUSB0 --protocol modbus\n"
            "  eg2scope live -s /dev/ttyUSB0 -s /dev/ttyUSB1     # one adapter per RS232 wire\n"
            "  eg2scope live -i pcan -c PCAN_USBBUS1 -o run.mcap # and record",
            LIVE_EXIT_STATUS,
        ),
        formatter_class=HelpFormatter,
    )
    add_source_arguments(parser)
    add_rerun_argument(parser)
    add_session_arguments(parser, record_required=False)
    parser.add_argument(
        "--format",
        "-f",
        choices=("text", "jsonl"),
        default="text",
        help="stdout format (default text)",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    return run_session(live_options(args), make_taps(tap_options(args)), show=args.format)
