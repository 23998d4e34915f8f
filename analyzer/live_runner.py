"""Running a live session for a live command (live, record, bridge, demo, a live plot): the
source opened first (a device that does not open fails at once, before any output is made), the
outputs, a status line, source events as they happen, and a clean ending: a user's stop (Ctrl-C,
SIGTERM, SIGHUP) or the end of ``--duration`` is how a live capture ends, exit 0. The options
come typed (``LiveOptions``), never as the command line's namespace."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import IO, TYPE_CHECKING, Any

from decoders.framing import LINE_BITS_PER_BYTE
from decoders.model import Record

from . import __version__
from .errors import UsageError
from .model import SourceEvent
from .outfile import check_new_file
from .session.batches import session_engine
from .session.capture import exit_code
from .session.listener import Listener, make_listener
from .session.session import Session, SessionOptions
from .sinks.text import format_event, use_colour
from .sources.live import Tap
from .sources.naming import BUS_BY_PROTOCOL
from .sources.source import LiveSource

if TYPE_CHECKING:
    from .sim.demo_options import DemoOptions

# a live command's own listeners: a list, or what makes them once the taps are open
Extra = list[Listener] | Callable[[], list[Listener]] | None


@dataclass(frozen=True)
class LiveOptions:
    """A live session's options, typed. ``protocol``: the byte protocol's name or alias ("auto"
    or None: detected per stream); ``output``: the MCAP file to record (None: no recording);
    ``force``: replace that file if it is there; ``duration``: seconds until the session stops
    (None: until the user stops it); ``queue_size``: items buffered between capture and
    decoding; ``rerun``: a Rerun target the session also goes to (None: no plot); ``engine``:
    the session's decoding (``--engine``: a usage error where it cannot decode the sources)."""

    protocol: str | None
    output: str | None
    force: bool
    duration: float | None
    queue_size: int
    rerun: str | None = None
    engine: str = "auto"


class StatusLine(Listener):
    """What a recorder shows on a terminal when it prints no records: a status line with the
    counts and each source's state, refreshed twice a second, and source events as they happen
    (events are printed whether or not stderr is a terminal)."""

    def __init__(self, session: Session, label: str, taps: list[Tap], out: IO[str]) -> None:
        self.session = session
        self.label = label
        self.taps = taps
        self.out = out
        self.live = out.isatty()
        self.colour = use_colour(out)
        self._next = 0.0

    def on_records(self, records: Sequence[Record]) -> None:
        pass  # counted by the session

    def on_event(self, event: SourceEvent) -> None:
        self._clear()
        self.out.write(format_event(event, self.colour) + "\n")
        self._next = 0.0

    def tick(self, now: float) -> None:
        if not self.live or time.monotonic() < self._next:
            return
        self._next = time.monotonic() + 0.5
        states = ", ".join(f"{t.bus} {'open' if t.is_open else 'waiting'}" for t in self.taps)
        self.out.write(f"\r\x1b[2K{self.label}: {self.session.counts.line()} [{states}]")
        self.out.flush()

    def close(self) -> None:
        self._clear()

    def _clear(self) -> None:
        if self.live:
            self.out.write("\r\x1b[2K")
            self.out.flush()


def metadata(taps: list[Tap]) -> dict[str, Any]:
    return {
        "tool": "eg2scope",
        "version": __version__,
        "command": " ".join(sys.argv),
        "sources": [
            {**_bus_metadata(t), "type": type(t).__name__, "passive": t.passive, **t.settings}
            for t in taps
        ],
        "passive": (
            "yes"
            if all(t.passive == "yes" for t in taps)
            else "no"
            if any(t.passive == "no" for t in taps)
            else "unknown"
        ),
    }


def _bus_metadata(tap: Tap) -> dict[str, Any]:
    """A source's bus in the metadata; one named by its protocol later has none yet."""
    if not tap.named_by_protocol:
        return {"bus": tap.bus}
    names = ", ".join(f"{name} ({protocol})" for protocol, name in BUS_BY_PROTOCOL.items())
    return {"bus": None, "bus_named_by_protocol": names}


def byte_times(taps: list[Tap]) -> dict[str, float]:
    """Seconds per byte of each serial bus (10 bits per byte: start, 8 data, stop)."""
    out: dict[str, float] = {}
    for tap in taps:
        baud = tap.settings.get("baudrate")
        if isinstance(baud, int | float) and baud > 0:
            out[tap.bus] = LINE_BITS_PER_BYTE / baud
    return out


def check_recording_name(path: str) -> None:
    if not path.lower().endswith(".mcap"):
        raise UsageError(f"recordings are MCAP files: name the output *.mcap, not {path}")


def check_recording_output(options: LiveOptions) -> None:
    """``-o``, before anything starts: an MCAP name, a folder that is there, and no file that
    a recording would replace unless ``--force``."""
    if options.output:
        check_recording_name(options.output)
        check_new_file(options.output, options.force)


def recorder(path: str, taps: list[Tap]) -> Listener:
    check_recording_name(path)
    return make_listener("mcap", path, metadata=metadata(taps))


def open_source(
    taps: list[Tap], queue_size: int, on_start: Callable[[], None] | None = None
) -> LiveSource:
    """The taps as a started source: every device opened (or waited for, ``--wait``);
    ``SourceError`` naming each device that did not open, and why."""
    source = LiveSource(taps, queue_size)
    source.on_started = on_start
    source.start()
    return source


def run_session(
    options: LiveOptions,
    taps: list[Tap],
    show: str | None = "text",
    per_bus: dict[str, str] | None = None,
    on_start: Callable[[], None] | None = None,
    extra: Extra = None,
    on_done: Callable[[Session], None] | None = None,
) -> int:
    """Watch ``taps`` with the outputs the options ask for: ``show`` "text" or "jsonl" on
    stdout (None: a status line and events on stderr), and an MCAP recording with ``-o``.
    The taps are opened first: a device that does not open fails the command before a file is
    made (``extra``: more listeners, or what makes them once the taps are open, so an output
    file of theirs is never made for a source that fails). ``on_done`` is handed the finished
    session."""
    protocol = session_protocol(options.protocol)
    check_recording_output(options)
    session_options = SessionOptions(
        protocol=protocol,
        per_bus=per_bus or {},
        byte_time_s=byte_times(taps),
        duration=options.duration,
        engine=options.engine,
    )
    source = open_source(taps, options.queue_size, on_start)
    try:  # until the session runs, the source is closed here if anything fails
        session = Session(source, _outputs(options, taps, show, extra), session_options)
    except BaseException:
        source.stop()
        raise
    if show is None:
        what = f"recording {options.output}" if options.output else "watching"
        session.listeners.append(StatusLine(session, what, taps, sys.stderr))
    session.run()
    if on_done is not None:
        on_done(session)
    return _report(session, taps, options.output)


def check_live_engine(engine: str, kind: str) -> None:
    """A usage error for an engine that cannot decode a live source whose items are of ``kind``
    (``sources.source.live_kind``, ``DemoOptions.kind``): asked before anything is opened,
    shown or written."""
    try:
        session_engine(engine, kind, positional=False)
    except ValueError as exc:
        raise UsageError(f"--engine {engine}: {exc}") from None


def session_protocol(name: str | None) -> str | None:
    """The byte protocol a name or alias says (None, "auto": detected per stream)."""
    from decoders.registry import resolve_protocol

    if name is None or name == "auto":
        return None
    try:
        return resolve_protocol(name)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def _report(session: Session, taps: list[Tap], output: str | None) -> int:
    """What the session did and what failed, on stderr, and the exit status."""
    counts = session.counts
    where = f" into {output}" if output else ""
    stopped = "stopped: " if counts.interrupted else ""
    print(f"eg2scope: {stopped}{counts.line()}{where}", file=sys.stderr)
    for listener, failure in session.detached:
        label = getattr(listener, "label", type(listener).__name__)
        print(f"eg2scope: error: {label} failed: {failure}", file=sys.stderr)
    failed_taps = [tap for tap in taps if tap.failed]
    for tap in failed_taps:
        print(f"eg2scope: error: {tap.bus} failed: {tap.failed}", file=sys.stderr)
    return exit_code(counts, failed=bool(session.detached or failed_taps))


def _outputs(
    options: LiveOptions, taps: list[Tap], show: str | None, extra: Extra
) -> list[Listener]:
    listeners: list[Listener] = list((extra() if callable(extra) else extra) or [])
    if show == "text":  # live: time counts from the session's start
        listeners.append(make_listener("text", sys.stdout, t0=time.time()))
    elif show is not None:
        listeners.append(make_listener(show, sys.stdout.buffer))
    if options.output:
        listeners.append(recorder(options.output, taps))
    if options.rerun is not None:  # Rerun is imported only when it is asked for
        from .health.rates import rates_of_capture
        from .plot.listener import rerun_listener

        rates = rates_of_capture(metadata(taps))  # each tap's own rate
        rerun = rerun_listener(options.rerun, source=options.output, rates=rates)
        listeners += [] if rerun is None else [rerun]
    return listeners


def run_demo(
    command: str,
    demo: DemoOptions,
    options: LiveOptions,
    show: str | None,
    extra: Extra = None,
    on_done: Callable[[Session], None] | None = None,
) -> int:
    """The simulated grippers through one live session, for ``eg2scope COMMAND`` (``extra``:
    more listeners; ``on_done``: handed the finished session)."""
    from .sim.rig import DemoRig

    check_recording_output(options)  # before the banner and the rig
    with DemoRig.of(demo) as rig:
        print(
            f"eg2scope {command}: {_demo_grippers(demo)} on "
            + ", ".join(f"{t.bus} ({type(t).__name__})" for t in rig.taps)
            + "; Ctrl-C to stop",
            file=sys.stderr,
        )
        return run_session(
            options,
            rig.taps,
            show=show,
            per_bus=rig.protocols,
            on_start=rig.run_hosts,
            extra=extra,
            on_done=on_done,
        )


def _demo_grippers(demo: DemoOptions) -> str:
    """Who is simulated, for the banner."""
    if demo.scenario is None:
        return "simulated grippers 1 and 2"
    return f"simulated gripper 1 playing scenario {demo.scenario.name!r}"
