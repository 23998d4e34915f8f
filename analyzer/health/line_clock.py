"""When a byte stream's frames began and ended, from the times of the reads that brought them.

A tap stamps each read when it returns: when its last byte arrived. A byte before it in the same
read arrived earlier by the bytes between them at the line's speed (``decoders.framing`` counts a
record's time back the same way). So a frame's start is its first byte's read time less the
bytes from there to the end of that read, and its end is its last byte's read time less the
bytes after it. Two times counted back from one read assume the line carried the bytes between
them without a pause: a gap or a turnaround inside one read cannot be measured, and is not.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Final

from decoders.model import Chunk

MAX_READS: Final = 100_000  # reads held for records still to come (records that never come,
# of a device filtered out, must not grow it without end)


@dataclass(frozen=True, slots=True)
class FrameTimes:
    """A frame's first byte's start and last byte's end on the line; ``first_read`` and
    ``last_read``: which reads brought them (the stream offset each read began at)."""

    start: float
    end: float
    first_read: int
    last_read: int


class LineClock:
    """The reads of one byte stream, held until the records of their bytes have come."""

    def __init__(self, byte_time_s: float) -> None:
        self.byte_time_s = byte_time_s
        self.reads: deque[tuple[int, int, float | None]] = deque()  # start, end offset, time
        self.offset = 0  # the stream offset after the last read
        self.direction: str | None = None  # the direction of its bytes, where the tap knows it

    def add(self, chunk: Chunk) -> None:
        n = len(chunk.data)
        if not n:
            return
        self.reads.append((self.offset, self.offset + n, chunk.t))
        self.offset += n
        if chunk.direction is not None:
            self.direction = chunk.direction
        if len(self.reads) > MAX_READS:
            self.reads.popleft()

    def times(self, offset: int, length: int) -> FrameTimes | None:
        """The times of the ``length`` bytes from stream offset ``offset`` (None: a read without
        a time, or reads no longer held). Reads wholly before them are let go."""
        reads = self.reads
        while reads and reads[0][1] <= offset:
            reads.popleft()
        if not reads or reads[0][0] > offset or length <= 0:
            return None
        last = offset + length
        first_read = reads[0]
        last_read = next((r for r in reads if r[1] >= last), None)
        if last_read is None or first_read[2] is None or last_read[2] is None:
            return None
        bt = self.byte_time_s
        start = first_read[2] - (first_read[1] - offset) * bt
        end = last_read[2] - (last_read[1] - last) * bt
        return FrameTimes(start, end, first_read[0], last_read[0])
