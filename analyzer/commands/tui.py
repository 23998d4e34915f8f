"""``eg2scope tui``: the live bus-debugging terminal UI on simulated buses (``--demo``), any
live source ``live`` takes, or a capture replayed (``eg2scope tui FILE``)."""

from __future__ import annotations

import argparse
import sys
from contextlib import ExitStack, redirect_stderr
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from ..errors import EXIT_ERROR, UsageError
from ..live_runner import byte_times, check_recording_output, open_source, recorder
from ..session.batches import session_engine
from ..session.capture import byte_protocol, exit_code, open_reader
from ..session.engine import ENGINES
from ..session.listener import Listener
from ..session.session import Session, SessionOptions, signals_call
from ..sources.live import Tap
from .common import (
    add_rerun_argument,
    add_session_arguments,
    capture_options,
    protocol_type,
    speed_type,
)
from .demo import add_demo_arguments
from .helptext import EXIT_STATUS, HelpFormatter, epilog
from .livesource import add_source_arguments, open_taps

if TYPE_CHECKING:
    from ..tui.app import Eg2ScopeApp, SessionPlan
    from ..tui.notes import Notes

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
        help="auto: the native core for CAN input where it is built, else Python (default); "
        "python: the Python decoders and tracker; native: the native core (a usage error "
        "where the input is not CAN or the core is not built)",
    )
    add_source_arguments(parser)
    add_session_arguments(parser, record_required=False)
    add_rerun_argument(parser)
    add_demo_arguments(parser)
    parser.set_defaults(func=run, device=None, errors_only=False, no_progress=True)


def session_protocol(args: argparse.Namespace) -> str | None:
    """The byte protocol ``--protocol`` names (None: detected per stream): the command line's
    name or alias (``serial``, ``modbus``, ``auto``) as the decoders know it."""
    try:
        return protocol_type(args.protocol or "auto")
    except argparse.ArgumentTypeError as exc:
        raise UsageError(f"--protocol: {exc}") from None


def extra_listeners(args: argparse.Namespace, live: bool, notes: Notes) -> list[Listener]:
    """``--rerun``: the Rerun listener ``record --rerun`` and ``live --rerun`` use. What it says
    on stderr (where the .rrd went, the web viewer's address) goes to ``notes``: shown in the
    TUI and printed again once the terminal is given back."""
    if args.rerun is None:
        return []  # Rerun is imported only when it is asked for
    from ..plot.listener import rerun_listener

    with redirect_stderr(notes):  # the listener's output keeps the stream it is given
        rerun = rerun_listener(args.rerun, source=args.output or args.file, live=live)
    return [] if rerun is None else [rerun]


def live_plan(
    args: argparse.Namespace,
    taps: list[Tap],
    per_bus: dict[str, str],
    on_start: Any,
    extra: list[Listener] | None = None,
) -> SessionPlan:
    from ..tui.app import SessionPlan

    check_recording_output(args)
    # opened first: a device that does not open fails here (exit 1), before a recording is made
    source = open_source(taps, args.queue_size, on_start)
    try:
        record: Listener | None = recorder(args.output, taps) if args.output else None
    except BaseException:
        source.stop()
        raise
    options = SessionOptions(
        protocol=session_protocol(args),
        per_bus=per_bus,
        byte_time_s=byte_times(taps),
        duration=args.duration,
        engine=getattr(args, "engine", "auto"),
    )
    outputs = ([] if record is None else [record]) + list(extra or [])

    def build(feed: Listener) -> Session:
        return Session(source, [*outputs, feed], options)

    names = ", ".join(t.bus for t in taps)
    return SessionPlan(
        build,
        live=True,
        recorder=record,
        recording_path=args.output,
        freeze_on=args.freeze_on,
        title=f"live: {names}",
    )


def capture_plan(
    args: argparse.Namespace, stack: ExitStack, extra: list[Listener] | None = None
) -> SessionPlan:
    from ..tui.app import SessionPlan
    from ..tui.replay import ReplaySource

    if args.output:
        raise UsageError(
            "-o records live sources; a capture is already recorded (export from the TUI "
            "with 'e' instead)"
        )
    opts = replace(capture_options(args), protocol=session_protocol(args))
    reader = stack.enter_context(open_reader(opts))
    source = ReplaySource(reader, opts.speed)
    options = SessionOptions(protocol=byte_protocol(opts), engine=opts.engine)
    outputs = list(extra or [])

    def build(feed: Listener) -> Session:
        return Session(source, [*outputs, feed], options)

    return SessionPlan(
        build, live=False, replay=source, freeze_on=args.freeze_on, title=f"capture: {opts.path}"
    )


def run(args: argparse.Namespace) -> int:
    from ..tui.app import Eg2ScopeApp
    from ..tui.notes import Notes

    if args.file and args.demo:
        raise UsageError("give a capture file or --demo, not both")
    if args.file:
        check_capture_engine(args)  # a usage error of the command line comes first
    require_terminal()
    notes = Notes()
    with ExitStack() as stack:
        if args.demo:
            from ..sim.rig import DemoRig

            rig = stack.enter_context(DemoRig(args.buses, noise=args.noise))
            extra = extra_listeners(args, live=True, notes=notes)
            plan = live_plan(args, rig.taps, rig.protocols, rig.run_hosts, extra)
        elif args.file:
            plan = capture_plan(args, stack, extra_listeners(args, live=False, notes=notes))
        else:
            taps = open_taps(args)
            plan = live_plan(args, taps, {}, None, extra_listeners(args, live=True, notes=notes))
        plan.notes = notes
        try:
            app = Eg2ScopeApp(plan)
        except ValueError as exc:  # the session cannot be made (an engine that cannot apply)
            raise UsageError(f"--engine {args.engine}: {exc}") from None
        with signals_call(lambda: _stop_app(app)):  # as 'q' does, the recording finished
            app.run()
        app.stop_session()  # however the app ended: the session closes every listener
    return finish(args, app, notes)


def check_capture_engine(args: argparse.Namespace) -> None:
    """UsageError if ``--engine`` cannot decode the capture (asked before the terminal is, and
    before any output such as ``--rerun``'s file is made)."""
    if args.engine == "auto":
        return
    with open_reader(capture_options(args)) as reader:
        try:
            session_engine(args.engine, reader.kind, reader.single_stream)
        except ValueError as exc:
            raise UsageError(f"--engine {args.engine}: {exc}") from None


def require_terminal() -> None:
    if not sys.stdout.isatty():
        raise UsageError(
            "the TUI needs a terminal; for text use 'eg2scope live', 'eg2scope demo' or "
            "'eg2scope decode'"
        )


def summary_line(args: argparse.Namespace, app: Eg2ScopeApp) -> str:
    """What the session did: of a capture, what was read of it; live, what was captured."""
    counts = app.session.counts
    replay = app.plan.replay
    if replay is None:
        where = f" into {args.output}" if args.output else ""
        return f"{counts.line()}{where}"
    read = "read to its end" if replay.finished else f"stopped at {replay.position:.0%}"
    return f"{args.file}: {read}, {counts.records:,} records decoded, {counts.errors:,} with errors"


def finish(args: argparse.Namespace, app: Eg2ScopeApp, notes: Notes) -> int:
    """After the app has gone: what happened, on stderr, and the exit status."""
    notes.print(sys.stderr)
    session = app.session
    print(f"eg2scope: {summary_line(args, app)}", file=sys.stderr)
    for listener, exc in session.detached:
        label = getattr(listener, "label", type(listener).__name__)
        print(f"eg2scope: error: {label} failed: {exc}", file=sys.stderr)
    for err in session.source.errors:
        print(f"eg2scope: {args.file}: {err}", file=sys.stderr)
    crashed = app.return_code not in (None, 0)  # the app itself (Textual printed the traceback)
    if crashed:
        print("eg2scope: error: the TUI failed (the traceback is above)", file=sys.stderr)
    if app.failure is not None:
        print(f"eg2scope: error: {app.failure_text()}", file=sys.stderr)
    if crashed or app.failure is not None:
        return EXIT_ERROR
    damaged = bool(session.source.errors)
    counts = session.counts
    if app.plan.replay is not None and app.plan.replay.finished:
        # the whole capture was read: whatever stopped the app afterwards cut nothing off
        counts = replace(counts, interrupted=False)
    return exit_code(counts, damaged=damaged, failed=bool(session.detached))


def _stop_app(app: Any) -> None:
    """Ctrl-C, SIGTERM or SIGHUP: end the session as an interrupt and quit as 'q' does."""
    if app.session is not None:
        app.session.interrupt()
    try:
        app.call_from_thread(app.action_quit)
    except RuntimeError:  # the app is not running (yet, or any more)
        app.exit(0)
