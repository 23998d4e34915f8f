"""``eg2scope plot``: force, opening, current, temperature and state of every gripper on one
clock in Rerun, from a capture, a recording or a live bus (docs/rerun.md)."""

from __future__ import annotations

import argparse
from typing import Any

from ..health.rates import RateOptions
from ..plot.launch import PlotOptions, plot
from ..plot.target import TargetChoice
from .common import (
    add_rate_arguments,
    add_replay_arguments,
    add_session_arguments,
    live_options,
    rate_options,
    whole_capture_options,
)
from .demo import add_demo_arguments, demo_options
from .helptext import CAPTURE_FILE, EXIT_STATUS, HelpFormatter, epilog
from .livesource import add_source_arguments, tap_options


def add_subparser(sub: Any) -> None:
    parser = sub.add_parser(
        "plot",
        help="plot force, opening, state and errors of every gripper in Rerun",
        description=(
            "Plot what each gripper's opening, force, current, temperature and state did, its "
            "grip cycles (a lane coloured by outcome, their figures in a log), the controller's "
            "commands, the bus's errors and each bus's health second by second (load %, "
            "frames, errors and unanswered requests per second, the CAN controller's state; "
            "the load at the rate given (-b, --baud), else a recording's or a live tap's own, else "
            "the EG2's), on one "
            "clock in Rerun: from any "
            "capture 'decode' reads or an eg2scope .mcap recording, or live from a bus. Every "
            "reading is plotted (nothing is downsampled), on the timelines capture_time and "
            "frame (the record's seq, as the TUI and the recording number it). By default the "
            "Rerun viewer is spawned when a display can be opened; otherwise <capture>.rrd is "
            "written in the current directory and the command that opens it is printed. The "
            "layout shows a plot only for what the capture carries, every plot of a capture "
            "over its whole span on one linked time axis (see docs/rerun.md)."
        ),
        epilog=epilog(
            "examples:\n"
            "  eg2scope plot captures/can_pick_place.log\n"
            "  eg2scope plot run.mcap --save run.rrd        # then: rerun run.rrd\n"
            "  eg2scope plot --demo                         # simulated grippers, live\n"
            "  eg2scope plot -i socketcan -c can0 --serve-web",
            EXIT_STATUS,
        ),
        formatter_class=HelpFormatter,
    )
    parser.add_argument(
        "file",
        nargs="?",
        help=f"{CAPTURE_FILE} (or give a live source or --demo instead)",
    )
    target = parser.add_argument_group(
        "where the plot goes (default: spawn a viewer, or "
        "write <capture>.rrd here when there is no display)"
    )
    where = target.add_mutually_exclusive_group()
    where.add_argument(
        "--save", metavar="FILE.rrd", help="write a Rerun recording file (replaced if there)"
    )
    where.add_argument("--spawn", action="store_true", help="spawn the Rerun viewer")
    where.add_argument(
        "--connect",
        nargs="?",
        const="",
        metavar="URL",
        help="send to a running viewer (default rerun+http://127.0.0.1:9876/proxy)",
    )
    where.add_argument(
        "--serve-web",
        action="store_true",
        help="serve Rerun's web viewer on 127.0.0.1 (this machine only) until Ctrl-C or "
        "SIGTERM; the printed address asks for the WebGL renderer, which needs no GPU",
    )
    add_replay_arguments(parser, "all at once", "The plot is the same either way")
    add_source_arguments(parser)
    add_rate_arguments(parser)  # the live sources' -b and --baud, for a capture too
    parser.add_argument(
        "--demo",
        action="store_true",
        help="plot the built-in demo live (simulated grippers on all three buses)",
    )
    add_demo_arguments(parser)
    add_session_arguments(parser, record_required=False)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    return plot(plot_options(args))


def plot_options(args: argparse.Namespace) -> PlotOptions:
    """The plot's options, typed: a capture (``FILE``), the demo (``--demo``) or live sources."""
    return PlotOptions(
        target=TargetChoice(
            save=args.save, spawn=args.spawn, connect=args.connect, serve_web=args.serve_web
        ),
        live=live_options(args),
        taps=tap_options(args),
        capture=whole_capture_options(args) if args.file else None,
        rates=rate_options(args) if args.file else RateOptions(),
        demo=demo_options(args) if args.demo else None,
    )
