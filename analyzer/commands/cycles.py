"""``eg2scope cycles``: every grip cycle of a capture or a live bus, with its outcome."""

from __future__ import annotations

import argparse
from typing import Any

from ..cycles.outputs import FORMATS
from ..cycles.run import CyclesOptions, cycles
from ..errors import UsageError
from ..live_runner import LiveOptions
from .common import (
    add_replay_arguments,
    non_negative_int,
    positive_float,
    positive_int,
    whole_capture_options,
)
from .decode import to_a_terminal
from .demo import add_demo_arguments, demo_options
from .helptext import CAPTURE_FILE, EXIT_STATUS, HelpFormatter, epilog
from .livesource import add_source_arguments, tap_options

OUTCOMES_HELP = (
    "outcomes: gripped (stopped by the force limit, state 6), closed_empty (fully closed, "
    "state 2, no contact: the part was missed), opened (fully open), positioned (reached the "
    "target of a seek or a move), stopped (a stop command, or standing still short of the "
    "target), faulted (fault bits during the cycle), refused (the gripper answered the command "
    "with a failure), unanswered (the command was never answered), unfinished (the cycle "
    "ended, or the capture did, while the gripper still moved), unknown (the host read "
    "neither the state nor an opening that proves the end: 'unknown' in the record names "
    "what was not read)"
)


def add_subparser(sub: Any) -> None:
    parser = sub.add_parser(
        "cycles",
        help="every grip cycle of a capture or a live bus, with its outcome",
        description=(
            "Cut each gripper's timeline into grip cycles and say how each ended. A cycle "
            "starts at a motion command to a gripper (catch, continuous catch, release, seek; "
            "on Modbus and CAN a write of the target opening) and ends at its next motion "
            "command, a stop, or the end of the capture. Each cycle has its outcome, the "
            "opening at contact, the peak force, the times to contact and to standing still, "
            "retries, faults, warnings (slip), what the host never read, and the seq of every "
            "frame that decided it (docs/contracts.md, 'Grip cycles'). Works on any capture "
            "'decode' reads and live, like 'live': a cycle is written when it ends."
        ),
        epilog=epilog(
            "examples:\n"
            "  eg2scope cycles captures/can_pick_place.log\n"
            "  eg2scope cycles run.mcap --format csv -o cycles.csv\n"
            "  eg2scope cycles dump.bin --format parquet -o cycles.parquet --device 2\n"
            "  eg2scope cycles -i socketcan -c can0 -b 500000 --format jsonl\n"
            "  eg2scope cycles --demo --duration 10",
            OUTCOMES_HELP,
            EXIT_STATUS,
        ),
        formatter_class=HelpFormatter,
    )
    parser.add_argument(
        "file", nargs="?", help=f"{CAPTURE_FILE} (or give a live source or --demo instead)"
    )
    _add_output_arguments(parser)
    add_replay_arguments(parser, "as fast as possible", "The cycles are the same either way")
    add_source_arguments(parser)
    parser.add_argument(
        "--demo",
        action="store_true",
        help="the cycles of the built-in demo, live (simulated grippers on all three buses)",
    )
    add_demo_arguments(parser)
    _add_live_arguments(parser)
    parser.set_defaults(func=run)


def _add_output_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--format",
        "-f",
        choices=FORMATS,
        default="text",
        help="text: one line per cycle, for people (default); jsonl: one JSON object per "
        "cycle, the contract for other programs; csv: for spreadsheets; parquet: typed columns "
        "(needs -o FILE, or stdout to a file or pipe)",
    )
    parser.add_argument(
        "--output",
        "-o",
        metavar="PATH",
        help="write to PATH instead of stdout (written under a temporary name and renamed "
        "when done; never the input file)",
    )
    parser.add_argument(
        "--device",
        "-d",
        type=non_negative_int,
        metavar="N",
        help="only the cycles of gripper N (a broadcast command starts one on it too)",
    )


def _add_live_arguments(parser: argparse.ArgumentParser) -> None:
    """A live session's end; a live command runs until it is stopped."""
    parser.set_defaults(until_stopped=True)
    live = parser.add_argument_group("live session")
    live.add_argument(
        "--duration",
        type=positive_float,
        metavar="S",
        help="stop after S seconds (default: run until Ctrl-C)",
    )
    live.add_argument(
        "--queue-size",
        type=positive_int,
        default=200_000,
        metavar="N",
        help="items buffered between capture and decoding before drops are counted "
        "(default 200000)",
    )


def run(args: argparse.Namespace) -> int:
    if args.format == "parquet" and to_a_terminal(args.output):
        raise UsageError(
            "--format parquet writes a binary file, not to a terminal: give -o FILE.parquet"
        )
    return cycles(cycles_options(args))


def cycles_options(args: argparse.Namespace) -> CyclesOptions:
    """The command's options, typed: a capture (``FILE``), the demo or live sources."""
    return CyclesOptions(
        fmt=args.format,
        output=args.output,
        device=args.device,
        live=LiveOptions(
            protocol=args.protocol,
            output=None,
            force=False,
            duration=args.duration,
            queue_size=args.queue_size,
            engine=args.engine,
        ),
        taps=tap_options(args),
        capture=whole_capture_options(args) if args.file else None,  # --device picks cycles
        demo=demo_options(args) if args.demo else None,
    )
