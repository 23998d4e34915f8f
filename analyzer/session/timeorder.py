"""The TUI's order of records: capture time across buses, stream order within a bus.

A session hands records over in stream order: the order its decoding finished them. Across
buses that is not time order: a serial frame is finished when its last byte (or the idle gap
after it) has come, and a byte stream's first frames wait until its protocol is detected, so
CAN frames captured meanwhile are handed over first, and a time column would run backwards.
``TimeMerge`` merges the buses' streams by time before the store takes them, so the store,
and the frame list, hold records in capture-time order:

- It hears the raw input (``hear``) as well as the records (``push``): a bus whose bytes came
  in but whose records are not out yet holds the others back from the time of those bytes.
  A record is let through once every bus still talking has reached its time (a k-way merge).
- Within a bus, stream order is kept: a bus whose own clock steps back is not reordered (its
  records sort at the latest time the bus had reached).
- A bus quiet for ``hold_s`` (no input: of the capture's clock, or the wall clock live) holds
  nobody back, so the view never waits on a silent line. Captures hold ``CAPTURE_HOLD_S``,
  live sessions about a batching window (``LIVE_HOLD_S``); at most ``MAX_HELD`` records wait
  (a slow line still detecting its protocol cannot hold a fast bus's records without end).
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
from typing import Any, Final

from decoders.model import Record

from .batches import RecordSequence

CAPTURE_HOLD_S: Final = 2.0  # capture seconds a quiet bus may hold the others back
LIVE_HOLD_S: Final = 0.3  # live: about a batching window and a serial line's idle gap
MAX_HELD: Final = 100_000


class TimeMerge:
    """See the module doc. ``push(records)`` and ``advance(now)`` return the records that are
    ready, in order; ``flush()`` all that are left."""

    def __init__(self, hold_s: float = CAPTURE_HOLD_S, max_held: int = MAX_HELD) -> None:
        self.hold_s = hold_s
        self.max_held = max_held
        self.reached: dict[str, float] = {}  # per bus: the time its records have reached
        self.heard: dict[str, float] = {}  # per bus: the latest time of its input
        self.first_heard: dict[str, float] = {}  # per bus: the time of its first input
        self._held: dict[str, deque[tuple[float, int, Record]]] = {}
        self._held_count = 0
        self._arrival = count()

    @property
    def held(self) -> int:
        return self._held_count

    def hear(self, items: Sequence[Any]) -> None:
        """The raw input (``Item``s) of the records that will follow."""
        heard, first = self.heard, self.first_heard
        if len(heard) == 1 and items:
            (only,) = heard
            last = items[-1].payload.t
            if last is not None and all(item.bus == only for item in items):
                heard[only] = max(heard[only], last)  # one bus: its input comes in time order
                return
        for item in items:
            t = item.payload.t
            if t is None:
                continue
            bus = item.bus
            if bus not in heard:
                heard[bus] = first[bus] = t
            elif t > heard[bus]:
                heard[bus] = t

    def push(self, records: RecordSequence, now: float | None = None) -> RecordSequence:
        """Take a batch (in stream order); ``now``: the wall clock of a live session. What is
        ready comes out as a sequence: the batch itself, or a ``RecordSequence``."""
        if not records:
            return self.advance(now)
        buses = records.column("bus")
        only = buses[0]
        if (
            not self._held_count
            and set(self.heard) | set(self.reached) <= {only}
            and all(b == only for b in buses)
        ):
            self._reach(only, records.column("t"))
            return records  # one bus so far: its stream order is the order
        reached, held, arrival = self.reached, self._held, self._arrival
        for rec, bus, t in zip(records, buses, records.column("t"), strict=True):
            last = reached.get(bus, -math.inf)
            key = last if t is None or t < last else t
            reached[bus] = key
            queue = held.get(bus)
            if queue is None:
                queue = held[bus] = deque()
            queue.append((key, next(arrival), rec))
        self._held_count += len(records)
        return self.advance(now)

    def advance(self, now: float | None = None) -> RecordSequence:
        """The held records every bus still talking has reached (``now``: the wall clock,
        live, so quiet buses stop holding the others back while nothing arrives)."""
        if not self._held_count:
            return RecordSequence()
        buses = set(self.reached) | set(self.heard)
        heard = {b: self.heard.get(b, self.reached.get(b, -math.inf)) for b in buses}
        clock = max(heard.values())
        if now is not None:
            clock = max(clock, now)
        # a bus with input but no records yet holds the others from its first input on
        bounds = [
            self.reached.get(b, self.first_heard.get(b, -math.inf))
            for b in buses
            if heard[b] >= clock - self.hold_s
        ]
        out = self._release(min(bounds) if bounds else math.inf)
        if self._held_count > self.max_held:
            out += self._release(math.inf, self._held_count - self.max_held)
        return out

    def flush(self) -> RecordSequence:
        return self._release(math.inf)

    def _reach(self, bus: str, times: Sequence[float | None]) -> None:
        reached = self.reached.get(bus, -math.inf)
        for t in times:
            if t is not None and t > reached:
                reached = t
        self.reached[bus] = reached

    def _release(self, until: float, most: int | None = None) -> RecordSequence:
        """Held records up to ``until``, in order (``most``: no more than that many)."""
        heads = [(q[0], bus) for bus, q in self._held.items() if q and q[0][0] <= until]
        heapq.heapify(heads)
        out = RecordSequence()
        held = self._held
        while heads and (most is None or len(out) < most):
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
