"""The contract between live taps (capture threads) and the decoding consumer.

A Tap runs its own capture thread(s) and puts Items (raw chunks or CAN frames, stamped on
arrival) and SourceEvents (port lost, reopened, passive or not, ...: see ``supervisor``) into a
TapQueue. The queue is bounded: a capture thread never blocks on a slow consumer; when the queue
is full the item is dropped and counted, and the consumer reports the count (drops are never
silent). A tap's ``settings`` (plain JSON data) describe it in a recording's metadata.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from ..model import Item, SourceEvent

# the events of a tap whose device went away (lost: the source failed) or was closed (the
# capture stopped): what was held for the bus's frames ends there
LOST = "lost"
CLOSED = "closed"


class TapQueue:
    """Bounded hand-over from capture threads to the consumer, counting what it had to drop.

    A deque, whose appends and pops are atomic: no lock per item on either side (queue.Queue
    takes a lock and signals a condition for every put and every get, which at 12,000 CAN
    frames/s costs more than decoding them). The consumer sleeps on an Event that a capture
    thread sets only when it is clear, about once per batch."""

    def __init__(self, maxsize: int = 200_000) -> None:
        self.maxsize = maxsize
        self._items: deque[Item | SourceEvent] = deque()
        self._ready = threading.Event()
        self._lock = threading.Lock()
        self.dropped = 0
        self._dropped_reported = 0

    def put(self, item: Item | SourceEvent) -> None:
        """Never blocks: a full queue drops the item and counts it."""
        if len(self._items) >= self.maxsize:
            with self._lock:
                self.dropped += 1
            return
        self._items.append(item)
        if not self._ready.is_set():
            self._ready.set()

    def get_batch(self, timeout: float = 0.05, max_items: int = 10_000) -> list[Item | SourceEvent]:
        """Everything waiting (up to max_items), waiting up to timeout for the first."""
        items = self._items
        if not items:
            self._ready.clear()
            if not items:  # checked again after the clear: a put in between has set it
                self._ready.wait(timeout)
        pop = items.popleft
        return [pop() for _ in range(min(len(items), max_items))]

    def new_drops(self) -> int:
        """Drops since the last call (for a 'dropped N items' event)."""
        with self._lock:
            n = self.dropped - self._dropped_reported
            self._dropped_reported = self.dropped
        return n


@dataclass
class Tap:
    """Base of the live sources. ``start`` launches capture threads feeding ``out``; ``stop``
    ends them and closes the hardware. ``passive`` is "yes", "no" or "unknown": whether the
    tap is guaranteed never to transmit on the bus it watches."""

    bus: str
    passive: str = "unknown"
    settings: dict[str, Any] = field(default_factory=dict)
    #: a serial tap named after the protocol its bytes show (sources/naming.py), not yet named
    named_by_protocol = False

    @property
    def is_open(self) -> bool:
        """The tap is capturing now (taps that open their ports on a thread override this)."""
        return True

    def start(self, out: TapQueue) -> None:
        raise NotImplementedError

    def stop(self) -> None:
        raise NotImplementedError

    @property
    def failed(self) -> str | None:
        """Why the tap gave up for good (a setting its device refuses), else None."""
        return None

    def first_open(self) -> str | None:
        """After ``start``: block until the first attempt to open the tap's device(s) is over.
        None when they opened (or are waited for: ``--wait``), else why not, naming the device
        ("/dev/ttyUSB0: no such port"). A tap that opens nothing returns None."""
        return None

    def event(self, out: TapQueue, level: int, kind: str, message: str, count: int = 1) -> None:
        out.put(SourceEvent(time.time(), self.bus, level, message, kind, count))


def first_attempts_over(events: list[threading.Event]) -> None:
    """Wait for every event; in short steps, so Ctrl-C is seen at once meanwhile."""
    for event in events:
        while not event.wait(0.1):
            pass


def wait_open(taps: list[Tap], timeout: float = 3.0) -> bool:
    """Wait until every tap is capturing (they open their ports on their own threads)."""
    deadline = time.monotonic() + timeout
    while not all(t.is_open for t in taps):
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.01)
    return True
