"""``eg2scope plot``'s run: a capture, or a live session (live sources or the demo), into a
Rerun view (docs/rerun.md). Rerun is imported only when the view is made."""

from __future__ import annotations

import sys
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

from ..errors import EXIT_INTERRUPTED, UsageError
from ..health.rates import BusRates, RateOptions, rates_of_capture
from ..live_runner import LiveOptions, check_live_engine, metadata, run_demo, run_session
from ..session.batches import session_engine
from ..session.capture import CaptureOptions, finish_capture, open_reader, run_capture
from ..session.listener import Listener
from ..session.session import Session
from ..sim.demo_options import DemoOptions
from ..sources.capture import CaptureReader
from ..sources.source import live_kind
from ..sources.tap_options import TapOptions, make_taps
from .target import RerunTarget, TargetChoice, chosen_target

if TYPE_CHECKING:
    from .listener import RerunListener


@dataclass(frozen=True)
class PlotOptions:
    """``eg2scope plot``'s options, typed. ``target``: where the plot goes; ``live``: a live
    session's (its recording, its end); ``taps``: the live sources; ``capture``: a capture to
    plot instead (None: live); ``rates``: the rates given for the capture's bus health;
    ``demo``: the simulated buses to plot instead (None: none). A bus's load is counted at the
    rate given, else the rate a recording says its tap ran at, a live tap's own, or the EG2's
    (``health.rates``)."""

    target: TargetChoice
    live: LiveOptions
    taps: TapOptions
    capture: CaptureOptions | None = None
    rates: RateOptions = field(default_factory=RateOptions)
    demo: DemoOptions | None = None


def plot(opts: PlotOptions) -> int:
    """Plot what the options name: a capture, or one live source (the demo, or taps)."""
    live = opts.demo is not None or opts.taps.given
    if opts.capture is not None and (opts.demo is not None or _names_a_tap(opts.taps)):
        raise UsageError("give a capture file or a live source (or --demo), not both")
    if opts.capture is None and not live:
        raise UsageError(
            "nothing to plot: give a capture file, a live source (-i/-c, "
            "--serial PORT) or --demo (see --help)"
        )
    if opts.capture is None:
        return plot_live(opts)
    if opts.live.output:
        raise UsageError("-o records a live source; a capture is plotted as it is")
    return plot_capture(opts.capture, opts.target, opts.rates)


def _names_a_tap(taps: TapOptions) -> bool:
    """Whether the source options name a live source: ``-b`` alone is a capture's bit rate."""
    return replace(taps, can={k: v for k, v in taps.can.items() if k != "bitrate"}).given


def plot_capture(capture: CaptureOptions, choice: TargetChoice, given: RateOptions) -> int:
    """The capture in Rerun, its bus health at the rates ``given`` (where not given, its own or
    the EG2's); a served web viewer stays up unless the user stopped it."""
    target = chosen_target(choice, capture.path)
    reader = open_reader(capture)  # a capture that cannot be read fails before a viewer opens
    try:
        rates = rates_of_capture(reader.metadata, given.bitrate, given.baud)
        listener = _capture_listener(capture, reader, target, rates)
    except BaseException:
        reader.close()
        raise
    unread = UnreadCapture(reader, listener.output)  # closed first: it may discard the plot
    session, reader = run_capture(capture, [unread, listener], reader)
    code = finish_capture(capture.path, session, reader)
    for _, failure in session.detached:
        print(f"eg2scope: error: the Rerun output failed: {failure}", file=sys.stderr)
    if code != EXIT_INTERRUPTED:
        listener.output.hold()
    listener.output.stop_server()
    return code


def _capture_listener(
    capture: CaptureOptions, reader: CaptureReader, target: RerunTarget, rates: BusRates
) -> RerunListener:
    """The Rerun listener of a capture; a usage error, before a viewer opens, for an engine
    that cannot decode it."""
    from .listener import LIVE_FLUSH_S, RerunListener

    try:
        session_engine(capture.engine, reader.kind, reader.single_stream)
    except ValueError as exc:
        raise UsageError(f"--engine {capture.engine}: {exc}") from None
    # a paced replay is watched as it goes: update the viewer as often as live
    flush = LIVE_FLUSH_S if capture.speed is not None else None
    return RerunListener(target, flush_interval=flush, rates=rates)


class UnreadCapture(Listener):
    """A capture from which nothing at all could be read gets no plot (no .rrd file); a
    damaged one that yielded anything keeps its plot. It only counts the raw items, so a
    candump log is still read natively (a native ``FrameBatch`` has a length too)."""

    wants_raw = True
    reads_frame_batches = True

    def __init__(self, reader: CaptureReader, output: Any) -> None:
        self.reader = reader
        self.output = output
        self.items = 0

    def on_raw(self, items: list[Any]) -> None:
        self.items += len(items)

    def on_records(self, records: Any) -> None:
        pass

    def close(self) -> None:
        if self.reader.errors and not self.items:
            self.output.discard()


def plot_live(opts: PlotOptions) -> int:
    """A live session in Rerun: the demo's, or the taps'."""
    if opts.demo is not None:
        check_live_engine(opts.live.engine, opts.demo.kind)  # before the rig and a viewer
        return _plot_demo(opts.demo, opts)
    taps = make_taps(opts.taps)  # usage errors before a viewer opens
    check_live_engine(opts.live.engine, live_kind(taps))
    target = chosen_target(opts.target, opts.live.output)
    made: list[Any] = []  # made once the taps are open: a source that fails makes no file
    ended: list[Session] = []
    rates = rates_of_capture(metadata(taps))  # the taps' own
    code = run_session(
        opts.live,
        taps,
        show=None,
        extra=lambda: made_listener(made, target, rates),
        on_done=ended.append,
    )
    return _finish_live(made[0], code, ended)


def made_listener(made: list[Any], target: RerunTarget, rates: BusRates) -> list[Any]:
    from .listener import RerunListener

    made.append(RerunListener(target, live=True, rates=rates))
    return made


def _plot_demo(demo: DemoOptions, opts: PlotOptions) -> int:
    target = chosen_target(opts.target, opts.live.output)
    made: list[Any] = []  # made once the rig runs: a refused -o makes no file
    ended: list[Session] = []
    code = run_demo(
        "plot",
        demo,
        opts.live,
        show=None,
        extra=lambda: made_listener(made, target, BusRates()),
        on_done=ended.append,
    )
    return _finish_live(made[0], code, ended)


def _finish_live(listener: Any, code: int, ended: list[Session]) -> int:
    """A served web viewer stays up after a session that ran its course (--duration), not
    after the user stopped it."""
    if not any(session.counts.interrupted for session in ended):
        listener.output.hold()
    listener.output.stop_server()
    return code
