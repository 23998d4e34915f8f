"""Helpers of the tap tests: drain a TapQueue into items and events, wait for conditions; a
real pty pair to tap."""

from __future__ import annotations

import os
import select
import time
import tty
from collections.abc import Callable

from analyzer.model import Item, SourceEvent
from analyzer.sources.live import TapQueue


class Collector:
    """Drains a TapQueue into items and events, waiting for conditions."""

    def __init__(self, q: TapQueue) -> None:
        self.q = q
        self.items: list[Item] = []
        self.events: list[SourceEvent] = []

    def pump(self, timeout: float = 0.02) -> None:
        for x in self.q.get_batch(timeout=timeout):
            if isinstance(x, SourceEvent):
                self.events.append(x)
            else:
                self.items.append(x)

    def wait(self, cond: Callable[[Collector], bool], timeout: float = 5.0) -> None:
        end = time.monotonic() + timeout
        while not cond(self):
            if time.monotonic() > end:
                kinds = [(e.kind, e.message) for e in self.events]
                raise AssertionError(f"timed out; events so far: {kinds}")
            self.pump()

    def wait_event(self, kind: str, n: int = 1, timeout: float = 5.0) -> SourceEvent:
        self.wait(lambda c: len(c.of(kind)) >= n, timeout)
        return self.of(kind)[n - 1]

    def of(self, kind: str) -> list[SourceEvent]:
        return [e for e in self.events if e.kind == kind]


class Pty:
    """A pty pair: the test drives the master, the tap opens the slave by name."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)  # no echo, no line discipline, before the tap opens it
        self.name = os.ttyname(self.slave)
        self.closed = False

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            n = os.write(self.master, view)
            view = view[n:]

    def readable(self, timeout: float) -> bool:
        return bool(select.select([self.master], [], [], timeout)[0])

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            os.close(self.master)
            os.close(self.slave)
