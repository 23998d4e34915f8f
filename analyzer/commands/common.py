"""Options and the read-decode loop shared by the offline commands (decode, stats)."""

from __future__ import annotations

import argparse
import gc
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from decoders.model import Record
from decoders.registry import resolve_protocol

from ..pipeline import Decoding
from ..sources.capture import CaptureReader, open_capture
from ..sources.pacing import paced, parse_speed

BATCH = 4096


def add_input_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "file",
        help="capture to read: candump -L .log, python-can .asc/.blf/.trc/.csv/.mf4, an "
        "eg2scope .mcap recording, or any other file as raw serial bytes",
    )
    parser.add_argument(
        "--protocol",
        "-p",
        default="auto",
        metavar="NAME",
        help="byte-stream protocol: serial (EB 90 / EE 16 frames), modbus (Modbus RTU) or "
        "auto (default: detected from the bytes). CAN files are always decoded as CAN.",
    )
    parser.add_argument(
        "--bus",
        metavar="NAME",
        help="bus name to put in records (default: the CAN channel in the file, or 'serial')",
    )
    parser.add_argument("--device", "-d", type=int, metavar="N", help="only records of device N")
    parser.add_argument(
        "--errors-only",
        "-e",
        action="store_true",
        help="only records with errors or warnings (bad checksums, garbage, no response, ...)",
    )
    parser.add_argument(
        "--speed",
        default="max",
        metavar="X",
        help="replay with the capture's own timing sped up X times (1 = real time, 10, ...) or "
        "'max' (default: as fast as possible)",
    )
    parser.add_argument("--no-progress", action="store_true", help="never show a progress bar")


def protocol_of(args: argparse.Namespace) -> str | None:
    name = args.protocol
    return None if name in (None, "auto") else resolve_protocol(name)


def record_filter(args: argparse.Namespace) -> Callable[[Record], bool] | None:
    device, errors_only = args.device, args.errors_only
    if device is None and not errors_only:
        return None

    def keep(rec: Record) -> bool:
        if device is not None and rec.device != device:
            return False
        return not errors_only or bool(rec.errors or rec.warnings)

    return keep


@contextmanager
def progress_bar(reader: CaptureReader, enabled: bool) -> Iterator[Callable[[int], None]]:
    """A progress bar on stderr while reading, only when stderr is a terminal."""
    if not enabled or not sys.stderr.isatty():
        yield lambda n: None
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        DownloadColumn,
        Progress,
        TextColumn,
        TimeRemainingColumn,
        TransferSpeedColumn,
    )

    columns = (
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        DownloadColumn(),
        TransferSpeedColumn(),
        TextColumn("{task.fields[records]:,} records"),
        TimeRemainingColumn(),
    )
    with Progress(*columns, console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task(reader.path.name, total=reader.size or None, records=0)
        count = 0

        def tick(n: int) -> None:
            nonlocal count
            count += n
            bar.update(task, completed=reader.position, records=count)

        yield tick


@contextmanager
def batch_gc(every: int = 256) -> Iterator[Callable[[], None]]:
    """Records hold no reference cycles, so refcounting frees them; the cyclic collector only
    re-walks the live objects (the throughput of a large decode halves with it on). It is
    paused while decoding and run every ``every`` batches instead, so memory stays bounded
    even if some library makes cycles."""
    was_enabled = gc.isenabled()
    gc.disable()
    count = 0

    def batch_done() -> None:
        nonlocal count
        count += 1
        if count % every == 0:
            gc.collect(1)

    try:
        yield batch_done
    finally:
        if was_enabled:
            gc.enable()


def decoded_batches(args: argparse.Namespace) -> Iterator[list[Record]]:
    """Read the capture named in args, decode it, yield filtered record batches in order.
    Damage found in the file is reported on stderr after everything before it."""
    keep = record_filter(args)
    with (
        batch_gc() as batch_done,
        open_capture(args.file, bus=args.bus) as reader,
        progress_bar(reader, not args.no_progress) as tick,
    ):
        decoding = Decoding(protocol_of(args), positional_seq=reader.single_stream)
        feed = decoding.feed
        speed = parse_speed(args.speed)
        size = BATCH if speed is None else 1  # paced replay: show each record as it comes
        batch: list[Record] = []
        for item in paced(reader, speed):
            batch += feed(item)
            if len(batch) >= size:
                tick(len(batch))
                batch_done()
                yield batch if keep is None else [r for r in batch if keep(r)]
                batch = []
        batch += decoding.finish()
        tick(len(batch))
        yield batch if keep is None else [r for r in batch if keep(r)]
    for err in reader.errors:
        print(f"eg2scope: {args.file}: {err}", file=sys.stderr)
