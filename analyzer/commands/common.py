"""The options several commands share, and their typed forms: the input options of the offline
commands (decode, stats, plot and tui on captures), the rates a capture's bus health is counted
at, and the options of a live session."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from decoders.registry import resolve_protocol

from ..errors import UsageError
from ..health.rates import DEFAULT_BAUD, DEFAULT_BITRATE, RateOptions
from ..plot.target import DEFAULT as DEFAULT_TARGET
from ..session.capture import CaptureOptions
from ..session.engine import ENGINES
from ..sources.pacing import parse_speed
from .helptext import CAPTURE_FILE

if TYPE_CHECKING:
    from ..live_runner import LiveOptions


def _whole_number(text: str, lowest: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if value < lowest:
        raise argparse.ArgumentTypeError(f"must be {lowest} or more, not {value}")
    return value


def non_negative_int(text: str) -> int:
    """argparse type: 0, 1, 2, ... (a usage error otherwise)."""
    return _whole_number(text, 0)


def positive_int(text: str) -> int:
    """argparse type: 1, 2, 3, ..."""
    return _whole_number(text, 1)


def positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number, not {text}")
    return value


def probability(text: str) -> float:
    """argparse type: a probability from 0 to 1."""
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"must be a probability from 0 to 1, not {text}")
    return value


def protocol_type(text: str) -> str | None:
    """argparse type: a protocol name or alias, or "auto" (None: detected)."""
    if text.lower() == "auto":
        return None
    try:
        return resolve_protocol(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{exc}, or auto (detected)") from None


def speed_type(text: str) -> float | None:
    try:
        return parse_speed(text)
    except UsageError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_protocol_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--protocol",
        "-p",
        type=protocol_type,
        default=None,
        metavar="NAME",
        help="byte-stream protocol: serial (EB 90 / EE 16 frames), modbus (Modbus RTU) or "
        "auto (default: detected from the bytes; decode hints when the one given finds fewer "
        "frames). CAN is chosen by the file: CAN captures are always decoded as CAN, and "
        "serial or modbus on one is a usage error.",
    )


def add_input_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "file",
        help=CAPTURE_FILE,
    )
    add_protocol_argument(parser)
    parser.add_argument(
        "--bus",
        metavar="NAME",
        help="bus name to put in records (default: the CAN channel in the file, or 'serial')",
    )
    parser.add_argument(
        "--device", "-d", type=non_negative_int, metavar="N", help="only records of device N"
    )
    parser.add_argument(
        "--errors-only",
        "-e",
        action="store_true",
        help="only records with errors or warnings (bad checksums, garbage, no response, ...)",
    )
    parser.add_argument(
        "--speed",
        type=speed_type,
        default=None,
        metavar="X",
        help="replay with the capture's own timing sped up X times (1 = real time, 10, ...) or "
        "'max' (default: as fast as possible)",
    )
    parser.add_argument("--no-progress", action="store_true", help="never show a progress bar")


def capture_options(args: argparse.Namespace) -> CaptureOptions:
    """The input options of an offline command's arguments."""
    return CaptureOptions(
        path=args.file,
        protocol=args.protocol,
        bus=args.bus,
        device=args.device,
        errors_only=args.errors_only,
        speed=args.speed,
        progress=not args.no_progress,
        engine=getattr(args, "engine", "auto"),
    )


# (option, its short form, metavar, what it is, what of a capture's bus health it counts);
# -b as python-can's, which tui's and plot's live sources take
RATE_OPTIONS = (
    (
        "--bitrate",
        "-b",
        "BPS",
        "CAN bit rate for",
        f"bus load, every CAN bus (default: the rate a recording says its tap ran at, else "
        f"{DEFAULT_BITRATE}, the EG2's)",
    ),
    (
        "--baud",
        None,
        "N",
        "serial baud rate for",
        f"line use, gaps and turnaround, every serial bus (default: the rate a recording says "
        f"its tap ran at, else {DEFAULT_BAUD}, the EG2's)",
    ),
)


def add_rate_arguments(parser: argparse.ArgumentParser) -> None:
    """``--bitrate`` and ``--baud``: the rates a capture's bus health is counted at. A command
    whose live sources take them already (python-can's ``-b/--bitrate``, the serial tap's
    ``--baud``: tui, plot; add them first) keeps those, their help saying what they do to a
    capture: one option for both, not a second that clashes."""
    for flag, short, metavar, what, figures in RATE_OPTIONS:
        # argparse has no public look-up of an option already added
        live = parser._option_string_actions.get(flag)
        if live is None:
            flags = (flag,) if short is None else (flag, short)
            parser.add_argument(
                *flags, type=positive_int, metavar=metavar, help=f"{what} a capture's {figures}"
            )
        else:
            tap = (live.help or "").rstrip(".")
            live.help = f"{tap}; replaying a capture file, the {what} its {figures}"


def rate_options(args: argparse.Namespace) -> RateOptions:
    """The rates ``add_rate_arguments``' options give a capture (None: not given). A usage
    error for one that is not positive: a live source's own ``-b`` and ``--baud`` take any
    whole number, and are checked where its tap is made."""
    given = RateOptions(getattr(args, "bitrate", None), getattr(args, "baud", None))
    for (flag, *_), value in zip(RATE_OPTIONS, (given.bitrate, given.baud), strict=True):
        if value is not None and value < 1:
            raise UsageError(f"{flag} of a capture must be a positive number, not {value}")
    return given


def add_session_arguments(parser: argparse.ArgumentParser, record_required: bool) -> None:
    """The options of a live session (its outputs and its end); a live command runs until it
    is stopped, and a stop is a clean end (``cli.runs_until_stopped``)."""
    parser.set_defaults(until_stopped=True)
    parser.add_argument(
        "--output",
        "-o",
        metavar="RUN.mcap",
        required=record_required,
        help="record raw input, decoded records, device state and events to this MCAP file "
        "(an existing file is refused unless --force)",
    )
    parser.add_argument(
        "--force",
        action="store_true",
        help="replace the -o file if it exists (without it, an existing file is a usage error)",
    )
    parser.add_argument(
        "--duration",
        type=positive_float,
        metavar="S",
        help="stop after S seconds (default: run until Ctrl-C)",
    )
    parser.add_argument(
        "--queue-size",
        type=positive_int,
        default=200_000,
        metavar="N",
        help="items buffered between capture and decoding before drops are "
        "counted (default 200000)",
    )


def live_options(args: argparse.Namespace) -> LiveOptions:
    """The options of a live session's arguments, typed (``--rerun``: None where the command
    has none)."""
    from ..live_runner import LiveOptions  # imported by live commands only: decode needs none

    return LiveOptions(
        protocol=args.protocol,
        output=args.output,
        force=args.force,
        duration=args.duration,
        queue_size=args.queue_size,
        rerun=getattr(args, "rerun", None),
        engine=getattr(args, "engine", "auto"),
    )


def add_rerun_argument(parser: argparse.ArgumentParser) -> None:
    """``--rerun [TARGET]``: the session also goes to Rerun (see ``parse_target``)."""
    parser.add_argument(
        "--rerun",
        nargs="?",
        const=DEFAULT_TARGET,
        default=None,
        metavar="TARGET",
        help="also plot the session in Rerun: spawn (a viewer, the default when a display can "
        "be opened; otherwise a dated .rrd file is written here), web (Rerun's web viewer on "
        "127.0.0.1), a viewer URL rerun+http://HOST:PORT/proxy, or a file NAME.rrd",
    )


def add_replay_arguments(parser: argparse.ArgumentParser, unpaced: str, same: str) -> None:
    """A capture's replay options: ``--speed`` (``unpaced``: what happens without it),
    ``--no-progress`` and ``--engine`` (``same``: what the choice leaves as it is)."""
    capture = parser.add_argument_group("capture replay")
    capture.add_argument(
        "--speed",
        type=speed_type,
        default=None,
        metavar="X",
        help="replay with the capture's own timing sped up X times (1 = real time) or 'max' "
        f"(default: {unpaced})",
    )
    capture.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    capture.add_argument(
        "--engine",
        choices=ENGINES,
        default="auto",
        help="the session's decoding, of a capture or a live source: auto (the native core for "
        "CAN input and raw dumps where it is built, else the Python decoders; default), "
        "python, or native (a usage error where it cannot decode the input: several byte "
        f"streams, as live serial taps, the demo's serial lines and their recordings). {same}",
    )


def whole_capture_options(args: argparse.Namespace) -> CaptureOptions:
    """The capture of a command that reads every record (no record filter: ``plot``,
    ``cycles``), from its file and ``add_replay_arguments``' options."""
    return CaptureOptions(
        path=args.file,
        protocol=args.protocol,
        bus=args.bus,
        speed=args.speed,
        progress=not args.no_progress,
        engine=args.engine,
    )
