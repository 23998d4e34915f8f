"""``eg2scope tui``: the live bus-debugging terminal UI on simulated buses (``--demo``), any
live source ``live`` takes, or a capture replayed (``eg2scope tui FILE``)."""

from __future__ import annotations

import argparse
import sys
from contextlib import ExitStack
from typing import TYPE_CHECKING, Any

from ..errors import UsageError
from ..listener import Listener
from ..session import Session, SessionOptions, signals_call
from ..sources.live import Tap
from .common import CaptureOptions, byte_protocol, exit_code, open_reader, speed_type
from .demo import add_demo_arguments
from .livesource import add_source_arguments, open_taps
from .session import (
    add_session_arguments,
    byte_times,
    check_recording_name,
    open_source,
    recorder,
)

if TYPE_CHECKING:
    from ..tui.app import SessionPlan

TRIGGER_NAMES = ("error", "fault", "unanswered")


def add_subparser(sub: Any) -> None:
    from ..tui.keys import help_text

    parser = sub.add_parser(
        "tui",
        help="the live bus-debugging terminal UI (live buses, the demo, or a capture)",
        description=(
            "Watch a bus in a terminal UI: every frame decoded in a scrolling list (follow, "
            "pause, filter, search, marks), the selected frame's fields and bytes, one row per "
            "gripper with its state, the problems found, register watch and latency. Takes "
            "every live source 'live' takes, the simulated buses (--demo), or a capture file "
            "'decode' reads, replayed (--speed)."
        ),
        epilog=(
            "examples:\n"
            "  eg2scope tui --demo\n"
            "  eg2scope tui -i socketcan -c can0 -b 500000\n"
            "  eg2scope tui --serial /dev/ttyUSB0 -o run.mcap   # watch and record\n"
            "  eg2scope tui run.mcap --speed 10                 # replay a capture\n\n"
            "keys:\n" + help_text()
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
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
    add_source_arguments(parser)
    add_session_arguments(parser, record_required=False)
    add_demo_arguments(parser)
    parser.set_defaults(func=run, device=None, errors_only=False, no_progress=True)


def live_plan(
    args: argparse.Namespace, taps: list[Tap], per_bus: dict[str, str], on_start: Any
) -> SessionPlan:
    from decoders.registry import resolve_protocol

    from ..tui.app import SessionPlan

    protocol = None if args.protocol in (None, "auto") else resolve_protocol(args.protocol)
    if args.output:
        check_recording_name(args.output)
    # opened first: a device that does not open fails here (exit 1), before a recording is made
    source = open_source(taps, args.queue_size, on_start)
    try:
        record: Listener | None = recorder(args.output, taps) if args.output else None
    except BaseException:
        source.stop()
        raise
    options = SessionOptions(
        protocol=protocol,
        per_bus=per_bus,
        byte_time_s=byte_times(taps),
        duration=args.duration,
    )

    def build(feed: Listener) -> Session:
        listeners = [feed] if record is None else [record, feed]
        return Session(source, listeners, options)

    names = ", ".join(t.bus for t in taps)
    return SessionPlan(
        build,
        live=True,
        recorder=record,
        recording_path=args.output,
        freeze_on=args.freeze_on,
        title=f"live: {names}",
    )


def capture_plan(args: argparse.Namespace, stack: ExitStack) -> SessionPlan:
    from ..tui.app import SessionPlan
    from ..tui.replay import ReplaySource

    if args.output:
        raise UsageError(
            "-o records live sources; a capture is already recorded (export from the TUI "
            "with 'e' instead)"
        )
    opts = CaptureOptions.from_args(args)
    reader = stack.enter_context(open_reader(opts))
    source = ReplaySource(reader, opts.speed)
    options = SessionOptions(protocol=byte_protocol(opts))

    def build(feed: Listener) -> Session:
        return Session(source, [feed], options)

    return SessionPlan(
        build, live=False, replay=source, freeze_on=args.freeze_on, title=f"capture: {opts.path}"
    )


def run(args: argparse.Namespace) -> int:
    from ..tui.app import Eg2ScopeApp

    if args.file and args.demo:
        raise UsageError("give a capture file or --demo, not both")
    if not sys.stdout.isatty():
        raise UsageError(
            "the TUI needs a terminal; for text use 'eg2scope live', 'eg2scope demo' or "
            "'eg2scope decode'"
        )
    with ExitStack() as stack:
        if args.demo:
            from ..sim.rig import DemoRig

            rig = stack.enter_context(DemoRig(args.buses, noise=args.noise))
            plan = live_plan(args, rig.taps, rig.protocols, rig.run_hosts)
        elif args.file:
            plan = capture_plan(args, stack)
        else:
            plan = live_plan(args, open_taps(args), {}, None)
        sessions: list[Session] = []
        plan.on_done.append(sessions.append)
        app = Eg2ScopeApp(plan)
        with signals_call(lambda: _stop_app(app)):  # as 'q' does, the recording finished
            app.run()
        if app.session is not None and app.session not in sessions:
            app.session.stop()  # the app ended another way (an error): close the session
    if not sessions:
        return 1
    session = sessions[0]
    where = f" into {args.output}" if args.output else ""
    print(f"eg2scope: {session.counts.line()}{where}", file=sys.stderr)
    for listener, exc in session.detached:
        label = getattr(listener, "label", type(listener).__name__)
        print(f"eg2scope: error: {label} failed: {exc}", file=sys.stderr)
    damaged = bool(session.source.errors)
    for err in session.source.errors:
        print(f"eg2scope: {args.file}: {err}", file=sys.stderr)
    return exit_code(session.counts, damaged=damaged, failed=bool(session.detached))


def _stop_app(app: Any) -> None:
    """Ctrl-C, SIGTERM or SIGHUP: end the session as an interrupt and quit as 'q' does."""
    if app.session is not None:
        app.session.interrupt()
    try:
        app.call_from_thread(app.action_quit)
    except RuntimeError:  # the app is not running (yet, or any more)
        app.exit(0)
