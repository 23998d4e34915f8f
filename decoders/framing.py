"""Splitting a byte stream into frames, shared by the serial and Modbus RTU decoders.

A protocol supplies two things: ``frame_at(buf, pos, final)`` says whether a frame starts at
``pos`` (and how long it is, and whether its checksum holds), and ``make_record`` turns the bytes
into a Record. This base does the rest the same way for every protocol:

- bytes are kept only until they are decided, so memory stays flat;
- a run of bytes that belongs to no frame becomes ``garbage`` records of at most
  ``MAX_GARBAGE`` bytes each;
- a frame-shaped candidate whose checksum fails becomes a frame with an error, unless a valid
  frame starts inside it: then its first bytes are garbage and decoding resumes at the first
  frame inside it (resynchronise one byte on, never a whole frame on). That frame is the valid
  one, or a candidate before it with a bad checksum of its own that ends in time: a damaged frame
  right after garbage keeps its own record;
- at the end of the stream a frame that lacks bytes becomes a ``truncated`` record (an error);
  when the capture was stopped instead (``stop``: a user's Ctrl-C, the end of a ``--duration``),
  a ``cut_off`` record, flagged ``cut_off`` with no error: the stop cut it, not the bus;
- every input byte ends up in exactly one record.

Times. Arrival times are kept per chunk. Without a byte time (a capture without a baud rate) a
record's ``t`` is the time of the chunk holding its first byte. With ``byte_time_s`` (10 bits
per byte at the line's baud) a chunk's ``t`` is when its last byte arrived, as a live tap stamps
a read, and a record's ``t`` is counted back from it at line speed: when the record's first byte
arrived. A record whose chunk held other bytes too is flagged ``estimated_time``: the count
back assumed no silence between them. Gaps between chunks are exposed to ``frame_at`` as a hint
only (``gap_at``).
"""

from __future__ import annotations

from collections import deque
from typing import Final

from . import messages as M
from .flags import ESTIMATED_TIME
from .flags import TRUNCATED as TRUNCATED_FLAG
from .model import CUT_OFF, GARBAGE, TRUNCATED, Chunk, Record

NEED_MORE: Final = -0x7FFFFFFF  # frame_at: cannot decide before more bytes arrive
MAX_GARBAGE: Final = 4096  # a garbage run is cut into records of at most this many bytes
LINE_BITS_PER_BYTE: Final = 10  # a byte on an 8N1 line: start bit, 8 data bits, stop bit

# one chunk's place and time: (stream offset of its first byte, offset after its last byte,
# its arrival time, whether a silence longer than gap_s came before it)
_ChunkSpan = tuple[int, int, float | None, bool]


class ByteStreamDecoder:
    """Base of the byte-stream decoders: feed Chunks, get Records in stream order."""

    protocol: str = ""
    gap_s: float = 0.00175  # silence that hints at a frame boundary (Modbus RTU's t3.5)
    idle_s: float = 0.1  # a live line quiet this long will not finish the frame it started

    def __init__(self, bus: str = "serial", *, byte_time_s: float | None = None) -> None:
        """``byte_time_s``: seconds per byte on the line (10 bits / baud), when known; chunk
        times are then arrival times of their last byte (see the module's docstring)."""
        if byte_time_s is not None and not byte_time_s > 0:
            raise ValueError(f"byte_time_s must be positive, not {byte_time_s!r}")
        self.bus = bus
        self.byte_time_s = byte_time_s
        # with a byte time: when the last stamped record's bytes had all arrived; a later
        # record cannot have started before (a pty or a USB adapter may deliver reads faster
        # than the line's rate, which would make estimated times go back)
        self._stamped_until = float("-inf")
        self._buf = bytearray()
        self._base = 0  # stream offset of _buf[0]
        self._times: deque[_ChunkSpan] = deque()
        self._last_t: float | None = None
        self._garbage_at: int | None = None  # buffer index where the open garbage run starts
        self._resume = 0  # buffer index of the first byte not decided yet (after an open run)
        self._garbage_why: str = M.GARBAGE_NO_HEADER
        self.direction_hint: str | None = None  # direction of the newest chunk, if known
        self._stopping = False  # deciding the held bytes because the capture was stopped

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
        return M.FRAMING_TRUNCATED.text(length=len(raw))

    # -- the shared machinery ---------------------------------------------------------------

    def start_at(self, offset: int) -> None:
        """Number this stream's bytes from ``offset`` (when decoding part of a capture)."""
        if self._buf or self._base:
            raise RuntimeError("start_at() must come before the first feed()")
        self._base = offset

    def feed(self, chunk: Chunk) -> list[Record]:
        if chunk.direction is not None:
            self.direction_hint = chunk.direction
        data = chunk.data
        t = chunk.t
        if data:
            gap = False
            if t is not None and self._last_t is not None:
                first_byte_t = t if self.byte_time_s is None else t - len(data) * self.byte_time_s
                gap = first_byte_t - self._last_t > self.gap_s
            start = self._base + len(self._buf)
            self._times.append((start, start + len(data), t, gap))
            self._buf += data
        if t is not None:
            self._last_t = t
        return self._scan(final=False)

    def finish(self) -> list[Record]:
        """End of stream: decide every byte still held."""
        return self._scan(final=True)

    def stop(self) -> list[Record]:
        """The capture was stopped (a user's stop, the end of a duration), not the stream
        ended: decide every byte held as ``finish`` does, but a frame begun becomes a
        ``cut_off`` record (no error: the stop cut it, not the bus)."""
        self._stopping = True
        try:
            return self._scan(final=True)
        finally:
            self._stopping = False

    def idle(self, now: float) -> list[Record]:
        """Live streams: when the line has been quiet for idle_s, decide the bytes held as if
        the stream had ended (a frame is sent in one go; its tail will not come later)."""
        if self._buf and self._last_t is not None and now - self._last_t > self.idle_s:
            return self._scan(final=True)
        return []

    def held_from(self) -> int | None:
        """Stream offset of the first byte still held undecided (None: nothing held)."""
        if self._garbage_at is not None:
            return self._base + self._garbage_at
        return self._base if self._buf else None

    def gap_at(self, pos: int) -> bool:
        """True if a silence longer than gap_s preceded buffer index pos (a boundary hint)."""
        offset = self._base + pos
        return any(start == offset and gap for start, _, _, gap in self._times)

    def _chunk_of(self, offset: int) -> _ChunkSpan | None:
        times = self._times
        # drop chunk entries wholly before offset, keeping the one that contains it
        while len(times) > 1 and times[1][0] <= offset:
            times.popleft()
        return times[0] if times else None

    def _time_of(self, offset: int) -> float | None:
        span = self._chunk_of(offset)
        return span[2] if span is not None else None

    def _stamp(self, rec: Record) -> Record:
        """Give a record its time, estimated from its place in its chunk when the byte time
        is known."""
        offset = rec.offset
        assert offset is not None
        span = self._chunk_of(offset)
        if span is None:
            return rec
        start, end, t, _ = span
        if t is None or self.byte_time_s is None:
            rec.t = t
            return rec
        bt = self.byte_time_s
        rec.t = max(t - (end - offset) * bt, self._stamped_until)
        self._stamped_until = rec.t + rec.length * bt
        if start < offset or end > offset + rec.length:
            rec.flags.append(ESTIMATED_TIME)
        return rec

    def _scan(self, final: bool) -> list[Record]:
        """Decide what can be decided in the bytes held; keep the rest."""
        out: list[Record] = []
        buf = self._buf
        n = len(buf)
        pos = self._resume  # the bytes of an open garbage run are decided: not again
        frame_at = self.frame_at
        make_record = self.make_record
        times = self._times
        plain_times = self.byte_time_s is None
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
            if r > 0:  # the common case: a valid frame
                if self._garbage_at is not None:
                    self._flush_garbage(out, pos)
                if plain_times:  # inlined _frame
                    offset = self._base + pos
                    t = times[0][2] if len(times) == 1 else self._time_of(offset)
                    out.append(make_record(bytes(buf[pos : pos + r]), offset, t, True))
                else:
                    out.append(self._frame(buf, pos, r, True))
                pos += r
            elif r == 0:
                self._garbage(out, pos, pos + 1)
                pos += 1
            elif r == NEED_MORE:
                if not final:
                    break
                pos = self._cut_off(out, pos)
            else:
                nxt = self._failed(out, pos, -r, final)
                if nxt is None:
                    break
                pos = nxt
        if final:
            self._flush_garbage(out, pos)
        self._keep_from(pos)
        return out

    def _cut_off(self, out: list[Record], pos: int) -> int:
        """The stream ended inside a candidate at pos: a frame may still start after it, else
        it is a truncated frame. Returns where to go on."""
        buf = self._buf
        q = self._valid_start(buf, pos + 1, len(buf), True)
        if q is None:
            self._flush_garbage(out, pos)
            out.append(self._truncated(bytes(buf[pos:]), pos))
            return len(buf)
        q = self._damaged_start(buf, pos + 1, q, True)
        self._garbage(out, pos, q, M.GARBAGE_INCOMPLETE)
        return q

    def _failed(self, out: list[Record], pos: int, length: int, final: bool) -> int | None:
        """A candidate at pos whose checksum fails: a frame with an error, or garbage up to a
        frame that starts inside it. Returns where to go on, None to wait for more bytes."""
        buf = self._buf
        q = self._valid_start(buf, pos + 1, pos + length, final)
        if q is None:
            if not final and self._undecided:
                return None
            self._flush_garbage(out, pos)
            out.append(self._frame(buf, pos, length, False))
            return pos + length
        q = self._damaged_start(buf, pos + 1, q, final)
        self._garbage(out, pos, q, M.GARBAGE_BAD_CHECKSUM)
        return q

    def _keep_from(self, pos: int) -> None:
        """Drop the decided bytes before pos (an open garbage run, shorter than MAX_GARBAGE,
        stays held) and the chunk times no record needs any more."""
        keep_from = pos if self._garbage_at is None else self._garbage_at
        self._resume = pos - keep_from
        if not keep_from:
            return
        del self._buf[:keep_from]
        self._base += keep_from
        if self._garbage_at is not None:
            self._garbage_at -= keep_from
        times = self._times
        while len(times) > 1 and times[0][1] <= self._base:
            times.popleft()

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

    def _damaged_start(self, buf: bytearray, lo: int, valid: int, final: bool) -> int:
        """Where to resume before the valid frame at ``valid``: the first candidate in
        [lo, valid) whose checksum fails and that ends by ``valid`` (it is then a damaged
        frame of its own, not part of the garbage before it), else ``valid``.

        _valid_start has just tried every index in [lo, valid) on the same bytes and none
        needed more, so this decides at once."""
        q = lo
        while q < valid:
            q = self.next_start(buf, q)
            if q >= valid:
                break
            r = self.frame_at(buf, q, final)
            if r < 0 and r != NEED_MORE and q - r <= valid:
                return q
            q += 1
        return valid

    def _garbage(self, out: list[Record], lo: int, hi: int, why: str | None = None) -> None:
        """Bytes [lo, hi) belong to no frame: extend the open garbage run (or open one) and
        emit it in pieces of MAX_GARBAGE bytes as it grows."""
        if self._garbage_at is None:
            self._garbage_at = lo
            self._garbage_why = why or M.GARBAGE_NO_FRAME
        elif why:
            self._garbage_why = why
        while hi - self._garbage_at >= MAX_GARBAGE:
            piece_end = self._garbage_at + MAX_GARBAGE
            out.append(self._garbage_record(self._garbage_at, piece_end))
            self._garbage_at = piece_end

    def _flush_garbage(self, out: list[Record], end: int) -> None:
        lo = self._garbage_at
        if lo is not None and end > lo:
            out.append(self._garbage_record(lo, end))
        self._garbage_at = None

    def _garbage_record(self, lo: int, hi: int) -> Record:
        raw = bytes(self._buf[lo:hi])
        return self._stamp(
            Record(
                t=None,
                bus=self.bus,
                protocol=self.protocol,
                kind=GARBAGE,
                length=len(raw),
                raw=raw,
                offset=self._base + lo,
                errors=[M.FRAMING_GARBAGE.text(length=len(raw), why=self._garbage_why)],
                summary=f"{len(raw)} garbage bytes",
                flags=[M.FRAMING_GARBAGE.code],
            )
        )

    def _frame(self, buf: bytearray, pos: int, length: int, valid: bool) -> Record:
        offset = self._base + pos
        if self.byte_time_s is None:
            return self.make_record(
                bytes(buf[pos : pos + length]), offset, self._time_of(offset), valid
            )
        return self._stamp(self.make_record(bytes(buf[pos : pos + length]), offset, None, valid))

    def _truncated(self, raw: bytes, pos: int) -> Record:
        if self._stopping:
            return self._cut_off_record(raw, pos)
        return self._stamp(
            Record(
                t=None,
                bus=self.bus,
                protocol=self.protocol,
                kind=TRUNCATED,
                length=len(raw),
                raw=raw,
                offset=self._base + pos,
                errors=[self.truncated_reason(raw)],
                summary=f"truncated frame ({len(raw)} bytes)",
                flags=[TRUNCATED_FLAG],  # the words are the protocol's truncated_reason
            )
        )

    def _cut_off_record(self, raw: bytes, pos: int) -> Record:
        return self._stamp(
            Record(
                t=None,
                bus=self.bus,
                protocol=self.protocol,
                kind=CUT_OFF,
                length=len(raw),
                raw=raw,
                offset=self._base + pos,
                warnings=[M.FRAMING_CUT_OFF.text(bytes=_bytes(len(raw)))],
                summary=f"frame cut off by the stop ({_bytes(len(raw))})",
                flags=[M.FRAMING_CUT_OFF.code],
            )
        )


def _bytes(n: int) -> str:
    return "1 byte" if n == 1 else f"{n} bytes"
