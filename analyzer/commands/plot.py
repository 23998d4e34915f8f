"""``eg2scope plot``: force, opening, current, temperature and state of every gripper on one
clock in Rerun, from a capture, a recording or a live bus (docs/rerun.md)."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from ..errors import EXIT_INTERRUPTED, UsageError
from ..live_runner import run_session
from ..plot.target import (
    SERVE_WEB,
    SPAWN,
    RerunTarget,
    connect_target,
    default_target,
    save_target,
)
from ..session.batches import session_engine
from ..session.capture import CaptureOptions, finish_capture, open_reader, run_capture
from ..session.engine import ENGINES
from ..session.listener import Listener
from ..session.session import Session
from ..sources.capture import CaptureReader
from .common import add_session_arguments, protocol_type, speed_type
from .demo import add_demo_arguments
from .helptext import CAPTURE_FILE, EXIT_STATUS, HelpFormatter, epilog
from .livesource import CAN_KEYS, add_source_arguments, open_taps


def add_subparser(sub: Any) -> None:
    parser = sub.add_parser(
        "plot",
        help="plot force, opening, state and errors of every gripper in Rerun",
        description=(
            "Plot what each gripper's opening, force, current, temperature and state did, and "
            "the controller's commands and the bus's errors, on one clock in Rerun: from any "
            "capture 'decode' reads or an eg2scope .mcap recording, or live from a bus. Every "
            "reading is plotted (nothing is downsampled), on the timelines capture_time and "
            "frame (the record's seq, as the TUI and the recording number it). By default the "
            "Rerun viewer is spawned when a display can be opened; otherwise <capture>.rrd is "
            "written in the current directory and the command that opens it is printed. The "
            "layout shows a plot only for what the capture carries, every plot of a capture "
            "over its whole span on one linked time axis (see docs/rerun.md)."
        ),
        epilog=epilog(
            "examples:\n"
            "  eg2scope plot captures/can_pick_place.log\n"
            "  eg2scope plot run.mcap --save run.rrd        # then: rerun run.rrd\n"
            "  eg2scope plot --demo                         # simulated grippers, live\n"
            "  eg2scope plot -i socketcan -c can0 --serve-web",
            EXIT_STATUS,
        ),
        formatter_class=HelpFormatter,
    )
    parser.add_argument(
        "file",
        nargs="?",
        help=f"{CAPTURE_FILE} (or give a live source or --demo instead)",
    )
    target = parser.add_argument_group(
        "where the plot goes (default: spawn a viewer, or "
        "write <capture>.rrd here when there is no display)"
    )
    where = target.add_mutually_exclusive_group()
    where.add_argument(
        "--save", metavar="FILE.rrd", help="write a Rerun recording file (replaced if there)"
    )
    where.add_argument("--spawn", action="store_true", help="spawn the Rerun viewer")
    where.add_argument(
        "--connect",
        nargs="?",
        const="",
        metavar="URL",
        help="send to a running viewer (default rerun+http://127.0.0.1:9876/proxy)",
    )
    where.add_argument(
        "--serve-web",
        action="store_true",
        help="serve Rerun's web viewer on 127.0.0.1 (this machine only) until Ctrl-C or "
        "SIGTERM; the printed address asks for the WebGL renderer, which needs no GPU",
    )
    capture = parser.add_argument_group("capture replay")
    capture.add_argument(
        "--speed",
        type=speed_type,
        default=None,
        metavar="X",
        help="replay with the capture's own timing sped up X times (1 = real time) or 'max' "
        "(default: all at once)",
    )
    capture.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    capture.add_argument(
        "--engine",
        choices=ENGINES,
        default="auto",
        help="the session's decoding: auto (the native core for CAN captures where it is built, "
        "else the Python decoders; default), python, or native (a usage error where it cannot "
        "decode the capture). The plot is the same either way",
    )
    add_source_arguments(parser)
    parser.add_argument(
        "--demo",
        action="store_true",
        help="plot the built-in demo live (simulated grippers on all three buses)",
    )
    add_demo_arguments(parser)
    add_session_arguments(parser, record_required=False)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    live = args.demo or live_source_given(args)
    if args.file and live:
        raise UsageError("give a capture file or a live source (or --demo), not both")
    if not args.file and not live:
        raise UsageError(
            "nothing to plot: give a capture file, a live source (-i/-c, "
            "--serial PORT) or --demo (see --help)"
        )
    if args.file:
        return plot_capture(args)
    return plot_live(args)


def live_source_given(args: argparse.Namespace) -> bool:
    can_given = any(key in args for key in CAN_KEYS) or bool(getattr(args, "bus_kwargs", None))
    return can_given or bool(args.serial) or bool(getattr(args, "bridge", None))


def chosen_target(args: argparse.Namespace, source: str | None) -> RerunTarget:
    """The target the options name, or the default for ``source`` (None: a live session)."""
    if args.save:
        if source is not None and args.save == source:
            raise UsageError(f"--save {args.save} would overwrite the capture being plotted")
        return save_target(args.save)
    if args.spawn:
        return RerunTarget(SPAWN)
    if args.connect is not None:
        return connect_target(args.connect or None)
    if args.serve_web:
        return RerunTarget(SERVE_WEB)
    return default_target(source)


def plot_capture(args: argparse.Namespace) -> int:
    from ..plot.listener import LIVE_FLUSH_S, RerunListener

    if args.output:
        raise UsageError("-o records a live source; a capture is plotted as it is")
    try:
        protocol = protocol_type(args.protocol or "auto")
    except argparse.ArgumentTypeError as exc:
        raise UsageError(str(exc)) from None
    opts = CaptureOptions(
        path=args.file,
        protocol=protocol,
        bus=args.bus,
        speed=args.speed,
        progress=not args.no_progress,
        engine=args.engine,
    )
    target = chosen_target(args, args.file)
    reader = open_reader(opts)  # a capture that cannot be read fails before a viewer opens
    try:
        try:  # an engine that cannot decode this capture: said before a viewer opens
            session_engine(args.engine, reader.kind, reader.single_stream)
        except ValueError as exc:
            raise UsageError(f"--engine {args.engine}: {exc}") from None
        # a paced replay is watched as it goes: update the viewer as often as live
        flush = LIVE_FLUSH_S if args.speed is not None else None
        listener = RerunListener(target, flush_interval=flush)
    except BaseException:
        reader.close()
        raise
    unread = UnreadCapture(reader, listener.output)  # closed first: it may discard the plot
    session, reader = run_capture(opts, [unread, listener], reader)
    code = finish_capture(args.file, session, reader)
    for _, failure in session.detached:
        print(f"eg2scope: error: the Rerun output failed: {failure}", file=sys.stderr)
    if code != EXIT_INTERRUPTED:
        listener.output.hold()
    listener.output.stop_server()
    return code


class UnreadCapture(Listener):
    """A capture from which nothing at all could be read gets no plot (no .rrd file); a
    damaged one that yielded anything keeps its plot."""

    wants_raw = True

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


def plot_live(args: argparse.Namespace) -> int:

    if args.demo:
        return _plot_demo(args)
    taps = open_taps(args)  # usage errors before a viewer opens
    target = chosen_target(args, args.output)
    made: list[Any] = []  # made once the taps are open: a source that fails makes no file
    ended: list[Session] = []
    code = run_session(
        args, taps, show=None, extra=lambda: made_listener(made, target), on_done=ended.append
    )
    return _finish_live(made[0], code, ended)


def made_listener(made: list[Any], target: RerunTarget) -> list[Any]:
    from ..plot.listener import RerunListener

    made.append(RerunListener(target, live=True))
    return made


def _plot_demo(args: argparse.Namespace) -> int:
    from .demo import run_demo

    target = chosen_target(args, args.output)
    made: list[Any] = []  # made once the rig runs: a refused -o makes no file
    ended: list[Session] = []
    code = run_demo(
        args, show=None, extra=lambda: made_listener(made, target), on_done=ended.append
    )
    return _finish_live(made[0], code, ended)


def _finish_live(listener: Any, code: int, ended: list[Session]) -> int:
    """A served web viewer stays up after a session that ran its course (--duration), not
    after the user stopped it."""
    if not any(session.counts.interrupted for session in ended):
        listener.output.hold()
    listener.output.stop_server()
    return code
