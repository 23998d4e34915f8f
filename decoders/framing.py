"""Splitting a byte stream into frames, shared by the serial and Modbus RTU decoders.

A protocol supplies two things: ``frame_at(buf, pos, final)`` says whether a frame starts at
``pos`` (and how long it is, and whether its checksum holds), and ``make_record`` turns the bytes
into a Record. This base does the rest the same way for every protocol:

- bytes are kept only until they are decided, so memory stays flat;
- a run of bytes that belongs to no frame becomes one ``garbage`` record;
- a frame-shaped candidate whose checksum fails becomes a frame with an error, unless a valid
  frame starts inside it, in which case its first bytes are garbage and decoding resumes there
  (resynchronise one byte on, never a whole frame on);
- at the end of the stream a frame that lacks bytes becomes a ``truncated`` record;
- every input byte ends up in exactly one record.

Arrival times are kept per chunk: a record's ``t`` is the arrival time of the chunk holding its
first byte. Gaps between chunks are exposed to ``frame_at`` as a hint only (``gap_at``).
"""

from __future__ import annotations

from collections import deque
from typing import Final

from .model import GARBAGE, TRUNCATED, Chunk, Record

NEED_MORE: Final = -0x7FFFFFFF  # frame_at: cannot decide before more bytes arrive
MAX_GARBAGE: Final = 4096  # a garbage run is cut into records of at most this many bytes


class ByteStreamDecoder:
    """Base of the byte-stream decoders: feed Chunks, get Records in stream order."""

    protocol: str = ""
    max_frame: int = 256  # longest possible frame, bounds the look-ahead
    gap_s: float = 0.00175  # silence that hints at a frame boundary

    def __init__(self, bus: str = "serial") -> None:
        self.bus = bus
        self._buf = bytearray()
        self._base = 0  # stream offset of _buf[0]
        # (stream offset of a chunk's first byte, its arrival time, gap before it?)
        self._times: deque[tuple[int, float | None, bool]] = deque()
        self._last_t: float | None = None
        self._garbage_at: int | None = None  # buffer index where the open garbage run starts
        self._garbage_why: str = "no frame header"
        self.direction_hint: str | None = None  # direction of the newest chunk, if known

    # -- to be supplied by a protocol -------------------------------------------------------

    def frame_at(self, buf: bytearray, pos: int, final: bool) -> int:
        """Length of a valid frame at pos (> 0); -length of a frame-shaped candidate whose
        checksum fails; 0 if no frame starts here; NEED_MORE if more bytes are needed."""
        raise NotImplementedError

    def next_start(self, buf: bytearray, pos: int) -> int:
        """The first index >= pos where a frame could start (len(buf) if none). Lets a
        protocol with a header skip garbage fast; the default tries every byte."""
        return pos

    def make_record(self, raw: bytes, offset: int, t: float | None, valid: bool) -> Record:
        raise NotImplementedError

    def truncated_reason(self, raw: bytes) -> str:
        return f"truncated frame: stream ended after {len(raw)} bytes"

    # -- the shared machinery ---------------------------------------------------------------

    def start_at(self, offset: int) -> None:
        """Number this stream's bytes from ``offset`` (when decoding part of a capture)."""
        if self._buf or self._base:
            raise RuntimeError("start_at() must come before the first feed()")
        self._base = offset

    def feed(self, chunk: Chunk) -> list[Record]:
        if chunk.direction is not None:
            self.direction_hint = chunk.direction
        if chunk.data:
            gap = (
                chunk.t is not None
                and self._last_t is not None
                and chunk.t - self._last_t > self.gap_s
            )
            self._times.append((self._base + len(self._buf), chunk.t, gap))
            self._buf += chunk.data
        if chunk.t is not None:
            self._last_t = chunk.t
        return self._scan(final=False)

    def finish(self) -> list[Record]:
        """End of stream: decide every byte still held."""
        return self._scan(final=True)

    idle_s: float = 0.1  # a live line quiet this long will not finish the frame it started

    def idle(self, now: float) -> list[Record]:
        """Live streams: when the line has been quiet for idle_s, decide the bytes held as if
        the stream had ended (a frame is sent in one go; its tail will not come later)."""
        if self._buf and self._last_t is not None and now - self._last_t > self.idle_s:
            return self._scan(final=True)
        return []

    def gap_at(self, pos: int) -> bool:
        """True if a silence longer than gap_s preceded buffer index pos (a boundary hint)."""
        offset = self._base + pos
        return any(start == offset and gap for start, _, gap in self._times)

    def _time_of(self, offset: int) -> float | None:
        times = self._times
        # drop chunk entries wholly before offset, keeping the one that contains it
        while len(times) > 1 and times[1][0] <= offset:
            times.popleft()
        return times[0][1] if times else None

    def _scan(self, final: bool) -> list[Record]:
        out: list[Record] = []
        buf = self._buf
        n = len(buf)
        pos = 0
        frame_at = self.frame_at
        make_record = self.make_record
        times = self._times
        skips = type(self).next_start is not ByteStreamDecoder.next_start
        while pos < n:
            if skips:
                start = self.next_start(buf, pos)
                if start > pos:
                    self._garbage(out, pos, start)
                    pos = start
                    if pos >= n:
                        break
            r = frame_at(buf, pos, final)
            if r > 0:  # the common case, inlined: a valid frame
                if self._garbage_at is not None:
                    self._flush_garbage(out, pos)
                offset = self._base + pos
                t = times[0][1] if len(times) == 1 else self._time_of(offset)
                out.append(make_record(bytes(buf[pos : pos + r]), offset, t, True))
                pos += r
                continue
            if r == NEED_MORE:
                if not final:
                    break
                # the stream ended inside a candidate: a real frame may still start later
                q = self._valid_start(buf, pos + 1, n, final)
                if q is not None:
                    self._garbage(out, pos, q, "incomplete frame followed by a valid one")
                    pos = q
                    continue
                self._flush_garbage(out, pos)
                raw = bytes(buf[pos:])
                out.append(self._truncated(raw, pos))
                pos = n
                break
            if r == 0:
                self._garbage(out, pos, pos + 1)
                pos += 1
                continue
            if r > 0:
                self._flush_garbage(out, pos)
                out.append(self._frame(buf, pos, r, True))
                pos += r
                continue
            length = -r
            # a candidate with a bad checksum: is there a valid frame inside it?
            q = self._valid_start(buf, pos + 1, pos + length, final)
            if q is None and not final and self._undecided:
                break
            if q is not None:
                self._garbage(out, pos, q, "bytes of a frame-shaped candidate with a bad checksum")
                pos = q
                continue
            self._flush_garbage(out, pos)
            out.append(self._frame(buf, pos, length, False))
            pos += length
        if final or (self._garbage_at is not None and pos - self._garbage_at >= MAX_GARBAGE):
            self._flush_garbage(out, pos)
        # keep only undecided bytes (and an open garbage run's start)
        keep_from = pos if self._garbage_at is None else self._garbage_at
        if keep_from:
            del buf[:keep_from]
            self._base += keep_from
            if self._garbage_at is not None:
                self._garbage_at -= keep_from
        return out

    _undecided: bool = False

    def _valid_start(self, buf: bytearray, lo: int, hi: int, final: bool) -> int | None:
        """First index in [lo, hi) where a valid frame starts. Sets _undecided when a candidate
        there needs bytes not yet received (the caller then waits, unless final)."""
        self._undecided = False
        q = lo
        while q < hi:
            q = self.next_start(buf, q)
            if q >= hi:
                break
            r = self.frame_at(buf, q, final)
            if r > 0:
                return q
            if r == NEED_MORE and not final:
                self._undecided = True
                return None
            q += 1
        return None

    def _garbage(self, out: list[Record], lo: int, hi: int, why: str | None = None) -> None:
        if self._garbage_at is None:
            self._garbage_at = lo
            self._garbage_why = why or "no frame starts here"
        elif why:
            self._garbage_why = why
        if hi - self._garbage_at >= MAX_GARBAGE:
            self._flush_garbage(out, hi)

    def _flush_garbage(self, out: list[Record], end: int) -> None:
        lo = self._garbage_at
        if lo is None or end <= lo:
            self._garbage_at = None
            return
        raw = bytes(self._buf[lo:end])
        offset = self._base + lo
        out.append(
            Record(
                t=self._time_of(offset),
                bus=self.bus,
                protocol=self.protocol,
                kind=GARBAGE,
                length=len(raw),
                raw=raw,
                offset=offset,
                errors=[f"garbage: {len(raw)} bytes belong to no frame ({self._garbage_why})"],
                summary=f"{len(raw)} garbage bytes",
            )
        )
        self._garbage_at = None

    def _frame(self, buf: bytearray, pos: int, length: int, valid: bool) -> Record:
        offset = self._base + pos
        return self.make_record(
            bytes(buf[pos : pos + length]), offset, self._time_of(offset), valid
        )

    def _truncated(self, raw: bytes, pos: int) -> Record:
        offset = self._base + pos
        return Record(
            t=self._time_of(offset),
            bus=self.bus,
            protocol=self.protocol,
            kind=TRUNCATED,
            length=len(raw),
            raw=raw,
            offset=offset,
            errors=[self.truncated_reason(raw)],
            summary=f"truncated frame ({len(raw)} bytes)",
        )
