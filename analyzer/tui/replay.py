"""A capture replayed under the user's hand: pause, resume and change speed while it plays.

``ReplaySource`` is a ``CaptureSource`` whose pacing can change at any time from another thread
(the TUI's keys): ``pause()``, ``resume()``, ``set_speed(x)`` (None: as fast as possible). Items
are let through when their capture time, divided by the speed, has come on the wall clock; a
speed change or a resume starts the mapping afresh, so nothing jumps. While paused or waiting it
yields empty batches every ``IDLE_S`` so the session keeps ticking its listeners (the screen,
marks into a recording). ``position`` (0-1) is how far through the file the replay is;
``finished``, whether it was read to its end (a stop before that leaves it False).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import Final

from ..model import Item, SourceEvent
from ..sources.capture import CaptureReader
from ..sources.source import CAPTURE_BATCH_ITEMS, Batch, CaptureSource

SPEEDS: Final[tuple[float | None, ...]] = (1.0, 2.0, 5.0, 10.0, None)  # None: max
IDLE_S: Final = 0.05  # longest wait without a batch (a tick for the listeners)


def speed_text(speed: float | None) -> str:
    return "max" if speed is None else f"{speed:g}x"


def next_speed(speed: float | None, step: int) -> float | None:
    """The next speed of ``SPEEDS`` up (step 1) or down (-1) from ``speed``."""
    if speed in SPEEDS:
        i = SPEEDS.index(speed)
    else:  # a speed from the command line: the nearest listed one above it
        i = next((k for k, s in enumerate(SPEEDS) if s is None or s >= (speed or 0)), 0)
    return SPEEDS[max(0, min(len(SPEEDS) - 1, i + step))]


class ReplaySource(CaptureSource):
    """See the module doc."""

    def __init__(self, reader: CaptureReader, speed: float | None = None) -> None:
        super().__init__(reader, speed)
        self._running = threading.Event()
        self._running.set()
        self._changed = threading.Event()  # speed changed or resumed: map time afresh
        self.finished = False

    # -- control (any thread) --------------------------------------------------------------

    @property
    def paused(self) -> bool:
        return not self._running.is_set()

    def pause(self) -> None:
        self._running.clear()

    def resume(self) -> None:
        self._changed.set()
        self._running.set()

    def toggle(self) -> bool:
        """Pause or resume; True if now paused."""
        if self.paused:
            self.resume()
        else:
            self.pause()
        return self.paused

    def set_speed(self, speed: float | None) -> None:
        self.speed = speed
        self._changed.set()

    @property
    def position(self) -> float:
        if self.finished:
            return 1.0
        size = self.reader.size or 0
        return min(1.0, self.reader.position / size) if size else 0.0

    # -- the session's side ------------------------------------------------------------------

    def batches(self, stop: threading.Event) -> Iterator[Batch]:
        batch: Batch = []
        anchor: tuple[float, float] | None = None  # (capture time, wall time) that match
        last_yield = time.monotonic()
        for x in self.reader:
            if not self._running.is_set():
                yield from self._pause(batch, stop)
                batch, anchor = [], None
            if self._changed.is_set():
                self._changed.clear()
                anchor = None
            speed = self.speed
            t = x.t if type(x) is SourceEvent else x.payload.t if type(x) is Item else None
            if speed is not None and t is not None:
                if anchor is None or t < anchor[0]:
                    anchor = (t, time.monotonic())
                due = anchor[1] + (t - anchor[0]) / speed
                while not stop.is_set():
                    wait = due - time.monotonic()
                    if wait <= 0 or self._changed.is_set() or not self._running.is_set():
                        break
                    if batch or time.monotonic() - last_yield >= IDLE_S:
                        yield batch  # what is due now; or an empty batch: a tick
                        batch = []
                        last_yield = time.monotonic()
                    time.sleep(min(wait, IDLE_S))
            batch.append(x)
            if len(batch) >= CAPTURE_BATCH_ITEMS or (speed is not None and t is None):
                yield batch
                batch = []
            if stop.is_set():
                break
        else:
            if batch:
                yield batch
            self.finished = True  # read to its end: a stop from now on cuts nothing off
            return
        if batch:
            yield batch

    def _pause(self, batch: Batch, stop: threading.Event) -> Iterator[Batch]:
        if batch:
            yield batch
        while not self._running.wait(IDLE_S) and not stop.is_set():
            yield []
