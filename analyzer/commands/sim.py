"""``eg2scope sim``: simulated grippers to point a host program (and the analyzer) at."""

from __future__ import annotations

import argparse
from typing import Any

from ..errors import UsageError
from ..sim.scenarios import listing
from ..sim.serve import SimOptions, serve
from .common import positive_float
from .demo import SCENARIO_HELP, TIME_SCALE_HELP, scenario_type
from .helptext import LIVE_EXIT_STATUS, HelpFormatter, epilog

DESCRIPTION = "\n\n".join(
    (
        "Start one or more simulated EG2-4XX grippers that answer as the protocol reference "
        "describes (latency, save pause, run states, faults, Modbus exceptions, short register "
        "numbers), and print where to connect.",
        "serial and modbus: the simulator makes a virtual multi-drop line of ptys with two free "
        "drops: one for your host program (open its /dev/pts/N path with pyserial at 115200 "
        "8N1, or the stable symlink /tmp/eg2scope-sim-<protocol>) and one for a sniffer "
        "(/tmp/eg2scope-sim-<protocol>-tap: every byte of both directions arrives there, as on "
        "a tapped RS485 pair).",
        "can: the grippers join a python-can bus (default: interface 'virtual', channel "
        "'eg2scope-sim'). python-can's virtual bus lives inside one process: it does not reach "
        "another program. To talk to the simulator from another process, use a virtual "
        "SocketCAN device:",
        "  sudo ip link add dev vcan0 type vcan && sudo ip link set up vcan0\n"
        "  eg2scope sim can -i socketcan -c vcan0",
        "--scenario plays a scripted scenario with the built-in host on the first gripper, over "
        "and over (a sniffer started later still sees whole cycles): grip cycles whose true "
        "outcome is known (a part caught, missed, slipping, a stall, a lost command, a bus-off "
        "on CAN); --truth writes each cycle as it played.",
        "Runs until Ctrl-C.",
    )
)


def add_subparser(sub: Any) -> None:
    parser = sub.add_parser(
        "sim",
        help="run simulated grippers on a virtual serial line or CAN bus",
        description=DESCRIPTION,
        epilog=epilog(
            "examples:\n"
            "  eg2scope sim serial                      # one gripper, ID 1\n"
            "  eg2scope sim modbus --id 1 --id 2 --noise 0.01\n"
            "  eg2scope sim can -i socketcan -c vcan0 --host-cycle\n"
            "  eg2scope sim serial --host-cycle         # traffic for a sniffer on the tap\n"
            "  eg2scope sim --list-scenarios\n"
            "  eg2scope sim modbus --scenario slip --truth -   # the truth on stdout",
            LIVE_EXIT_STATUS,
        ),
        formatter_class=HelpFormatter,
    )
    parser.add_argument(
        "protocol",
        nargs="?",
        choices=("serial", "modbus", "can"),
        help="which gripper model to simulate (needed unless --list-scenarios)",
    )
    parser.add_argument(
        "--id",
        dest="ids",
        type=int,
        action="append",
        metavar="N",
        help="a gripper with this ID (repeat for several on one bus; default: 1)",
    )
    parser.add_argument(
        "--object-width",
        default="400",
        metavar="W",
        help="width of the object between the jaws, 0-1000 of the stroke (1000 = 70 mm), or "
        "'none': closing stops there with state 6 at the force limit (default: 400 = 28 mm)",
    )
    parser.add_argument(
        "--noise",
        type=float,
        default=0.0,
        metavar="P",
        help="probability (0-1) of each kind of line trouble per response: a bad checksum/CRC "
        "(CAN: an error frame and a retransmission), garbage bytes (CAN: a foreign frame), "
        "no response at all (default: 0)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the noise (default: 0)")
    parser.add_argument(
        "--link",
        metavar="PATH",
        help="serial/modbus: the stable symlink for the host program "
        "(default: /tmp/eg2scope-sim-<protocol>; the sniffer's gets '-tap' appended)",
    )
    parser.add_argument(
        "--host-cycle",
        action="store_true",
        help="also run the built-in scripted host (pick-and-place cycles on every ID) on the "
        "host drop (CAN: on the same bus), so a sniffer sees real traffic",
    )
    parser.add_argument("--scenario", type=scenario_type, metavar="NAME", help=SCENARIO_HELP)
    parser.add_argument(
        "--list-scenarios",
        action="store_true",
        help="print the scenarios, one line each, and exit",
    )
    parser.add_argument(
        "--time-scale", type=positive_float, default=1.0, metavar="F", help=TIME_SCALE_HELP
    )
    parser.add_argument(
        "--truth",
        metavar="FILE",
        help="with --scenario: write each grip cycle as it played to FILE ('-': stdout), one "
        "JSON object a line (the command, the true outcome, the width at contact, when it "
        "began and ended)",
    )
    parser.add_argument(
        "--short-registers",
        action="store_true",
        help="with --host-cycle on modbus: send register 10 for 1010 (xArm style)",
    )
    can_group = parser.add_argument_group("CAN bus (python-can names, as can.logger takes them)")
    can_group.add_argument(
        "-i", "--interface", default="virtual", help="python-can interface (default: virtual)"
    )
    can_group.add_argument(
        "-c", "--channel", default="eg2scope-sim", help="channel (default: eg2scope-sim)"
    )
    can_group.add_argument(
        "-b",
        "--bitrate",
        type=int,
        default=None,
        help="bit rate, for interfaces that set it (the gripper: 500000)",
    )
    parser.set_defaults(func=run, until_stopped=True)  # a server: Ctrl-C is how it ends


def run(args: argparse.Namespace) -> int:
    if args.list_scenarios:
        print(listing())
        return 0
    return serve(sim_options(args))


def sim_options(args: argparse.Namespace) -> SimOptions:
    """The simulator's options, typed; a usage error for an ID, noise or width out of range."""
    if args.protocol is None:
        raise UsageError("give a protocol: serial, modbus or can")
    scenario = args.scenario
    if scenario is not None and scenario.needs_can and args.protocol != "can":
        raise UsageError(f"scenario {scenario.name!r} needs the CAN bus: eg2scope sim can")
    if args.truth is not None and scenario is None:
        raise UsageError("--truth needs --scenario (the truth is a scenario's)")
    ids = tuple(args.ids or [1])
    limit = 16382 if args.protocol == "can" else 254
    for device in ids:
        if not 1 <= device <= limit:
            raise UsageError(f"--id must be 1-{limit}, not {device}")
    if not 0.0 <= args.noise <= 1.0:
        raise UsageError(f"--noise must be between 0 and 1, not {args.noise}")
    return SimOptions(
        protocol=args.protocol,
        ids=ids,
        object_width=_object_width(args.object_width),
        noise=args.noise,
        seed=args.seed,
        link=args.link,
        host_cycle=args.host_cycle,
        short_registers=args.short_registers,
        interface=args.interface,
        channel=args.channel,
        bitrate=args.bitrate,
        scenario=scenario,
        truth=args.truth,
        pace=args.time_scale,
    )


def _object_width(text: str) -> float | None:
    if text.lower() in ("none", "no", "-"):
        return None
    try:
        width = float(text)
    except ValueError:
        width = -1.0
    if not 0 <= width <= 1000:
        raise UsageError(f"--object-width must be 0-1000 or 'none', not {text}")
    return width
