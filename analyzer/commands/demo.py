"""``eg2scope demo``: simulated grippers on all three buses, decoded live. No hardware needed."""

from __future__ import annotations

import argparse
from typing import Any

from ..errors import UsageError
from ..live_runner import run_demo
from ..sim.demo_options import BUSES, DemoOptions
from ..sim.scenarios import NAMES, Scenario, scenario
from .common import add_session_arguments, live_options, positive_float, probability
from .helptext import LIVE_EXIT_STATUS, HelpFormatter, epilog

DEFAULT_NOISE = 0.01


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
        epilog=epilog(
            "examples:\n"
            "  eg2scope demo --duration 10 -o demo.mcap\n"
            "  eg2scope demo --scenario tour                 # every kind of grip cycle in turn\n"
            "  eg2scope demo --scenario grip:300 --truth truth.jsonl\n"
            "  eg2scope sim --list-scenarios                 # the scenarios, one line each",
            LIVE_EXIT_STATUS,
        ),
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


def scenario_type(text: str) -> Scenario:
    """argparse type: a scenario, ``NAME`` or ``NAME:WIDTH``."""
    try:
        return scenario(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


SCENARIO_HELP = (
    f"play a scripted scenario ({', '.join(NAMES)}; NAME:WIDTH gives its part a width, "
    "100-900 of the stroke; 'eg2scope sim --list-scenarios' says what each does) instead of "
    "the pick-and-place cycles: its host sends the motion commands and polls state, opening "
    "and force, and every grip cycle's true outcome is known (--truth)"
)
TIME_SCALE_HELP = (
    "the simulated jaw moves and squeezes F times faster, and the scenario's host pauses F "
    "times shorter (default 1: as the real gripper)"
)
TRUTH_HELP = (
    "with --scenario: write each grip cycle as it played to this file, one JSON object a line "
    "(the command, the true outcome, the width at contact, when it began and ended)"
)


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
        default=None,
        metavar="P",
        help="probability of a corrupted, garbled or dropped response (default 0.01; 0 with "
        "--scenario, whose truth noise would spoil)",
    )
    group.add_argument("--scenario", type=scenario_type, metavar="NAME", help=SCENARIO_HELP)
    group.add_argument(
        "--time-scale", type=positive_float, default=1.0, metavar="F", help=TIME_SCALE_HELP
    )
    group.add_argument("--truth", metavar="FILE", help=TRUTH_HELP)


def demo_options(args: argparse.Namespace) -> DemoOptions:
    """The demo options of a command's arguments, typed."""
    noise = args.noise
    if noise is None:
        noise = 0.0 if args.scenario is not None else DEFAULT_NOISE
    if args.truth is not None and args.scenario is None:
        raise UsageError("--truth needs --scenario (the truth is a scenario's)")
    if args.scenario is not None and args.scenario.needs_can and "can" not in args.buses:
        raise UsageError(f"scenario {args.scenario.name!r} needs the CAN bus in --buses")
    return DemoOptions(
        buses=args.buses,
        noise=noise,
        scenario=args.scenario,
        pace=args.time_scale,
        truth=args.truth,
    )


def run(args: argparse.Namespace) -> int:
    return run_demo(args.command, demo_options(args), live_options(args), show=args.format)
