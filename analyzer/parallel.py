"""Decoding a large capture file on every core: parts decoded in parallel, joined in order.

The decode path is sequential by nature (framing state, pending requests, timing rules), but
that state only reaches back a bounded way. Each worker decodes one part of the file, starting
``WARMUP`` bytes early and running ``WARMUP`` bytes past its end, so that framing, the CAN
direction table, pairing and the timing linter are in the same state as in a one-piece decode;
it keeps only the records that start inside its part. Records are numbered by their place in
the input (``seq`` = offset, or CAN frame index), the same in every worker.

The joins are checked: consecutive parts must meet exactly (byte streams: the last record of
one part ends where the next part's first record starts; CAN: frame indices follow on). If a
join does not hold (a garbage run or a pending request longer than the warm-up, a malformed
candump line), the caller decodes the file in one piece instead. Only raw byte dumps and
uncompressed candump logs are split; everything else is decoded in one piece.
"""

from __future__ import annotations

import argparse
import gc
import multiprocessing
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from decoders.model import CanFrame, Chunk, Record

from .pipeline import Decoding, Item
from .sources.can_files import CandumpReader, is_gzip
from .sources.capture import RawBytesReader, can_bus_name

# Part sizes and warm-ups per kind of input. A candump log carries time: its warm-up covers
# the longest a request may wait for its answer (a save, 2 s) on a busy bus. A raw dump has
# no timing, so pairing state lasts only until the next request: a short warm-up will do.
PART_BYTES = {"candump": 6 << 20, "bytes": 1 << 20}  # the smallest part
PART_MAX = 64 << 20  # the largest part (keeps the progress bar moving on huge files)
PARTS_PER_WORKER = 2  # few parts: each costs a warm-up; two per worker keep both busy
WARMUP = {"candump": 1 << 20, "bytes": 64 << 10}
MIN_PARALLEL_BYTES = {"candump": 8 << 20, "bytes": 2 << 20}  # smaller: one piece
READ = 1 << 16


class JoinError(Exception):
    """Two parts did not meet exactly: decode in one piece instead."""


@dataclass
class Part:
    path: str
    kind: str  # "bytes" or "candump"
    lo: int  # the part: records starting in [lo, hi)
    hi: int
    warm_lo: int  # decoded: [warm_lo, cool_hi)
    cool_hi: int
    size: int
    can_index: int  # frame index of the first line at warm_lo (candump)
    index_lo: int  # frame indices of the part itself (candump): [index_lo, index_hi)
    index_hi: int
    protocol: str | None
    bus: str | None
    fmt: str
    device: int | None
    errors_only: bool
    tmpdir: str


@dataclass
class PartResult:
    out_path: str
    first: int | None  # first record's offset (bytes) or index (CAN), before filtering
    end: int | None  # offset after the last record, or last index + 1
    records: int
    errors: list[str]


def splittable(path: Path, fmt: str, reader_kind: str) -> bool:
    """Worth and possible to split: large raw dumps and candump logs, JSONL or CSV out."""
    if fmt not in ("jsonl", "csv") or (os.cpu_count() or 1) < 2:
        return False
    if (
        reader_kind not in MIN_PARALLEL_BYTES
        or path.stat().st_size < MIN_PARALLEL_BYTES[reader_kind]
    ):
        return False
    return reader_kind != "candump" or not is_gzip(path)


def _line_starts(path: Path, points: list[int]) -> list[int]:
    """Move each point forward to the start of the next line."""
    out = []
    with path.open("rb") as f:
        for p in points:
            if p == 0:
                out.append(0)
                continue
            f.seek(p - 1)
            rest = f.readline()  # up to and including the newline ending the line at p-1
            out.append(p - 1 + len(rest))
    return out


def _frame_lines_before(path: Path, points: list[int]) -> list[int]:
    """How many candump frame lines (lines starting with '(') precede each point."""
    counts: dict[int, int] = {}
    n = 0
    pos = 0
    at_line_start = True
    with path.open("rb") as f:
        for p in sorted(set(points)):
            while pos < p:
                block = f.read(min(READ * 16, p - pos))
                if not block:
                    break
                n += block.count(b"\n(") + (1 if at_line_start and block[:1] == b"(" else 0)
                at_line_start = block[-1:] == b"\n"
                pos += len(block)
            counts[p] = n
    return [counts[p] for p in points]


def plan(path: Path, kind: str, base: dict[str, Any], workers: int = 2) -> list[Part]:
    size = path.stat().st_size
    step = max(PART_BYTES[kind], min(PART_MAX, -(-size // (workers * PARTS_PER_WORKER))))
    cuts = list(range(0, size, step))[1:]
    if kind == "candump":
        cuts = _line_starts(path, cuts)
    bounds = [0, *sorted(set(c for c in cuts if 0 < c < size)), size]
    warm = [max(0, lo - WARMUP[kind]) for lo in bounds[:-1]]
    cool = [min(size, hi + WARMUP[kind]) for hi in bounds[1:]]
    n = len(warm)
    if kind == "candump":
        warm = _line_starts(path, warm)
        cool = _line_starts(path, cool)
        counts = _frame_lines_before(path, warm + bounds)
        indices, at_bounds = counts[:n], counts[n:]
    else:
        indices, at_bounds = [0] * n, [0] * (n + 1)
    return [
        Part(
            str(path),
            kind,
            bounds[i],
            bounds[i + 1],
            warm[i],
            cool[i],
            size,
            indices[i],
            at_bounds[i],
            at_bounds[i + 1],
            **base,
        )
        for i in range(n)
    ]


def _items(part: Part) -> Iterator[Item]:
    """A raw dump's part (with its warm-up and overrun) as chunks."""
    bus = part.bus or "serial"
    with open(part.path, "rb") as f:
        f.seek(part.warm_lo)
        left = part.cool_hi - part.warm_lo
        while left > 0 and (data := f.read(min(READ, left))):
            left -= len(data)
            yield Item(bus, Chunk(data))


def _can_frames(part: Part) -> Iterator[tuple[str, CanFrame]]:
    """A candump log's part (with its warm-up and overrun) as (bus, frame)."""
    reader = CandumpReader(part.path, (part.warm_lo, part.cool_hi))
    fixed = part.bus
    names: dict[str | None, str] = {}
    for frame in reader:
        name = fixed or names.get(frame.channel)
        if name is None:
            name = names[frame.channel] = can_bus_name(frame.channel)
        yield name, frame
    if reader.errors:
        # a malformed line shifts the frame numbering this split relies on
        raise JoinError("; ".join(reader.errors[:3]))


def _writer(fmt: str, out: IO[bytes]) -> Callable[[list[Record]], None]:
    if fmt == "jsonl":
        from .sinks.jsonl import JsonlSink

        return JsonlSink(out).write
    import io

    from .sinks.csv import CsvSink

    text = io.TextIOWrapper(out, encoding="utf-8", newline="")
    sink = CsvSink(text, header=False)

    def write(records: list[Record]) -> None:
        sink.write(records)
        text.flush()

    return write


def decode_part(part: Part) -> PartResult:
    """Worker: decode a part with warm-up, write its records to a temp file."""
    gc.disable()  # records hold no cycles (see commands.common.batch_gc)
    decoding = Decoding(
        part.protocol, positional_seq=True, start_offset=part.warm_lo, can_index=part.can_index
    )
    at_end = part.cool_hi >= part.size
    is_bytes = part.kind == "bytes"
    lo, hi = part.lo, part.hi
    first: int | None = None
    end: int | None = None
    count = 0
    fd, out_path = tempfile.mkstemp(dir=part.tmpdir, suffix=f".{part.fmt}")
    device, errors_only = part.device, part.errors_only
    with os.fdopen(fd, "wb") as out:
        write = _writer(part.fmt, out)

        def take(records: list[Record]) -> None:
            nonlocal first, end, count
            if not records:
                return
            if is_bytes:
                mine = [r for r in records if r.offset is not None and lo <= r.offset < hi]
                if mine:
                    if first is None:
                        first = mine[0].offset
                    last = mine[-1]
                    end = (last.offset or 0) + last.length
            else:
                ilo, ihi = part.index_lo, part.index_hi
                mine = [r for r in records if r.index is not None and ilo <= r.index < ihi]
                if mine:
                    if first is None:
                        first = mine[0].index
                    end = (mine[-1].index or 0) + 1
            count += len(mine)
            if device is not None or errors_only:
                mine = [
                    r
                    for r in mine
                    if (device is None or r.device == device)
                    and (not errors_only or r.errors or r.warnings)
                ]
            write(mine)

        batch: list[Record] = []
        if is_bytes:
            for item in _items(part):
                batch += decoding.feed(item)
                if len(batch) >= 4096:
                    take(batch)
                    batch = []
        else:
            feed_can = decoding.feed_can
            for bus, frame in _can_frames(part):
                batch += feed_can(bus, frame)
                if len(batch) >= 4096:
                    take(batch)
                    batch = []
        batch += decoding.finish() if at_end else _flush_without_end(decoding)
        take(batch)
    return PartResult(out_path, first, end, count, [])


def _flush_without_end(decoding: Decoding) -> list[Record]:
    """The part's overrun is decoded; release what the pairing stage still holds without
    deciding the bytes after it (they belong to the next part)."""
    return decoding.pairer.flush()


def run_parallel(
    path: Path,
    kind: str,
    args: argparse.Namespace,
    protocol: str | None,
    out: IO[bytes],
    progress: Callable[[int, int], None],
    jobs: int = 0,
) -> int:
    """Decode in parts on every core, then write the joined output to ``out``. Returns the
    number of records. Raises JoinError, having written nothing, when parts do not meet."""
    with tempfile.TemporaryDirectory(prefix="eg2scope-") as tmpdir:
        base = {
            "protocol": protocol,
            "bus": args.bus,
            "fmt": args.format,
            "device": args.device,
            "errors_only": args.errors_only,
            "tmpdir": tmpdir,
        }
        workers = max(1, jobs or os.cpu_count() or 2)
        parts = plan(path, kind, base, workers)
        ctx = multiprocessing.get_context("fork")
        results: list[PartResult] = []
        workers = min(workers, len(parts))
        with ctx.Pool(workers) as pool:
            for part, res in zip(parts, pool.imap(decode_part, parts), strict=True):
                if results:
                    prev = results[-1]
                    if prev.end is not None and res.first is not None and prev.end != res.first:
                        raise JoinError(
                            f"parts do not meet at {part.lo}: {prev.end} != {res.first}"
                        )
                results.append(res)
                progress(part.hi, part.size)
        total = 0
        for res in results:
            with open(res.out_path, "rb") as f:
                shutil.copyfileobj(f, out, 1 << 20)
            total += res.records
        return total


def reader_kind(reader: Any) -> str:
    """ "bytes", "candump" or "" (not splittable) for a capture reader."""
    if isinstance(reader, RawBytesReader):
        return "bytes"
    inner = getattr(reader, "_reader", None)
    if isinstance(inner, CandumpReader):
        return "candump"
    return ""
