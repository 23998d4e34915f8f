"""The offline capture run through one session: the input options of an offline command
(typed: the core never sees argparse), the capture's reader and its checks, the record filter,
the progress bar, and the exit status a session ends with (docs/contracts.md)."""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from decoders.model import EG2_CAN, EG2_SERIAL, MODBUS_RTU
from decoders.registry import PROTOCOL_WORDS, short_name, valid_frames

from ..errors import EXIT_DAMAGED, EXIT_ERROR, EXIT_INTERRUPTED, EXIT_OK, UsageError
from ..model import SourceEvent
from ..outfile import OutputError
from ..sources import sniff
from ..sources.capture import CaptureReader, GzipBytesReader, RawBytesReader, open_capture
from ..sources.source import CaptureSource
from .batches import RecordSequence, SampleSequence
from .listener import Listener
from .session import Session, SessionCounts, SessionOptions
from .stage import DETECT_BYTES


@dataclass(frozen=True)
class DecodeOutput:
    """What ``eg2scope decode`` writes, typed: the format, the file (None or "-": stdout), the
    text's colour (None: as the output decides), times as given, and the parts' processes
    (``--jobs``; 0: as many as there are idle cores)."""

    fmt: str
    path: str | None = None
    colour: bool | None = None
    absolute_time: bool = False
    jobs: int = 0

    @property
    def binary(self) -> bool:
        return self.fmt in ("jsonl", "parquet")


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
    engine: str = "auto"  # the session's: analyzer/session/batches.py

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
        self.reads_whole_states = inner.reads_whole_states
        self.wants_raw = inner.wants_raw
        self.reads_frame_batches = inner.reads_frame_batches
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
    opts: CaptureOptions,
    listeners: list[Listener],
    reader: CaptureReader | None = None,
    whole: Sequence[Listener] = (),
) -> tuple[Session, CaptureReader]:
    """Decode a capture through one session into ``listeners`` (filtered by the options) and
    ``whole`` (every record: grip cycles and a bus's health are the whole bus's), with a progress
    bar on a terminal. Returns the finished session and its reader."""
    reader = reader or open_reader(opts)
    keep = opts.record_filter()
    if keep is not None:
        listeners = [FilteredListener(x, keep) for x in listeners]
    listeners = [*listeners, *whole]
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


def protocol_hint(opts: CaptureOptions, reader: CaptureReader) -> str:
    """When ``--protocol`` names a byte protocol that finds fewer valid frames in the start of
    a raw dump than another one: a hint naming the other ("" when the choice looks right).
    The dump is decoded as asked."""
    forced = opts.protocol
    if forced is None or not isinstance(reader, RawBytesReader | GzipBytesReader):
        return ""
    counts = valid_frames(sniff.head(opts.path)[:DETECT_BYTES])
    best = max(counts, key=lambda name: counts[name])
    if forced not in counts or counts[best] <= counts[forced]:
        return ""
    found = f"{counts[forced]} valid frames" if counts[forced] else "no valid frame"
    return (
        f"hint: --protocol {short_name(forced)} finds {found} in the first {DETECT_BYTES} "
        f"bytes; detection finds {counts[best]} {PROTOCOL_WORDS[best]} frames there: leave "
        f"--protocol out, or give --protocol {short_name(best)}"
    )


def raise_output_failure(session: Session, path: str | None) -> None:
    """The output listener was detached: fail (a file that was there before is kept)."""
    if not session.detached:
        return
    exc = session.detached[0][1]
    if isinstance(exc, BrokenPipeError):
        raise exc  # `| head`: the reader went away; the CLI stops quietly
    raise OutputError(f"cannot write {path or 'the output'}: {exc}")
