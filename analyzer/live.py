"""A live session: taps feed a bounded queue; this loop decodes off the capture threads.

taps ──(TapQueue)──> Decoding ──> Tracker ──> outputs (text on stdout, MCAP recording)

Drops (a consumer that fell behind) are counted by the queue and reported as events; events
from the taps (port lost, reopened, passive or not) go to every output. Ctrl-C or SIGTERM ends
the session cleanly: held bytes and requests are decided and the MCAP file is finished.
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Protocol

from decoders.model import Record

from .pipeline import Decoding, Item
from .sources.live import INFO, WARNING, SourceEvent, Tap, TapQueue
from .tracker import DeviceState, Tracker

TICK_S = 0.05


class LiveOutput(Protocol):
    def records(self, records: list[Record]) -> None: ...
    def event(self, event: SourceEvent) -> None: ...
    def states(self, states: list[DeviceState]) -> None: ...
    def items(self, items: list[Item]) -> None: ...
    def tick(self) -> None: ...
    def close(self) -> None: ...


class OutputBase:
    """No-op defaults, so an output implements only what it shows."""

    def records(self, records: list[Record]) -> None:
        pass

    def event(self, event: SourceEvent) -> None:
        pass

    def states(self, states: list[DeviceState]) -> None:
        pass

    def items(self, items: list[Item]) -> None:
        pass

    def tick(self) -> None:
        pass

    def close(self) -> None:
        pass


@dataclass
class SessionCounts:
    items: int = 0
    records: int = 0
    errors: int = 0
    dropped: int = 0

    def line(self) -> str:
        return (
            f"{self.items:,} chunks/frames captured, {self.records:,} records decoded, "
            f"{self.errors:,} with errors, {self.dropped:,} dropped"
        )


class LiveSession:
    def __init__(
        self,
        taps: list[Tap],
        outputs: list[Any],
        protocol: str | None = None,
        queue_size: int = 200_000,
        per_bus: dict[str, str] | None = None,
    ) -> None:
        self.taps = taps
        self.outputs = outputs
        self.queue = TapQueue(queue_size)
        self.decoding = Decoding(protocol, per_bus)
        self.tracker = Tracker()
        self.counts = SessionCounts()
        self.stop_event = threading.Event()

    def run(
        self, duration: float | None = None, on_start: Callable[[], None] | None = None
    ) -> SessionCounts:
        """Run until stop(), Ctrl-C, SIGTERM or ``duration`` seconds; always finishes cleanly.
        ``on_start`` runs once the taps are listening."""
        deadline = None if duration is None else time.monotonic() + duration
        with _sigterm_as_interrupt():
            try:
                for tap in self.taps:
                    tap.start(self.queue)
                if on_start is not None:
                    on_start()
                while not self.stop_event.is_set():
                    if deadline is not None and time.monotonic() >= deadline:
                        break
                    self._step(self.queue.get_batch(TICK_S))
            except KeyboardInterrupt:
                pass
            finally:
                for tap in self.taps:
                    try:
                        tap.stop()
                    except Exception as exc:  # a failing close must not lose the recording
                        self._event(
                            SourceEvent(
                                time.time(),
                                tap.bus,
                                WARNING,
                                f"error while closing: {exc}",
                                "closed",
                            )
                        )
                self._step(self.queue.get_batch(0.0, max_items=10**9), final=True)
                for out in self.outputs:
                    out.close()
        return self.counts

    def stop(self) -> None:
        self.stop_event.set()

    def _event(self, ev: SourceEvent) -> None:
        for out in self.outputs:
            out.event(ev)

    def _step(self, batch: list[Item | SourceEvent], final: bool = False) -> None:
        records: list[Record] = []
        items: list[Item] = []
        feed = self.decoding.feed
        for x in batch:
            if isinstance(x, SourceEvent):
                if items:  # keep events in order with the data around them
                    self._emit(items, records)
                    items, records = [], []
                self._event(x)
            else:
                items.append(x)
                records += feed(x)
        self.counts.items += len(items)
        records += self.decoding.finish() if final else self.decoding.tick(time.time())
        drops = self.queue.new_drops()
        if drops:
            self.counts.dropped += drops
            self._event(
                SourceEvent(
                    time.time(),
                    "*",
                    WARNING,
                    f"consumer fell behind: dropped {drops} items",
                    "drops",
                )
            )
        self._emit(items, records)
        for out in self.outputs:
            out.tick()

    def _emit(self, items: list[Item], records: list[Record]) -> None:
        if items:
            for out in self.outputs:
                out.items(items)
        if not records:
            return
        self.counts.records += len(records)
        self.counts.errors += sum(1 for r in records if r.errors)
        changed: dict[int, DeviceState] = {}
        update = self.tracker.update
        for rec in records:
            st = update(rec)
            if st is not None:
                changed[id(st)] = st
        for out in self.outputs:
            out.records(records)
            if changed:
                out.states(list(changed.values()))


def info(bus: str, message: str, kind: str = "info") -> SourceEvent:
    return SourceEvent(time.time(), bus, INFO, message, kind)


@contextmanager
def _sigterm_as_interrupt() -> Iterator[None]:
    """SIGTERM ends a session like Ctrl-C does (only possible from the main thread)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
