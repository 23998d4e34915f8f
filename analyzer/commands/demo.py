"""``eg2scope demo``: simulated grippers on all three buses, decoded live. No hardware needed."""

from __future__ import annotations

import argparse
from typing import Any

from ..live_runner import run_demo
from ..sim.rig import BUSES, DemoOptions
from .common import add_session_arguments, live_options, probability
from .helptext import LIVE_EXIT_STATUS, HelpFormatter, epilog


def add_subparser(sub: Any) -> None:
    parser = sub.add_parser(
        "demo",
        help="watch simulated grippers on all three buses (no hardware needed)",
        description=(
            "Start simulated EG2 grippers (IDs 1 and 2) on a regular-serial RS232 line, a "
            "Modbus RTU RS485 line (virtual ptys) and a virtual CAN bus, with a host program on "
            "each running pick-and-place cycles, and watch them through eg2scope's real passive "
            "taps, decoded live. A little line noise is injected so checksum errors and garbage "
            "show up. Ctrl-C or SIGTERM ends it."
        ),
        epilog=epilog("example:\n  eg2scope demo --duration 10 -o demo.mcap", LIVE_EXIT_STATUS),
        formatter_class=HelpFormatter,
    )
    add_demo_arguments(parser)
    parser.add_argument(
        "--format",
        "-f",
        choices=("text", "jsonl"),
        default="text",
        help="stdout format: text, for people (default), or jsonl, one JSON record per line",
    )
    add_session_arguments(parser, record_required=False)
    parser.set_defaults(func=run, protocol="auto")


def bus_list(text: str) -> tuple[str, ...]:
    """argparse type: the demo's buses, comma separated."""
    buses = tuple(b.strip() for b in text.split(",") if b.strip())
    unknown = sorted(set(buses) - set(BUSES))
    if unknown or not buses:
        raise argparse.ArgumentTypeError(
            f"unknown demo bus {', '.join(unknown) or repr(text)}; choose from {', '.join(BUSES)}"
        )
    return buses


def add_demo_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("demo (simulated grippers)")
    group.add_argument(
        "--buses",
        type=bus_list,
        default=BUSES,
        metavar="LIST",
        help="buses to simulate, comma separated (default: serial,modbus,can)",
    )
    group.add_argument(
        "--noise",
        type=probability,
        default=0.01,
        metavar="P",
        help="probability of a corrupted, garbled or dropped response (default 0.01)",
    )


def demo_options(args: argparse.Namespace) -> DemoOptions:
    """The demo options of a command's arguments, typed."""
    return DemoOptions(buses=args.buses, noise=args.noise)


def run(args: argparse.Namespace) -> int:
    return run_demo(args.command, demo_options(args), live_options(args), show=args.format)
