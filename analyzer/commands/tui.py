"""``eg2scope tui``: the live bus-debugging terminal UI on simulated buses (``--demo``), any
live source ``live`` takes, or a capture replayed (``eg2scope tui FILE``)."""

from __future__ import annotations

import argparse
from typing import Any

from ..health.rates import RateOptions
from ..session.engine import ENGINES
from ..tui.launch import TuiOptions, run_tui
from ..tui.store import LIVE_KEEP
from .common import (
    add_rate_arguments,
    add_rerun_argument,
    add_session_arguments,
    capture_options,
    live_options,
    positive_int,
    rate_options,
    speed_type,
)
from .demo import add_demo_arguments, demo_options
from .helptext import EXIT_STATUS, HelpFormatter, epilog
from .livesource import add_source_arguments, tap_options

TRIGGER_NAMES = ("error", "fault", "unanswered")


def add_subparser(sub: Any) -> None:
    from ..tui.keys import help_text

    parser = sub.add_parser(
        "tui",
        help="the live bus-debugging terminal UI (live buses, the demo, or a capture)",
        description=(
            "Watch a bus in a terminal UI: every frame decoded in a scrolling list (follow, "
            "pause, filter, search, marks), the selected frame's fields and bytes, one row per "
            "gripper with its state, the problems found, register watch and latency, each "
            "grip cycle as it ends (its outcome and figures; Enter shows its frames), and a "
            "health line per bus (load, frames/s, errors/s, the worst recent event). Takes "
            "every live source 'live' takes, the simulated buses (--demo), or a capture file "
            "'decode' reads, replayed (--speed)."
        ),
        epilog=epilog(
            "examples:\n"
            "  eg2scope tui --demo\n"
            "  eg2scope tui -i socketcan -c can0 -b 500000\n"
            "  eg2scope tui --serial /dev/ttyUSB0 -o run.mcap   # watch and record\n"
            "  eg2scope tui run.mcap --speed 10                 # replay a capture\n\n"
            "keys:\n" + help_text(),
            EXIT_STATUS,
        ),
        formatter_class=HelpFormatter,
    )
    parser.add_argument(
        "file", nargs="?", help="a capture to replay (anything 'eg2scope decode' reads)"
    )
    parser.add_argument(
        "--demo", action="store_true", help="watch simulated grippers on all three buses"
    )
    parser.add_argument(
        "--speed",
        type=speed_type,
        default=None,
        metavar="X",
        help="replay speed of a capture: 1 (real time), 2, 5, 10 ... or max (default)",
    )
    parser.add_argument(
        "--freeze-on",
        choices=TRIGGER_NAMES,
        help="freeze the view on the first such record (capture and recording go on); "
        "'x' re-arms it",
    )
    parser.add_argument(
        "--engine",
        choices=ENGINES,
        default="auto",
        help="auto: the native core for CAN input and raw dumps where it is built, else "
        "Python (default); python: the Python decoders and tracker; native: the native core "
        "(a usage error for several byte streams, as live serial taps and their recordings, "
        "or where the core is not built)",
    )
    parser.add_argument(
        "--keep",
        type=keep_type,
        default=None,
        metavar="N",
        help=f"records the TUI keeps to show, the oldest dropped first (memory stays bounded "
        f"in a session that runs for hours; a recording keeps everything): default the last "
        f"{LIVE_KEEP:,} of a live session, every record of a capture file; 'all': every one",
    )
    add_source_arguments(parser)
    add_rate_arguments(parser)  # the live sources' -b and --baud, for a capture too
    add_session_arguments(parser, record_required=False)
    add_rerun_argument(parser)
    add_demo_arguments(parser)
    parser.set_defaults(func=run, device=None, errors_only=False, no_progress=True)


def tui_options(args: argparse.Namespace) -> TuiOptions:
    """The TUI's options, typed: a capture (``FILE``), the demo (``--demo``) or live sources."""
    return TuiOptions(
        live=live_options(args),
        taps=tap_options(args),
        capture=capture_options(args) if args.file else None,
        rates=rate_options(args) if args.file else RateOptions(),
        demo=demo_options(args) if args.demo else None,
        engine=args.engine,
        freeze_on=args.freeze_on,
        keep=keep_option(args),
    )


def keep_type(text: str) -> int:
    """argparse type of --keep: a number of records, or 'all' (0)."""
    return 0 if text.strip().lower() == "all" else positive_int(text)


def keep_option(args: argparse.Namespace) -> int | None:
    """How many records the store keeps (None: every one): --keep, else the default of a live
    session or of a capture file (bounded by the file)."""
    if args.keep is None:
        return None if args.file else LIVE_KEEP
    return args.keep or None


def run(args: argparse.Namespace) -> int:
    return run_tui(tui_options(args))
