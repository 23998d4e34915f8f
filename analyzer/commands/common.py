"""What the offline commands (decode, stats, and later plot/tui on captures) share: the input
options, their checks, and running a capture through one session."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from decoders.model import EG2_CAN, EG2_SERIAL, MODBUS_RTU
from decoders.registry import resolve_protocol, short_name

from ..batches import RecordSequence, SampleSequence
from ..errors import EXIT_DAMAGED, EXIT_ERROR, EXIT_INTERRUPTED, EXIT_OK, UsageError
from ..listener import Listener
from ..model import SourceEvent
from ..session import Session, SessionCounts, SessionOptions
from ..sources.capture import CaptureReader, open_capture
from ..sources.pacing import parse_speed
from ..sources.source import CaptureSource
from .helptext import CAPTURE_FILE


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


@dataclass(frozen=True)
class CaptureOptions:
    """The input options of an offline command, typed (the core never sees argparse)."""

    path: str
    protocol: str | None = None
    bus: str | None = None
    device: int | None = None
    errors_only: bool = False
    speed: float | None = None
    progress: bool = True
    engine: str = "auto"  # the session's: analyzer/batches.py

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> CaptureOptions:
        return cls(
            path=args.file,
            protocol=args.protocol,
            bus=args.bus,
            device=args.device,
            errors_only=args.errors_only,
            speed=args.speed,
            progress=not args.no_progress,
            engine=getattr(args, "engine", "auto"),
        )

    def filter_words(self) -> str:
        """The record filter as the command line said it ("--device 2 --errors-only"); ''
        when there is none."""
        words = [] if self.device is None else [f"--device {self.device}"]
        return " ".join(words + (["--errors-only"] if self.errors_only else []))

    def record_filter(self) -> RecordFilter | None:
        """Which records of a batch ``--device`` and ``--errors-only`` keep (None: all)."""
        device, errors_only = self.device, self.errors_only
        if device is None and not errors_only:
            return None

        def keep(records: RecordSequence) -> list[int]:
            indexes = records.problems() if errors_only else range(len(records))
            if device is None:
                return list(indexes)
            devices = records.column("device")
            return [i for i in indexes if devices[i] == device]

        return keep


def open_reader(opts: CaptureOptions) -> CaptureReader:
    """The capture's reader; a usage error when the protocol option cannot apply to it."""
    reader = open_capture(opts.path, bus=opts.bus)
    if opts.protocol in (EG2_SERIAL, MODBUS_RTU) and reader.protocols:
        said = ", ".join(f"{bus}: {short_name(p)}" for bus, p in sorted(reader.protocols.items()))
        reader.close()
        raise UsageError(
            f"{opts.path} says which protocol each of its serial buses speaks ({said}), and is "
            f"decoded as it says: --protocol {short_name(opts.protocol)} is for raw dumps; "
            "leave it out"
        )
    if opts.protocol in (EG2_SERIAL, MODBUS_RTU) and reader.kind == "can":
        reader.close()
        raise UsageError(
            f"{opts.path} is a CAN capture, decoded as CAN: --protocol "
            f"{short_name(opts.protocol)} is for byte streams (raw serial or Modbus RTU dumps "
            "and lines); leave it out"
        )
    if opts.protocol == EG2_CAN and reader.kind != "can":
        reader.close()
        raise UsageError(
            f"{opts.path} is read as a byte stream, and CAN is chosen by the file, not by "
            "--protocol: give a CAN capture (candump .log, .asc, .blf, .trc, an eg2scope "
            ".mcap), or -p serial / -p modbus for this one"
        )
    return reader


def byte_protocol(opts: CaptureOptions) -> str | None:
    """The byte-stream protocol to force (None: detect); CAN needs no choice."""
    return None if opts.protocol == EG2_CAN else opts.protocol


#: the indexes of the records of a batch to pass on
RecordFilter = Callable[[RecordSequence], list[int]]


class FilteredListener(Listener):
    """Passes on only the records ``keep`` picks (``--device``, ``--errors-only``): a batch of
    the kind it came in (``records.take``), a native one still without a Record per record."""

    def __init__(self, inner: Listener, keep: RecordFilter) -> None:
        self.inner = inner
        self.keep = keep
        self.kept = 0  # records passed on
        self.wants_states = inner.wants_states
        self.wants_raw = inner.wants_raw
        self.label = getattr(inner, "label", type(inner).__name__)

    def on_records(self, records: RecordSequence) -> None:
        indexes = self.keep(records)
        if indexes:
            self.kept += len(indexes)
            kept = records if len(indexes) == len(records) else records.take(indexes)
            self.inner.on_records(kept)

    def on_states(self, samples: SampleSequence) -> None:
        self.inner.on_states(samples)

    def on_event(self, event: SourceEvent) -> None:
        self.inner.on_event(event)

    def on_raw(self, items: list[Any]) -> None:
        self.inner.on_raw(items)

    def tick(self, now: float) -> None:
        self.inner.tick(now)

    def close(self) -> None:
        self.inner.close()

    def on_error(self, exc: BaseException) -> None:
        self.inner.on_error(exc)


class ProgressListener(Listener):
    """A progress bar on stderr while a capture is read (terminals only)."""

    def __init__(self, reader: CaptureReader) -> None:
        from rich.console import Console
        from rich.progress import (
            BarColumn,
            DownloadColumn,
            Progress,
            TextColumn,
            TimeRemainingColumn,
            TransferSpeedColumn,
        )

        self.reader = reader
        self.records = 0
        self.progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            DownloadColumn(),
            TransferSpeedColumn(),
            TextColumn("{task.fields[records]:,} records"),
            TimeRemainingColumn(),
            console=Console(stderr=True),
            transient=True,
        )
        self.task = self.progress.add_task(reader.path.name, total=reader.size or None, records=0)
        self.progress.start()

    def on_records(self, records: RecordSequence) -> None:
        self.records += len(records)

    def tick(self, now: float) -> None:
        self.progress.update(self.task, completed=self.reader.position, records=self.records)

    def close(self) -> None:
        self.progress.stop()


def run_capture(
    opts: CaptureOptions, listeners: list[Listener], reader: CaptureReader | None = None
) -> tuple[Session, CaptureReader]:
    """Decode a capture through one session into ``listeners`` (filtered by the options), with
    a progress bar on a terminal. Returns the finished session and its reader."""
    reader = reader or open_reader(opts)
    keep = opts.record_filter()
    if keep is not None:
        listeners = [FilteredListener(x, keep) for x in listeners]
    if opts.progress and opts.speed is None and sys.stderr.isatty():
        listeners = [*listeners, ProgressListener(reader)]
    options = SessionOptions(protocol=byte_protocol(opts), engine=opts.engine)
    session = Session(CaptureSource(reader, opts.speed), listeners, options)
    with reader:
        session.run()
    return session, reader


def finish_capture(
    path: str, session: Session, reader: CaptureReader, opts: CaptureOptions | None = None
) -> int:
    """Report damage, an empty capture and failed outputs on stderr; the exit code
    (docs/contracts.md). ``opts``: the filter the records went through (none: all shown)."""
    for err in reader.errors:
        print(f"eg2scope: {path}: {err}", file=sys.stderr)
    if session.counts.interrupted:
        print("eg2scope: interrupted", file=sys.stderr)
    elif not reader.errors:  # damage says why itself
        words = "" if opts is None else opts.filter_words()
        shown = session.counts.records
        if words:
            shown = sum(x.kept for x in session.listeners if isinstance(x, FilteredListener))
        report_empty(path, reader.size, shown, words)
    return exit_code(session.counts, damaged=bool(reader.errors), failed=bool(session.detached))


def report_empty(path: str, size: int, records: int, filter_words: str = "") -> None:
    """Say on stderr that a capture held nothing to show (``records``: those shown, after
    the filter ``filter_words`` names), so silence is never the answer: an empty file, a
    capture without a frame, a filter that matched none."""
    if records:
        return
    if size == 0:
        why = "empty file: no records"
    elif filter_words:
        why = f"no records matched {filter_words}"
    else:
        why = "no frames in this capture: no records"
    print(f"eg2scope: {path}: {why}", file=sys.stderr)


def exit_code(counts: SessionCounts, damaged: bool = False, failed: bool = False) -> int:
    """A session's exit status (docs/contracts.md): a failed output or device is an error; a
    live session stopped by the user ended as it should (0), a capture cut short is 130."""
    if failed:
        return EXIT_ERROR
    if counts.interrupted and not counts.live:
        return EXIT_INTERRUPTED
    return EXIT_DAMAGED if damaged else EXIT_OK
