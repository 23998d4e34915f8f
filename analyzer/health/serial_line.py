"""A serial line's health: its use at the baud rate (10 bits a byte, 8N1), the gaps between its
frames, Modbus frames closer than the standard's silence (3.5 characters; 1.75 ms above 19200
baud), each gripper's turnaround (its request's end to its response's start), the frames with
errors, and the mark of a USB adapter's latency timer in the read times.

Line use comes from the reads (every byte, whatever it is), per whole second of the reads'
times; frame times from ``line_clock``. A raw dump has no times at all: then only the counts.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Any, Final

from decoders.flags import BAD_CHECKSUM, GARBAGE, TRUNCATED
from decoders.framing import LINE_BITS_PER_BYTE
from decoders.modbus_framing import frame_silence_s
from decoders.model import FRAME, MODBUS_RTU, REQUEST, RESPONSE, Chunk, Record

from .figures import Spread, load_pct, per_second
from .latency_timer import ReadTimes
from .line_clock import FrameTimes, LineClock
from .seconds import CLOSE_FRAMES, SecondLog

ERROR_FLAGS: Final = (BAD_CHECKSUM, GARBAGE, TRUNCATED)
MAX_WAITING: Final = 4096  # requests waiting for their response (pairing links at most a few)


class SerialLine:
    """One serial bus, fed its reads (``add_read``) and then the records found in them."""

    def __init__(self, baud: int, port: str | None = None, log: SecondLog | None = None) -> None:
        self.baud = baud
        self.log = log  # second by second, when asked for
        self.port = port
        self.byte_time_s = LINE_BITS_PER_BYTE / baud
        self.silence_ms = frame_silence_s(baud) * 1000.0  # Modbus RTU's t3.5
        self.bytes = 0
        self.seconds: Counter[int] = Counter()  # bits per whole second
        self.first_t: float | None = None  # when the first read's first byte began
        self.last_t: float | None = None
        self.reads = ReadTimes()
        self.clocks: dict[str, LineClock] = {}
        self.protocol: str | None = None
        self.frames = 0
        self.errors = 0
        self.error_counts: Counter[str] = Counter()
        self.gaps = Spread()
        self.close_frames = 0  # Modbus frames closer than the standard's silence
        self.turnaround: dict[int, Spread] = {}
        self._waiting: dict[int, FrameTimes] = {}  # request seq -> its times
        self._last: tuple[FrameTimes, bool] | None = None  # the last record's times, a frame?

    # -- reads -------------------------------------------------------------------------------

    def add_read(self, stream: str, chunk: Chunk) -> None:
        clock = self.clocks.get(stream)
        if clock is None:
            clock = self.clocks[stream] = LineClock(self.byte_time_s)
        clock.add(chunk)
        n, t = len(chunk.data), chunk.t
        self.bytes += n
        if t is None or not n:
            return
        second = math.floor(t)
        self.seconds[second] += n * LINE_BITS_PER_BYTE
        if self.log is not None:
            self.log.read(second, n * LINE_BITS_PER_BYTE)
        begun = t - n * self.byte_time_s
        if self.first_t is None or begun < self.first_t:
            self.first_t = begun
        if self.last_t is None or t > self.last_t:
            self.last_t = t
        self.reads.add(t)

    # -- records -----------------------------------------------------------------------------

    def add_record(self, rec: Record) -> None:
        flags = [f for f in rec.flags if f in ERROR_FLAGS] if rec.errors else None
        if flags is not None:
            self.errors += 1
            self.error_counts.update(flags)
        times = self._times(rec)
        if rec.kind == FRAME:
            self.frames += 1
            self.protocol = self.protocol or rec.protocol
            if times is not None:
                self._frame(rec, times)
        if self.log is not None and rec.t is not None and math.isfinite(rec.t):
            self._log(math.floor(rec.t), rec.kind == FRAME, flags)
        self._last = None if times is None else (times, rec.kind == FRAME)

    @property
    def untimed(self) -> bool:
        """No read so far had a time (a raw dump): its records have no times either."""
        return self.first_t is None

    def add_untimed(self, records: Any) -> None:
        """``add_record`` of every record of a sequence (a ``RecordSequence`` or a native
        ``RecordBatch``) while the line is ``untimed``, in bulk: with no times there are no
        gaps, turnarounds or seconds, only the counts."""
        frames = records.count_of("kind", FRAME)
        if frames:
            self.frames += frames
            if self.protocol is None:
                self.protocol = records[records.column("kind").index(FRAME)].protocol
        if records.error_count():
            for rec in records.take(records.problems()):
                if rec.errors:
                    self.errors += 1
                    self.error_counts.update(f for f in rec.flags if f in ERROR_FLAGS)
        self._last = None
        for clock in self.clocks.values():
            clock.reads.clear()  # reads without a time give no frame times: none to find

    def _times(self, rec: Record) -> FrameTimes | None:
        clock = self._clock(rec)
        if clock is None or rec.offset is None:
            return None
        return clock.times(rec.offset, rec.length)

    def _clock(self, rec: Record) -> LineClock | None:
        """The stream of a record: the line's only one, or the one of its direction."""
        clocks = self.clocks
        if len(clocks) == 1:
            return next(iter(clocks.values()))
        return next((c for c in clocks.values() if c.direction == rec.direction), None)

    def _frame(self, rec: Record, times: FrameTimes) -> None:
        last = self._last
        if last is not None and last[1]:
            gap = _between(last[0], times)
            self.gaps.add(gap)
            if gap is not None and rec.protocol == MODBUS_RTU and gap < self.silence_ms:
                self.close_frames += 1
                if self.log is not None and rec.t is not None and math.isfinite(rec.t):
                    self.log.event(math.floor(rec.t), CLOSE_FRAMES)
        if rec.direction == REQUEST:
            if len(self._waiting) >= MAX_WAITING:
                del self._waiting[next(iter(self._waiting))]
            self._waiting[rec.seq] = times
        elif rec.direction == RESPONSE and rec.pair is not None and rec.device is not None:
            request = self._waiting.pop(rec.pair, None)
            if request is not None:
                spread = self.turnaround.get(rec.device)
                if spread is None:
                    spread = self.turnaround[rec.device] = Spread()
                spread.add(_between(request, times))

    def _log(self, second: int, frame: bool, flags: list[str] | None) -> None:
        """A record in the second-by-second log: a frame, an error (its flags)."""
        log = self.log
        assert log is not None
        if frame:
            log.frames(second, 1, 0)
        if flags is not None:
            log.error(second, tuple(flags))

    # -- the figures -------------------------------------------------------------------------

    def figures(self) -> dict[str, Any]:
        """The line's figures (docs/contracts.md, statistics), after the rate's keys."""
        start, end = self.first_t, self.last_t
        load: dict[str, float | None] = {"mean": None, "p95": None, "max": None}
        if start is not None and end is not None:
            timed = sum(self.seconds.values())
            load = load_pct(self.seconds, start, end, timed, self.baud)
        modbus = self.protocol == MODBUS_RTU
        return {
            "protocol": self.protocol,
            "frames": self.frames,
            "bytes": self.bytes,
            "bits": self.bytes * LINE_BITS_PER_BYTE,
            "duration_s": None if start is None or end is None else round(end - start, 6),
            "frames_per_s": per_second(self.frames, start, end),
            "load_pct": load,
            "error_frames": self._error_frames(),
            "gaps_ms": self.gaps.summary(),
            "modbus_t3_5_ms": round(self.silence_ms, 3) if modbus else None,
            # without times nothing can be said to be close
            "closer_than_t3_5": self.close_frames if modbus and not self.untimed else None,
            "turnaround_ms": [
                {"device": device, **spread.summary()}
                for device, spread in sorted(self.turnaround.items())
            ],
            "latency_timer": self.reads.hint(self.port),
        }

    def _error_frames(self) -> dict[str, int]:
        """Records with errors, and those of the classes a line's noise makes."""
        return {"total": self.errors, **{f: self.error_counts[f] for f in ERROR_FLAGS}}


def _between(before: FrameTimes, after: FrameTimes) -> float | None:
    """Milliseconds from one frame's end to the next one's start (0 at least: a tap or an
    adapter that delivers faster than the line would make it negative); None when one read
    brought both ends, both counted back from its one time."""
    if after.first_read == before.last_read:
        return None
    return max(0.0, after.start - before.end) * 1000.0
