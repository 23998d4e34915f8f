"""Decoding a large capture file on every core: parts decoded in parallel, streamed in order.

The decode path is sequential by nature (framing state, pending requests, timing rules), but
that state only reaches back a bounded way. Each worker runs the session's decoding stage and
its output listener (Decoding, the JSONL or CSV listener) over one part of the file, starting
``WARMUP`` bytes early and running ``WARMUP`` bytes past its end, so that framing, the CAN
direction table, pairing and the timing linter are in the same state as in a one-piece decode;
it keeps only the records that start inside its part. Records are numbered by their place in
the input (``seq`` = offset, or CAN frame index), the same in every worker.

The joins are checked on the state that matters, and any doubt means one piece:
- a part's own records must all be decided inside its overrun: a request of the part still waiting
  for its answer, or bytes of the part still undecided, when the overrun ends -> one piece;
- the records a part decoded in its overrun must equal, one for one, the first records the next
  part decoded after its warm-up (so the next part's warm-up reached the same state);
- consecutive parts must meet exactly (no record lost or doubled at the boundary).
Only raw byte dumps and uncompressed candump -L logs are split; everything else is one piece.

No waste: a part's output is kept in memory only until its turn (at most ``WINDOW`` parts
ahead of the one being written), never copied through temporary files. The parent process
decodes parts too whenever the next part to write is not ready, so a worker slowed by a busy
core delays nothing but its own part; when no core is idle at the start, the file is decoded
in one piece. A join that fails after parts were written resumes in one piece where the
written output ends (``JoinError.resume``).
"""

from __future__ import annotations

import gc
import io
import multiprocessing
import os
import signal
import sys
import threading
import time
import zlib
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import orjson

from decoders.model import EG2_SERIAL, CanFrame, Chunk, Record
from decoders.registry import detect_protocol

from ..errors import EXIT_OK
from ..model import Item
from ..sources.can_files import CandumpReader, is_gzip
from ..sources.capture import RawBytesReader, can_bus_name
from .batches import RecordSequence
from .listener import Listener
from .stage import Decoding

if TYPE_CHECKING:
    from ..sources.capture import CaptureReader
    from .capture import CaptureOptions

# Part sizes and warm-ups per kind of input. A candump log carries time: its warm-up covers
# the longest a request may wait for its answer (a save, 2 s) on a busy bus. A raw dump has
# no timing, so pairing state lasts only until the next request: a short warm-up will do.
PART_BYTES = {"candump": 6 << 20, "bytes": 1 << 20}  # the smallest part
PARTS_PER_WORKER = 2  # few parts: each costs a warm-up; two per worker keep both busy
# the largest part: its output waits in memory for its turn (JSONL is ~45x a raw serial dump,
# ~10x a candump log)
PART_MAX = {"candump": 8 << 20, "bytes": 1 << 20}
WINDOW = 3  # parts decoded ahead of the one being written (bounds memory)
IDLE_NEEDED = 0.6  # of a core, idle at the start, for a split to pay
WARMUP = {"candump": 1 << 20, "bytes": 64 << 10}
MIN_PARALLEL_BYTES = {"candump": 8 << 20, "bytes": 2 << 20}  # smaller: one piece
READ = 1 << 16
BATCH = 4096


class JoinError(Exception):
    """Two parts did not meet exactly: decode in one piece instead, keeping only the records
    from ``resume`` on (a byte offset or CAN frame index; 0: nothing was written yet)."""

    def __init__(self, text: str, resume: int = 0, damage: bool = False) -> None:
        super().__init__(text)
        self.resume = resume
        # damage in a part: the one-piece decode says where it is (in the file's own line
        # numbers, not the part's), so the change of method is not worth a line of its own
        self.damage = damage

    def __reduce__(self) -> tuple[type[JoinError], tuple[str, int, bool]]:
        return (JoinError, (str(self), self.resume, self.damage))  # a worker's, to the parent


@dataclass(frozen=True)
class PartJob:
    """What every worker is told: the file, how to decode and what to keep."""

    path: str
    kind: str  # "bytes" or "candump"
    size: int
    protocol: str | None
    bus: str | None
    fmt: str
    device: int | None
    errors_only: bool


@dataclass(frozen=True)
class Part:
    job: PartJob
    lo: int  # the part: records starting in [lo, hi) (bytes) ...
    hi: int
    warm_lo: int  # decoded: [warm_lo, cool_hi)
    cool_hi: int
    can_index: int  # frame index of the first line at warm_lo (candump)
    index_lo: int  # ... or with frame indices in [index_lo, index_hi) (candump)
    index_hi: int


@dataclass
class PartResult:
    output: bytes
    first: int | None  # first record's position (offset, or CAN index), before filtering
    end: int | None  # position after the last record (offset + length, or index + 1)
    records: int
    # (position, crc32 of the record's JSON) for the records past the part's end that the
    # overrun decided, and for the part's first records after its warm-up: the join check
    overrun: list[tuple[int, int]] = field(default_factory=list)
    head: list[tuple[int, int]] = field(default_factory=list)


def splittable(path: Path, fmt: str, kind: str) -> bool:
    """Worth and possible to split: large raw dumps and candump logs, JSONL or CSV out."""
    if fmt not in ("jsonl", "csv") or (os.cpu_count() or 1) < 2:
        return False
    if kind not in MIN_PARALLEL_BYTES or path.stat().st_size < MIN_PARALLEL_BYTES[kind]:
        return False
    return kind != "candump" or not is_gzip(path)


def reader_kind(reader: Any) -> str:
    """ "bytes", "candump" or "" (not splittable) for a capture reader."""
    if isinstance(reader, RawBytesReader):
        return "bytes"
    inner = getattr(reader, "_reader", None)
    if isinstance(inner, CandumpReader) and inner.splittable:  # -L lines: Unix time each
        return "candump"
    return ""


# -- planning --------------------------------------------------------------------------------


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


def plan(job: PartJob, workers: int = 2) -> list[Part]:
    path, kind, size = Path(job.path), job.kind, job.size
    step = max(PART_BYTES[kind], min(PART_MAX[kind], -(-size // (workers * PARTS_PER_WORKER))))
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
        Part(job, bounds[i], bounds[i + 1], warm[i], cool[i], indices[i], at_bounds[i],
             at_bounds[i + 1])
        for i in range(n)
    ]  # fmt: skip


# -- one worker --------------------------------------------------------------------------------


def _byte_items(part: Part) -> Iterator[Item]:
    """A raw dump's part (with its warm-up and overrun) as chunks that end exactly at the part's
    end, so the decoding's state there can be checked."""
    bus = part.job.bus or "serial"
    with open(part.job.path, "rb") as f:
        f.seek(part.warm_lo)
        pos = part.warm_lo
        while pos < part.cool_hi:
            stop = part.hi if pos < part.hi else part.cool_hi
            data = f.read(min(READ, stop - pos))
            if not data:
                return
            pos += len(data)
            yield Item(bus, Chunk(data))


def _can_frames(part: Part) -> Iterator[tuple[str, CanFrame]]:
    """A candump log's part (with its warm-up and overrun) as (bus, frame)."""
    reader = CandumpReader(part.job.path, (part.warm_lo, part.cool_hi))
    fixed = part.job.bus
    names: dict[str | None, str] = {}
    for frame in reader:
        name = fixed or names.get(frame.channel)
        if name is None:
            name = names[frame.channel] = can_bus_name(frame.channel)
        yield name, frame
    if reader.errors:
        # a malformed line shifts the frame numbering this split relies on
        raise JoinError("; ".join(reader.errors[:3]), damage=True)


def _output(fmt: str, out: IO[bytes]) -> Listener:
    if fmt == "jsonl":
        from ..sinks.jsonl import JsonlListener

        return JsonlListener(out)
    from ..sinks.csv import CsvListener

    return CsvListener(io.TextIOWrapper(out, encoding="utf-8", newline=""), header=False)


def _position(rec: Record) -> int:
    return rec.offset if rec.offset is not None else (rec.index or 0)


def _digest(rec: Record) -> tuple[int, int]:
    return _position(rec), zlib.crc32(orjson.dumps(rec.to_dict()))


class _PartDecoder:
    """The session's stages over one part: Decoding -> the output listener (the gripper states
    a Tracker would fold are no part of decode's output)."""

    def __init__(self, part: Part, out: IO[bytes]) -> None:
        self.part = part
        job = part.job
        self.decoding = Decoding(
            job.protocol, positional_seq=True, start_offset=part.warm_lo, can_index=part.can_index
        )
        self.output = _output(job.fmt, out)
        if job.kind == "bytes":
            self.lo, self.hi = part.lo, part.hi
        else:
            self.lo, self.hi = part.index_lo, part.index_hi
        self.result = PartResult(b"", None, None, 0)

    def take(self, records: list[Record], final: bool = False) -> None:
        if not records:
            return
        lo, hi, res = self.lo, self.hi, self.result
        mine = [r for r in records if lo <= _position(r) < hi]
        if not final:
            res.overrun += [_digest(r) for r in records if _position(r) >= hi]
        if mine:
            if res.first is None:
                res.first = _position(mine[0])
                if lo > 0:
                    res.head = [_digest(r) for r in mine[:BATCH]]
            last = mine[-1]
            res.end = (
                (last.offset + last.length) if last.offset is not None else _position(last) + 1
            )
            res.records += len(mine)
            job = self.part.job
            if job.device is not None or job.errors_only:
                mine = [
                    r
                    for r in mine
                    if (job.device is None or r.device == job.device)
                    and (not job.errors_only or r.errors or r.warnings)
                ]
            self.output.on_records(RecordSequence(mine))

    def check_end(self) -> None:
        """At the end of the overrun nothing of the part may still be undecided."""
        undecided = self.decoding.undecided_before(self.hi)
        if undecided:
            raise JoinError(f"part ending at {self.part.hi}: {undecided} at the end of its overrun")


def decode_part(part: Part) -> PartResult:
    """Decode a part with warm-up and overrun; its output comes back with the result."""
    out = io.BytesIO()
    at_end = part.cool_hi >= part.job.size
    worker = _PartDecoder(part, out)
    decoding = worker.decoding
    batch: list[Record] = []
    if part.job.kind == "bytes":
        for item in _byte_items(part):
            batch += decoding.feed(item)
            if len(batch) >= BATCH:
                worker.take(batch)
                batch = []
    else:
        feed_can = decoding.feed_can
        for bus, frame in _can_frames(part):
            batch += feed_can(bus, frame)
            if len(batch) >= BATCH:
                worker.take(batch)
                batch = []
    worker.take(batch)
    if at_end:
        worker.take(decoding.finish(), final=True)
    else:
        worker.check_end()
        worker.take(decoding.pairer.flush(), final=True)
    worker.output.close()
    worker.result.output = out.getvalue()
    return worker.result


# Ctrl-C and a terminal's SIGHUP go to the whole process group: the parent alone reports them,
# once; SIGTERM is how Pool.terminate ends a worker
_IGNORED_BY_WORKERS = (signal.SIGINT, signal.SIGHUP)
_HELD_WHILE_FORKING = {signal.SIGINT, signal.SIGTERM, signal.SIGHUP}


def _worker_init() -> None:
    # forked with these signals held (``_start_pool``): the parent's handlers (an interrupt)
    # are not the workers', so they are set before any signal gets through
    for sig in _IGNORED_BY_WORKERS:
        signal.signal(sig, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _HELD_WHILE_FORKING)
    gc.disable()  # records hold no cycles (see session.rare_gc)


def _start_pool(workers: int) -> tuple[Any, set[int | signal.Signals]]:
    """A pool of ``workers`` forked processes, and the signal mask to restore once the caller
    can stop the pool. Ctrl-C, SIGTERM and SIGHUP are held meanwhile: a worker forked before
    its ``_worker_init`` would run the parent's handler (a KeyboardInterrupt traceback when
    ``Pool.terminate`` reaches it), and a parent interrupted inside the forking lost the
    interrupt in a fork hook ("Exception ignored") and exited 0."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, _HELD_WHILE_FORKING)
    try:
        pool = multiprocessing.get_context("fork").Pool(workers, initializer=_worker_init)
    except BaseException:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)
        raise
    return pool, held


# -- the parent --------------------------------------------------------------------------------


def _resume_at(part: Part) -> int:
    return part.lo if part.job.kind == "bytes" else part.index_lo


def _check_join(prev: PartResult, res: PartResult, part: Part) -> None:
    if prev.end is not None and res.first is not None and prev.end != res.first:
        raise JoinError(
            f"parts do not meet at {part.lo}: {prev.end} != {res.first}", _resume_at(part)
        )
    n = min(len(prev.overrun), len(res.head))
    if prev.overrun[:n] != res.head[:n]:
        raise JoinError(
            f"the part from {part.lo} decoded its first records differently", _resume_at(part)
        )


class _Ready:
    """A part the parent decoded itself (the same face as a pool's AsyncResult)."""

    def __init__(self, part: Part) -> None:
        self.result: PartResult | None = None
        self.error: JoinError | None = None
        try:
            self.result = decode_part(part)
        except JoinError as exc:
            self.error = exc  # raised in its turn, as a worker's would be

    def ready(self) -> bool:
        return True

    def get(self) -> PartResult:
        if self.error is not None:
            raise self.error
        assert self.result is not None
        return self.result


def spare_cores(sample_s: float = 0.1) -> float:
    """Cores idle right now (Linux /proc/stat over ``sample_s``; elsewhere: all but this one)."""
    cores = os.cpu_count() or 1

    def idle_total() -> tuple[int, int]:
        with open("/proc/stat") as f:
            ticks = [int(x) for x in f.readline().split()[1:]]
        return ticks[3] + ticks[4], sum(ticks)  # idle + iowait, all

    try:
        idle0, all0 = idle_total()
        time.sleep(sample_s)
        idle1, all1 = idle_total()
    except (OSError, ValueError, IndexError):
        return cores - 1.0
    if all1 <= all0:
        return cores - 1.0
    return cores * (idle1 - idle0) / (all1 - all0)


def run_parallel(
    job: PartJob, out: IO[bytes], progress: Callable[[int], None], jobs: int = 0,
    header: bytes = b"",
) -> int:  # fmt: skip
    """Decode in parts on every core, writing ``header`` and each part's output to ``out`` in
    order as soon as it is its turn. Returns the number of records. Raises JoinError when two
    parts do not meet (``resume``: where the written output ends)."""
    cores = max(2, jobs or os.cpu_count() or 2)
    parts = plan(job, cores)
    todo = iter(parts)
    waiting: deque[tuple[Part, Any]] = deque()  # in file order: handed out, not yet written
    total = 0
    prev: PartResult | None = None
    pool, held = _start_pool(min(cores - 1, len(parts)))
    with pool:
        try:
            signal.pthread_sigmask(signal.SIG_SETMASK, held)  # a signal held arrives here
            for part in todo:  # the workers start on the first parts ...
                waiting.append((part, pool.apply_async(decode_part, (part,))))
                if len(waiting) >= cores - 1:
                    break
            while waiting:
                part, pending = waiting[0]
                if not pending.ready() and len(waiting) < WINDOW:
                    mine = next(todo, None)  # ... and the parent takes the next one meanwhile
                    if mine is not None:
                        waiting.append((mine, _Ready(mine)))
                        continue
                waiting.popleft()
                try:
                    res = pending.get()
                except JoinError as exc:  # the part could not be decided on its own
                    resume = 0 if prev is None else _resume_at(part)
                    raise JoinError(str(exc), resume, exc.damage) from None
                if prev is None:
                    out.write(header)
                else:
                    _check_join(prev, res, part)
                out.write(res.output)
                total += res.records
                prev = res
                progress(part.hi)
                if len(waiting) < WINDOW and (nxt := next(todo, None)) is not None:
                    waiting.append((nxt, pool.apply_async(decode_part, (nxt,))))
        except BaseException:
            _stop(pool)
            raise
    return total


def _stop(pool: Any) -> None:
    """Stop the workers now. ``Pool.terminate`` can wait forever for a result that a killed
    worker was halfway through sending (a part's output comes back through the pool's pipe),
    so it runs aside, and the workers are killed outright if it has not returned in a moment."""
    stopper = threading.Thread(target=pool.terminate, daemon=True)
    stopper.start()
    stopper.join(2.0)
    if stopper.is_alive():
        for child in multiprocessing.active_children():
            child.kill()


def decode_in_parallel(
    opts: CaptureOptions, fmt: str, jobs: int, reader: CaptureReader, out: IO[Any]
) -> int | None:
    """Large raw dumps and candump logs, to JSONL or CSV: decode on every core and return the
    exit code. None when the file is not split (the caller decodes it in one piece); a
    JoinError when the split failed after some output was written (the caller goes on in one
    piece from its ``resume``)."""
    from .capture import byte_protocol

    path = Path(opts.path)
    kind = reader_kind(reader)
    if opts.speed is not None or jobs == 1 or not kind or not splittable(path, fmt, kind):
        return None
    if not jobs and spare_cores() < IDLE_NEEDED:
        return None  # the other cores are busy: one piece is faster
    protocol = byte_protocol(opts)
    if kind == "bytes" and protocol is None:
        with path.open("rb") as f:
            protocol = detect_protocol(f.read(4096)) or EG2_SERIAL
    binary: IO[bytes] = out if fmt == "jsonl" else out.buffer  # type: ignore[attr-defined]
    header = b""
    if fmt == "csv":
        from ..sinks.csv import CsvListener

        text = io.StringIO()
        CsvListener(text)  # writes the header
        header = text.getvalue().encode()
    out.flush()
    job = PartJob(
        str(path), kind, path.stat().st_size, protocol, opts.bus, fmt, opts.device,
        opts.errors_only,
    )  # fmt: skip
    try:
        with _PartProgress(reader, opts.progress) as progress:
            run_parallel(job, binary, progress, jobs, header)
    except JoinError as exc:
        binary.flush()
        rest = "the rest of " if exc.resume else ""
        if not exc.damage:
            print(f"eg2scope: decoding {rest}{path.name} in one piece ({exc})", file=sys.stderr)
        if not exc.resume:
            return None
        raise
    binary.flush()
    return EXIT_OK


def resumed(listener: Listener, resume: int) -> Listener:
    """``listener`` given only the records from ``resume`` on (a one-piece decode going on
    where a split decode's written output ends)."""
    from .capture import FilteredListener

    def keep(records: RecordSequence) -> list[int]:
        offsets, indexes = records.column("offset"), records.column("index")
        return [
            i
            for i, (offset, index) in enumerate(zip(offsets, indexes, strict=True))
            if (offset if offset is not None else (index or 0)) >= resume
        ]

    return FilteredListener(listener, keep)


class _PartProgress:
    """The capture's progress bar, moved by finished parts (terminals only)."""

    def __init__(self, reader: CaptureReader, enabled: bool) -> None:
        self.bar: Any = None
        self.reader = reader
        if enabled and sys.stderr.isatty():
            from .capture import ProgressListener

            self.bar = ProgressListener(reader)

    def __enter__(self) -> Any:
        def progress(done: int) -> None:
            if self.bar is not None:
                self.reader.position = done
                self.bar.tick(0.0)

        return progress

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.close()
