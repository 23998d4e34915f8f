"""``eg2scope tui``'s run: the session plan (the simulated buses, live taps, or a capture
replayed), the app run on the terminal, and what happened said on stderr once the terminal is
given back, with the exit status. The app (Textual) is imported only when it runs."""

from __future__ import annotations

import sys
from collections.abc import Callable
from contextlib import ExitStack, redirect_stderr
from dataclasses import dataclass, field, replace
from functools import partial
from typing import TYPE_CHECKING, Any

from ..errors import EXIT_ERROR, UsageError
from ..health.rates import BusRates, RateOptions, rates_of_capture
from ..live_runner import (
    LiveOptions,
    byte_times,
    check_live_engine,
    check_recording_output,
    open_source,
    recorder,
    session_protocol,
)
from ..session.batches import session_engine
from ..session.capture import CaptureOptions, byte_protocol, exit_code, open_reader
from ..session.listener import Listener
from ..session.session import Session, SessionOptions, signals_call
from ..sim.demo_options import DemoOptions
from ..sim.rig import DemoRig
from ..sources.live import Tap
from ..sources.source import live_kind
from ..sources.tap_options import TapOptions, make_taps
from .bus_rates import live_rates
from .notes import Notes
from .replay import ReplaySource
from .terminal import TerminalWatch

if TYPE_CHECKING:
    from .app import Eg2ScopeApp, SessionPlan


@dataclass(frozen=True)
class TuiOptions:
    """``eg2scope tui``'s options, typed. ``live``: the live session's (its recording, its
    end, ``--rerun``); ``taps``: the live sources; ``capture``: the capture to replay instead
    (None: live); ``rates``: the rates given for the capture's bus health (its own, else the
    EG2's, where not given); ``demo``: the simulated buses to watch instead (None: none);
    ``engine``: the session's decoding; ``freeze_on``: the trigger armed at the start (None:
    none); ``keep``: how many of the newest records the TUI keeps (None: every one)."""

    live: LiveOptions
    taps: TapOptions
    capture: CaptureOptions | None = None
    rates: RateOptions = field(default_factory=RateOptions)
    demo: DemoOptions | None = None
    engine: str = "auto"
    freeze_on: str | None = None
    keep: int | None = None

    @property
    def path(self) -> str | None:
        """The capture's path (None: live)."""
        return None if self.capture is None else self.capture.path


def run_tui(opts: TuiOptions) -> int:
    """The TUI on the session the options ask for, until the user quits; the exit status."""
    if opts.capture is not None and opts.demo is not None:
        raise UsageError("give a capture file or --demo, not both")
    taps = None  # a usage error of the command line comes first
    if opts.capture is not None:
        check_capture_engine(opts.capture)
    elif opts.demo is not None:
        check_live_engine(opts.engine, opts.demo.kind)
    else:
        taps = make_taps(opts.taps)
        check_live_engine(opts.engine, live_kind(taps))
    require_terminal()
    notes = Notes()
    with ExitStack() as stack:
        plan = session_plan(opts, stack, notes, taps)
        plan.notes = notes
        app = _app(plan, opts.engine)
        stop = partial(_stop_app, app)  # as 'q' does: the recording finished
        terminal = TerminalWatch(stop)  # its window closed, the script driving it killed
        app.driver_class = terminal.driver_class(app.driver_class)
        with signals_call(stop), terminal:
            app.run()
        app.stop_session()  # however the app ended: the session closes every listener
    return finish(opts, app, notes)


def session_plan(
    opts: TuiOptions, stack: ExitStack, notes: Notes, taps: list[Tap] | None
) -> SessionPlan:
    """The plan of the session the options ask for (``stack`` holds what it opens; ``taps``:
    the live sources, when neither a capture nor the demo)."""
    if opts.demo is not None:
        rig = stack.enter_context(DemoRig.of(opts.demo))
        extra = extra_listeners(opts, live=True, notes=notes)
        return live_plan(opts, rig.taps, rig.protocols, rig.run_hosts, extra)
    if opts.capture is not None:
        return capture_plan(opts, stack, capture_listeners(opts, notes))
    assert taps is not None
    return live_plan(opts, taps, {}, None, extra_listeners(opts, live=True, notes=notes))


def _app(plan: SessionPlan, engine: str) -> Eg2ScopeApp:
    from .app import Eg2ScopeApp

    try:
        return Eg2ScopeApp(plan)
    except ValueError as exc:  # the session cannot be made (an engine that cannot apply)
        raise UsageError(f"--engine {engine}: {exc}") from None


def extra_listeners(
    opts: TuiOptions, live: bool, notes: Notes, rates: BusRates | None = None
) -> list[Listener]:
    """``--rerun``: the Rerun listener ``record --rerun`` and ``live --rerun`` use, its bus
    health at ``rates`` (None: the EG2's). What it says on stderr (where the .rrd went, the
    web viewer's address) goes to ``notes``: shown in the TUI and printed again once the
    terminal is given back."""
    if opts.live.rerun is None:
        return []  # Rerun is imported only when it is asked for
    from ..plot.listener import rerun_listener

    source = opts.live.output or opts.path
    with redirect_stderr(notes):  # the listener's output keeps the stream it is given
        rerun = rerun_listener(opts.live.rerun, source=source, live=live, rates=rates)
    return [] if rerun is None else [rerun]


def capture_listeners(opts: TuiOptions, notes: Notes) -> Callable[[BusRates], list[Listener]]:
    """``extra_listeners`` of a capture, made once its rates are known."""
    return lambda rates: extra_listeners(opts, live=False, notes=notes, rates=rates)


def live_plan(
    opts: TuiOptions,
    taps: list[Tap],
    per_bus: dict[str, str],
    on_start: Any,
    extra: list[Listener] | None = None,
) -> SessionPlan:
    from .app import SessionPlan

    live = opts.live
    check_recording_output(live)
    # opened first: a device that does not open fails here (exit 1), before a recording is made
    source = open_source(taps, live.queue_size, on_start)
    try:
        record: Listener | None = recorder(live.output, taps) if live.output else None
    except BaseException:
        source.stop()
        raise
    options = SessionOptions(
        protocol=session_protocol(live.protocol),
        per_bus=per_bus,
        byte_time_s=byte_times(taps),
        duration=live.duration,
        engine=opts.engine,
    )
    outputs = ([] if record is None else [record]) + list(extra or [])

    def build(tui: list[Listener]) -> Session:
        return Session(source, [*outputs, *tui], options)

    names = ", ".join(t.bus for t in taps)
    return SessionPlan(
        build,
        live=True,
        recorder=record,
        rates=live_rates(taps),
        recording_path=live.output,
        freeze_on=opts.freeze_on,
        title=f"live: {names}",
        keep=opts.keep,
    )


def capture_plan(
    opts: TuiOptions,
    stack: ExitStack,
    extra: Callable[[BusRates], list[Listener]] | None = None,
) -> SessionPlan:
    """The plan of the capture ``opts.capture`` replayed; ``extra`` makes the listeners it
    feeds besides the TUI's, given the capture's rates (its health as the TUI's own)."""
    from .app import SessionPlan

    capture = opts.capture
    if capture is None:
        raise ValueError("a capture plan needs a capture")
    if opts.live.output:
        raise UsageError(
            "-o records live sources; a capture is already recorded (export from the TUI "
            "with 'e' instead)"
        )
    reader = stack.enter_context(open_reader(capture))
    source = ReplaySource(reader, capture.speed)
    options = SessionOptions(protocol=byte_protocol(capture), engine=capture.engine)
    rates = rates_of_capture(reader.metadata, opts.rates.bitrate, opts.rates.baud)
    outputs = [] if extra is None else extra(rates)

    def build(tui: list[Listener]) -> Session:
        return Session(source, [*outputs, *tui], options)

    return SessionPlan(
        build,
        live=False,
        replay=source,
        rates=rates,
        freeze_on=opts.freeze_on,
        title=f"capture: {capture.path}",
        keep=opts.keep,
    )


def check_capture_engine(capture: CaptureOptions) -> None:
    """UsageError if the engine asked for cannot decode the capture (asked before the terminal
    is, and before any output such as ``--rerun``'s file is made)."""
    if capture.engine == "auto":
        return
    with open_reader(capture) as reader:
        try:
            session_engine(capture.engine, reader.kind, reader.single_stream)
        except ValueError as exc:
            raise UsageError(f"--engine {capture.engine}: {exc}") from None


def require_terminal() -> None:
    if not sys.stdout.isatty():
        raise UsageError(
            "the TUI needs a terminal; for text use 'eg2scope live', 'eg2scope demo' or "
            "'eg2scope decode'"
        )


def summary_line(opts: TuiOptions, app: Eg2ScopeApp) -> str:
    """What the session did: of a capture, what was read of it; live, what was captured."""
    counts = app.session.counts
    replay = app.plan.replay
    if replay is None:
        where = f" into {opts.live.output}" if opts.live.output else ""
        return f"{counts.line()}{where}"
    read = "read to its end" if replay.finished else f"stopped at {replay.position:.0%}"
    return f"{opts.path}: {read}, {counts.records:,} records decoded, {counts.errors:,} with errors"


def finish(opts: TuiOptions, app: Eg2ScopeApp, notes: Notes) -> int:
    """After the app has gone: what happened, on stderr, and the exit status."""
    notes.print(sys.stderr)
    session = app.session
    print(f"eg2scope: {summary_line(opts, app)}", file=sys.stderr)
    for listener, exc in session.detached:
        label = getattr(listener, "label", type(listener).__name__)
        print(f"eg2scope: error: {label} failed: {exc}", file=sys.stderr)
    for err in session.source.errors:
        print(f"eg2scope: {opts.path}: {err}", file=sys.stderr)
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
    """Ctrl-C, SIGTERM, SIGHUP or the terminal gone: end the session as an interrupt and quit
    as 'q' does. The quit is queued (from any thread) with the app's messages: it runs once the
    app has mounted its panes (quitting in the middle of that fails in Textual), or not at all
    when the app has ended."""
    if app.session is not None:
        app.session.interrupt()
    app.call_later(app.action_quit)
