"""``eg2scope sim``'s run: simulated grippers served on a virtual multi-drop serial line (ptys)
or a python-can bus until Ctrl-C or SIGTERM, where to connect printed, and what was served
printed at the end. With a scenario the built-in host plays it on the first gripper (``play``),
over and over, its truth written as JSON lines to the truth file."""

from __future__ import annotations

import contextlib
import functools
import os
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

from ..outfile import output_stream
from .endpoints import CanGripperServer, ModbusGripperServer, SerialGripperServer
from .gripper import GripperModel
from .host import HostQuirks, run_host_cycle
from .play import TruthLog, play_scenario
from .ptybus import PtyBus
from .scenarios import Scenario

MODELS = {
    "serial": "EG2-4X1, regular serial protocol (EB 90 / EE 16 frames), 115200 8N1",
    "modbus": "EG2-4X2, Modbus RTU, 115200 8N1",
    "can": "EG2-4X0, CAN register protocol, 29-bit identifiers",
}


@dataclass(frozen=True)
class SimOptions:
    """What to simulate, typed. ``protocol``: serial, modbus or can; ``ids``: the grippers;
    ``object_width``: the object between the jaws, 0-1000 of the stroke (None: no object);
    ``noise``: the probability of each kind of line trouble per response, with its ``seed``;
    ``link``: the host's stable symlink of a serial line (None: in the temporary folder);
    ``host_cycle``: run the scripted host too (``short_registers``: as xArm sends Modbus
    registers); ``interface``, ``channel``, ``bitrate``: the CAN bus, as python-can names it;
    ``scenario``: play it with the built-in host on the first ID instead (None: none), its
    truth to the file ``truth`` ("-": stdout; None: nowhere); ``pace``: the jaw's speed-up."""

    protocol: str
    ids: tuple[int, ...]
    object_width: float | None
    noise: float
    seed: int
    link: str | None
    host_cycle: bool
    short_registers: bool
    interface: str
    channel: str
    bitrate: int | None
    scenario: Scenario | None = None
    truth: str | None = None
    pace: float = 1.0


def serve(opts: SimOptions) -> int:
    """Serve the grippers until stopped (a stop is how it ends: exit 0)."""
    models = {
        device: GripperModel(
            device, now=time.monotonic(), object_width=opts.object_width, pace=opts.pace
        )
        for device in opts.ids
    }
    stop = threading.Event()
    servers: list[Any] = []
    try:
        _serve(opts, models, stop, servers)
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
    opts: SimOptions,
    models: dict[int, GripperModel],
    stop: threading.Event,
    servers: list[Any],
) -> None:
    """Start everything, wait for Ctrl-C, stop everything (in reverse order)."""
    with contextlib.ExitStack() as stack:
        host_target: str | None = None  # CAN: the host gets its own handle on the bus
        if opts.protocol == "can":
            _start_can(opts, models, stack, servers)
        else:
            host_target = _start_serial(opts, models, stack, servers)
        stack.callback(stop.set)
        if opts.host_cycle or opts.scenario is not None:
            truth = TruthLog(None if opts.truth is None else _truth_file(opts.truth, stack))
            stack.enter_context(_host_thread(opts, host_target, stop, servers[0], truth))
        _wait(stop)
        print("\nstopping ...", file=sys.stderr)


def _noise(opts: SimOptions) -> dict[str, Any]:
    return {"corrupt": opts.noise, "garbage": opts.noise, "drop": opts.noise, "seed": opts.seed}


def _start_can(
    opts: SimOptions,
    models: dict[int, GripperModel],
    stack: contextlib.ExitStack,
    servers: list[Any],
) -> None:
    """The grippers on the CAN bus."""
    server = CanGripperServer(
        models,
        interface=opts.interface,
        channel=opts.channel,
        bitrate=opts.bitrate,
        **_noise(opts),
    )
    server.start()
    servers.append(server)
    stack.callback(server.stop)
    _print_can(opts)


def _start_serial(
    opts: SimOptions,
    models: dict[int, GripperModel],
    stack: contextlib.ExitStack,
    servers: list[Any],
) -> str:
    """The grippers on a virtual line of ptys; the host's drop."""
    base = opts.link or os.path.join(tempfile.gettempdir(), f"eg2scope-sim-{opts.protocol}")
    bus = stack.enter_context(PtyBus())
    gripper_path = bus.add_endpoint("gripper")
    host_path = bus.add_endpoint("host", link=base)
    tap_path = bus.add_endpoint("tap", link=base + "-tap")
    cls = SerialGripperServer if opts.protocol == "serial" else ModbusGripperServer
    server = cls(gripper_path, models, **_noise(opts))
    server.start()
    servers.append(server)
    stack.callback(server.stop)
    _print_serial(opts, host_path, base, tap_path, base + "-tap")
    return host_path


def _describe(opts: SimOptions) -> str:
    ids, width = opts.ids, opts.object_width
    noun = "gripper" if len(ids) == 1 else "grippers"
    what = "no object" if width is None else f"object at {width:g} ({width * 0.07:.1f} mm)"
    if opts.scenario is not None:
        what = f"scenario {opts.scenario.name}: {opts.scenario.summary}"
    noise = f", noise {opts.noise:g}" if opts.noise else ""
    return (
        f"eg2scope sim: {len(ids)} simulated {noun} {MODELS[opts.protocol]}\n"
        f"  IDs {', '.join(map(str, ids))}; {what}{noise}"
    )


def _print_serial(opts: SimOptions, host: str, host_link: str, tap: str, tap_link: str) -> None:
    print(_describe(opts))
    print(f"  host program: open {host}  (stable link: {host_link})")
    print(f"  sniffer:      open {tap}  (stable link: {tap_link})")
    print(f"  e.g. python -c \"import serial; s = serial.Serial('{host_link}', 115200)\"")
    _print_host(opts, "on the host drop")
    print("Ctrl-C stops.", flush=True)


def _print_can(opts: SimOptions) -> None:
    print(_describe(opts))
    bitrate = f" -b {opts.bitrate}" if opts.bitrate else ""
    print(f"  CAN bus: interface {opts.interface}, channel {opts.channel}{bitrate}")
    print(f"  connect: can.Bus(interface={opts.interface!r}, channel={opts.channel!r})")
    if opts.interface == "virtual":
        print(
            "  note: python-can's virtual bus does not cross processes; for another program "
            "use a vcan device: -i socketcan -c vcan0"
        )
    _print_host(opts, "on the bus")
    print("Ctrl-C stops.", flush=True)


def _print_host(opts: SimOptions, where: str) -> None:
    if opts.scenario is not None:
        print(
            f"  the built-in host program is playing scenario {opts.scenario.name!r} on "
            f"gripper {opts.ids[0]} {where}"
        )
    elif opts.host_cycle:
        print(f"  the built-in host program is running pick-and-place cycles {where}")


def _truth_file(path: str, stack: contextlib.ExitStack) -> Any:
    """The truth's stream: stdout for "-", else a file complete when the simulator stops."""
    return stack.enter_context(output_stream(path, False))


@contextlib.contextmanager
def _host_thread(
    opts: SimOptions, target: str | None, stop: threading.Event, server: Any, truth: TruthLog
) -> Iterator[threading.Thread]:
    """The scripted host on the host's drop (``target``) or, for CAN (None), on a handle of
    its own on the same bus; the scenario's player when there is one (``server``: its world)."""
    quirks = HostQuirks(short_registers=opts.short_registers)
    bus = None
    if target is None:
        import can

        kwargs: dict[str, Any] = {"receive_own_messages": False}
        if opts.bitrate:
            kwargs["bitrate"] = opts.bitrate
        bus = can.Bus(interface=opts.interface, channel=opts.channel, **kwargs)
    port_or_bus = target if bus is None else bus
    run: Callable[[], object]
    if opts.scenario is not None:
        run = functools.partial(
            play_scenario,
            opts.scenario,
            opts.protocol,
            opts.protocol,
            port_or_bus,
            server,
            opts.ids[0],
            stop,
            truth,
            quirks=quirks,
            pace=opts.pace,
            repeat=True,  # a sniffer started later still sees whole cycles
        )
    else:
        run = functools.partial(
            run_host_cycle, opts.protocol, port_or_bus, list(opts.ids), None, stop, quirks
        )
    thread = threading.Thread(target=run, name="sim-host", daemon=True)
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
