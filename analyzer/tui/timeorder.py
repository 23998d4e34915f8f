"""The TUI's order of records: capture time across buses, stream order within a bus.

A session hands records over in stream order: the order its decoding finished them. Across
buses that is not time order: a serial frame is finished when its last byte (or the idle gap
after it) has come, so CAN frames captured meanwhile are handed over first, and a time column
would run backwards. ``TimeMerge`` merges the buses' streams by time before the store takes
them (a k-way merge: a record is let through once every bus still talking has reached its
time), so the store, and the frame list, hold records in capture-time order.

- Within a bus, stream order is kept: a bus whose own clock steps back is not reordered (its
  records sort at the latest time the bus had reached).
- A bus silent for ``hold_s`` (of the capture's clock, or the wall clock live) holds nobody
  back: the view never waits on a quiet line. Captures hold ``CAPTURE_HOLD_S`` (longer than a
  frame is ever held), so their order is strict; live sessions hold a batching window.
- One bus (a raw dump, a candump log of one channel) is handed through as it comes: its stream
  order is its time order, and a native batch stays a batch.
- ``flush()`` at the end lets everything through.

Records keep their ``seq`` (the record's identity in ``decode``'s output, go-to and pairs), so
across buses the numbers in the list are not in row order.
"""

from __future__ import annotations

import heapq
import math
from collections import deque
from collections.abc import Sequence
from itertools import count
from typing import Final

from decoders.model import Record

from ..batches import column

CAPTURE_HOLD_S: Final = 2.0  # capture seconds a quiet bus may hold the others back
LIVE_HOLD_S: Final = 0.3  # live: about a batching window and a serial line's idle gap


class TimeMerge:
    """See the module doc. ``push(records)`` and ``advance(now)`` return the records that are
    ready, in order; ``flush()`` all that are left."""

    def __init__(self, hold_s: float = CAPTURE_HOLD_S) -> None:
        self.hold_s = hold_s
        self.latest: dict[str, float] = {}  # per bus: the time it has reached (its sort key)
        self._held: dict[str, deque[tuple[float, int, Record]]] = {}
        self._held_count = 0
        self._arrival = count()

    @property
    def held(self) -> int:
        return self._held_count

    def push(self, records: Sequence[Record], now: float | None = None) -> Sequence[Record]:
        """Take a batch (in stream order); ``now``: the wall clock of a live session."""
        if not records:
            return self.advance(now)
        buses = column(records, "bus")
        first = buses[0]
        if self._held_count == 0 and all(b == first for b in buses) and set(self.latest) <= {first}:
            self._reach(first, column(records, "t"))
            return records  # one bus so far: its stream order is the order
        latest, held, arrival = self.latest, self._held, self._arrival
        for rec, bus, t in zip(records, buses, column(records, "t"), strict=True):
            reached = latest.get(bus, -math.inf)
            key = reached if t is None or t < reached else t
            latest[bus] = key
            queue = held.get(bus)
            if queue is None:
                queue = held[bus] = deque()
            queue.append((key, next(arrival), rec))
        self._held_count += len(records)
        return self.advance(now)

    def advance(self, now: float | None = None) -> list[Record]:
        """The held records every bus still talking has reached (``now``: the wall clock,
        live, so quiet buses stop holding the others back while nothing arrives)."""
        if not self._held_count:
            return []
        newest = max(self.latest.values())
        clock = newest if now is None else max(newest, now)
        talking = [t for t in self.latest.values() if t >= clock - self.hold_s]
        return self._release(min(talking) if talking else math.inf)

    def flush(self) -> list[Record]:
        return self._release(math.inf)

    def _reach(self, bus: str, times: Sequence[float | None]) -> None:
        reached = self.latest.get(bus, -math.inf)
        for t in times:
            if t is not None and t > reached:
                reached = t
        self.latest[bus] = reached

    def _release(self, until: float) -> list[Record]:
        heads = [(q[0], bus) for bus, q in self._held.items() if q and q[0][0] <= until]
        if not heads:
            return []
        heapq.heapify(heads)
        out: list[Record] = []
        held = self._held
        while heads:
            (_, _, rec), bus = heads[0]
            queue = held[bus]
            queue.popleft()
            out.append(rec)
            if queue and queue[0][0] <= until:
                heapq.heapreplace(heads, (queue[0], bus))
            else:
                heapq.heappop(heads)
        self._held_count -= len(out)
        return out
