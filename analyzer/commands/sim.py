"""``eg2scope sim``: simulated grippers to point a host program (and the analyzer) at."""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import tempfile
import threading
import time
from typing import Any

from ..errors import UsageError
from ..sim.endpoints import CanGripperServer, ModbusGripperServer, SerialGripperServer
from ..sim.gripper import GripperModel
from ..sim.host import HostQuirks, run_host_cycle
from ..sim.ptybus import PtyBus
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
        "Runs until Ctrl-C.",
    )
)

MODELS = {
    "serial": "EG2-4X1, regular serial protocol (EB 90 / EE 16 frames), 115200 8N1",
    "modbus": "EG2-4X2, Modbus RTU, 115200 8N1",
    "can": "EG2-4X0, CAN register protocol, 29-bit identifiers",
}


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
            "  eg2scope sim serial --host-cycle         # traffic for a sniffer on the tap",
            LIVE_EXIT_STATUS,
        ),
        formatter_class=HelpFormatter,
    )
    parser.add_argument(
        "protocol", choices=("serial", "modbus", "can"), help="which gripper model to simulate"
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


def run(args: argparse.Namespace) -> int:
    ids = args.ids or [1]
    limit = 16382 if args.protocol == "can" else 254
    for device in ids:
        if not 1 <= device <= limit:
            raise UsageError(f"--id must be 1-{limit}, not {device}")
    if not 0.0 <= args.noise <= 1.0:
        raise UsageError(f"--noise must be between 0 and 1, not {args.noise}")
    width = _object_width(args.object_width)
    models = {
        device: GripperModel(device, now=time.monotonic(), object_width=width) for device in ids
    }
    noise = {"corrupt": args.noise, "garbage": args.noise, "drop": args.noise, "seed": args.seed}
    stop = threading.Event()
    servers: list[Any] = []
    try:
        _serve(args, ids, models, noise, width, stop, servers)
    except KeyboardInterrupt:  # Ctrl-C before the wait began: the same clean stop
        pass
    if servers:
        stats = servers[0].stats
        print(
            f"served {stats.requests} requests, sent {stats.responses} responses "
            f"({stats.dropped} dropped, {stats.corrupted} corrupted, {stats.garbage} garbage)",
            file=sys.stderr,
        )
    return 0


def _serve(
    args: argparse.Namespace,
    ids: list[int],
    models: dict[int, GripperModel],
    noise: dict[str, Any],
    width: float | None,
    stop: threading.Event,
    servers: list[Any],
) -> None:
    """Start everything, wait for Ctrl-C, stop everything (in reverse order)."""
    with contextlib.ExitStack() as stack:
        server: Any
        host_target: Any
        if args.protocol == "can":
            server = CanGripperServer(
                models,
                interface=args.interface,
                channel=args.channel,
                bitrate=args.bitrate,
                **noise,
            )
            server.start()
            servers.append(server)
            stack.callback(server.stop)
            host_target = None
            _print_can(args, ids, width)
        else:
            base = args.link or os.path.join(tempfile.gettempdir(), f"eg2scope-sim-{args.protocol}")
            bus = stack.enter_context(PtyBus())
            gripper_path = bus.add_endpoint("gripper")
            host_path = bus.add_endpoint("host", link=base)
            tap_path = bus.add_endpoint("tap", link=base + "-tap")
            cls = SerialGripperServer if args.protocol == "serial" else ModbusGripperServer
            server = cls(gripper_path, models, **noise)
            server.start()
            servers.append(server)
            stack.callback(server.stop)
            host_target = host_path
            _print_serial(args, ids, width, host_path, base, tap_path, base + "-tap")
        stack.callback(stop.set)
        if args.host_cycle:
            stack.enter_context(_host_thread(args, ids, host_target, stop))
        _wait(stop)
        print("\nstopping ...", file=sys.stderr)


def _describe(args: argparse.Namespace, ids: list[int], width: float | None) -> str:
    noun = "gripper" if len(ids) == 1 else "grippers"
    what = "no object" if width is None else f"object at {width:g} ({width * 0.07:.1f} mm)"
    noise = f", noise {args.noise:g}" if args.noise else ""
    return (
        f"eg2scope sim: {len(ids)} simulated {noun} {MODELS[args.protocol]}\n"
        f"  IDs {', '.join(map(str, ids))}; {what}{noise}"
    )


def _print_serial(
    args: argparse.Namespace,
    ids: list[int],
    width: float | None,
    host: str,
    host_link: str,
    tap: str,
    tap_link: str,
) -> None:
    print(_describe(args, ids, width))
    print(f"  host program: open {host}  (stable link: {host_link})")
    print(f"  sniffer:      open {tap}  (stable link: {tap_link})")
    print(f"  e.g. python -c \"import serial; s = serial.Serial('{host_link}', 115200)\"")
    if args.host_cycle:
        print("  the built-in host program is running pick-and-place cycles on the host drop")
    print("Ctrl-C stops.", flush=True)


def _print_can(args: argparse.Namespace, ids: list[int], width: float | None) -> None:
    print(_describe(args, ids, width))
    bitrate = f" -b {args.bitrate}" if args.bitrate else ""
    print(f"  CAN bus: interface {args.interface}, channel {args.channel}{bitrate}")
    print(f"  connect: can.Bus(interface={args.interface!r}, channel={args.channel!r})")
    if args.interface == "virtual":
        print(
            "  note: python-can's virtual bus does not cross processes; for another program "
            "use a vcan device: -i socketcan -c vcan0"
        )
    if args.host_cycle:
        print("  the built-in host program is running pick-and-place cycles on the bus")
    print("Ctrl-C stops.", flush=True)


@contextlib.contextmanager
def _host_thread(
    args: argparse.Namespace, ids: list[int], target: Any, stop: threading.Event
) -> Any:
    quirks = HostQuirks(short_registers=args.short_registers)
    bus = None
    if target is None:  # CAN: the host gets its own handle on the same bus
        import can

        kwargs: dict[str, Any] = {"receive_own_messages": False}
        if args.bitrate:
            kwargs["bitrate"] = args.bitrate
        bus = can.Bus(interface=args.interface, channel=args.channel, **kwargs)
        target = bus
    thread = threading.Thread(
        target=run_host_cycle,
        args=(args.protocol, target, ids, None, stop, quirks),
        name="sim-host",
        daemon=True,
    )
    thread.start()
    try:
        yield thread
    finally:
        stop.set()
        thread.join(2.0)
        if bus is not None:
            bus.shutdown()


def _wait(stop: threading.Event) -> None:
    """Until Ctrl-C (or SIGTERM)."""
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        while not stop.wait(0.2):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
