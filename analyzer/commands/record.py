"""``eg2scope record``: record any live source to MCAP (raw, decoded, device state, events)."""

from __future__ import annotations

import argparse
from typing import Any

from ..live_runner import run_demo, run_session
from ..sources.tap_options import make_taps
from .common import add_rerun_argument, add_session_arguments, live_options
from .demo import add_demo_arguments, demo_options
from .helptext import LIVE_EXIT_STATUS, HelpFormatter, epilog
from .livesource import add_source_arguments, tap_options


def add_subparser(sub: Any) -> None:
    parser = sub.add_parser(
        "record",
        help="record a live source to an MCAP file",
        description=(
            "Record a live source to MCAP, Foxglove-compatible: /raw/<bus> (the bytes and "
            "frames as captured, so the recording can be decoded again later), /decoded/<bus>, "
            "/state/<bus>/<device> and /events/<bus>. Chunks are flushed at least twice a "
            "second, so a recorder that is killed loses at most the last second; Ctrl-C or "
            "SIGTERM finishes the file and ends cleanly. Replay with 'eg2scope decode run.mcap'."
        ),
        epilog=epilog(
            "examples:\n"
            "  eg2scope record -i socketcan -c can0 -o run.mcap\n"
            "  eg2scope record --serial /dev/ttyUSB0 -o run.mcap --show\n"
            "  eg2scope record --demo -o demo.mcap --duration 10",
            LIVE_EXIT_STATUS,
        ),
        formatter_class=HelpFormatter,
    )
    add_source_arguments(parser)
    parser.add_argument(
        "--demo",
        action="store_true",
        help="record the built-in demo (simulated grippers on all three buses)",
    )
    add_demo_arguments(parser)
    add_rerun_argument(parser)
    add_session_arguments(parser, record_required=True)
    parser.add_argument("--show", action="store_true", help="also print the decoded text")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    show = "text" if args.show else None
    if args.demo:
        return run_demo(args.command, demo_options(args), live_options(args), show=show)
    return run_session(live_options(args), make_taps(tap_options(args)), show=show)
