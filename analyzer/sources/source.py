"""What a session reads from: live taps behind a bounded queue, or a capture file.

A Source yields batches of ``Item``s (raw input) and ``SourceEvent``s in arrival order. Live taps
capture on their own threads into a ``TapQueue`` (a slow consumer never blocks them: drops are
counted and reported as events); a capture file is read on the session's thread, paced to its own
timing when a replay speed is given. The session decodes each batch and calls its listeners.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

from ..errors import SourceError
from ..model import WARNING, Item, SourceEvent
from .live import Tap, TapQueue
from .naming import BusNamer
from .pacing import paced

if TYPE_CHECKING:
    from .capture import CaptureReader

Batch = list[Item | SourceEvent]

LIVE_BATCH_S = 0.05  # live: decode and show 20 times a second
LIVE_BATCH_ITEMS = 2000  # and after a backlog, in steps short enough to keep views refreshed
CAPTURE_BATCH_ITEMS = 2048  # captures: CAN frames (or byte chunks) per batch
CAPTURE_BATCH_BYTES = 1 << 14  # ... or this many bytes of chunks (records and samples in cache)
# the words of a device that is not there (yet): --wait would wait for it
ABSENT = ("no such", "is down")


class Source:
    """Base: ``start()``, iterate ``batches(stop)``, then ``stop()`` returns what is left."""

    #: live sources are ticked with wall time (quiet lines decide their held bytes)
    live = False
    #: records can be numbered by their place in the input (offset / CAN index)
    positional = False
    #: items lost because the session fell behind (live only)
    dropped = 0
    #: what the items are: "can" (CAN frames only), "bytes" (byte chunks only) or "mixed"
    kind = "mixed"

    def start(self) -> None:
        pass

    def batches(self, stop: threading.Event) -> Iterator[Batch]:
        raise NotImplementedError

    def stop(self) -> Batch:
        return []

    def read_natively(self) -> None:
        """The session decodes with the native core and no listener wants the raw items: a
        source that can hand it native frame batches (no Python object per frame) does."""

    @property
    def errors(self) -> list[str]:
        """Damage found in the input (a capture file); empty for live sources."""
        return []

    @property
    def protocols(self) -> dict[str, str]:
        """The protocols of buses the source named after them (bus -> protocol), so the
        decoding uses the protocol a name says (sources/naming.py)."""
        return {}


class LiveSource(Source):
    """One or more taps feeding one bounded queue. ``start`` opens them: a tap whose device
    does not open raises ``SourceError`` (unless it waits for it: ``--wait``)."""

    live = True

    def __init__(self, taps: list[Tap], queue_size: int = 200_000) -> None:
        self.taps = taps
        self.kind = live_kind(taps)
        self.queue = TapQueue(queue_size)
        self.dropped = 0
        self.on_started: Callable[[], None] | None = None  # runs once the taps listen
        self.started = False
        self.namer = BusNamer(taps)

    @property
    def protocols(self) -> dict[str, str]:
        return self.namer.protocols

    def start(self) -> None:
        """Start every tap and wait for each one's first attempt to open its device; if any
        did not open, stop them all and raise ``SourceError`` naming each device and why.
        Once started, calling it again does nothing (a command opens its source before it
        makes its outputs, and the session then runs it)."""
        if self.started:
            return
        self.started = True
        try:
            for tap in self.taps:
                tap.start(self.queue)
            failures = [why for why in (tap.first_open() for tap in self.taps) if why]
        except BaseException:
            self._stop_taps()
            raise
        if failures:
            self._stop_taps()
            self.queue.get_batch(0.0, max_items=10**9)  # their events: the error says it all
            absent = any(word in why for why in failures for word in ABSENT)
            hint = " (--wait waits for a device that is not plugged in yet)" if absent else ""
            raise SourceError("; ".join(f"cannot open {why}" for why in failures) + hint)
        if self.on_started is not None:
            self.on_started()

    def batches(self, stop: threading.Event) -> Iterator[Batch]:
        """A batch every ``LIVE_BATCH_S`` (at once after a full one: a backlog). Taking what
        waits as soon as the decoding is free would decode a few frames at a time, all the
        time: the capture threads, whose every receive gives up Python's GIL, would have to
        win it back from the decoding for every frame, at a cost greater than the frame's.
        Decoding in bursts leaves the capture threads the GIL in between."""
        get = self.queue.get_batch
        due = time.monotonic()
        while not stop.is_set():
            wait = due - time.monotonic()
            if wait > 0 and stop.wait(wait):
                break
            due = time.monotonic() + LIVE_BATCH_S
            batch = get(LIVE_BATCH_S, LIVE_BATCH_ITEMS)
            if len(batch) >= LIVE_BATCH_ITEMS:
                due = 0.0
            drops = self._drops()
            if drops is not None:
                batch.append(drops)
            yield self.namer.sort(batch)

    def stop(self) -> Batch:
        rest = self._stop_taps()
        rest = self.queue.get_batch(0.0, max_items=10**9) + rest
        drops = self._drops()
        if drops is not None:
            rest.append(drops)
        return self.namer.sort(rest) + self.namer.finish()

    def _stop_taps(self) -> Batch:
        """Stop every tap; a failing close is an event (it must not lose the recording)."""
        events: Batch = []
        for tap in self.taps:
            try:
                tap.stop()
            except Exception as exc:
                message = f"error while closing: {exc}"
                events.append(SourceEvent(time.time(), tap.bus, WARNING, message, "closed"))
        return events

    def _drops(self) -> SourceEvent | None:
        n = self.queue.new_drops()
        if not n:
            return None
        self.dropped += n
        return SourceEvent(
            time.time(), "*", WARNING, f"consumer fell behind: dropped {n} items", "drops", n
        )


def live_kind(taps: Sequence[Tap]) -> str:
    """What a live source of ``taps`` gives: "can" (frames), "bytes" or "mixed"."""
    kinds = {_tap_kind(tap) for tap in taps}
    return kinds.pop() if len(kinds) == 1 else "mixed"


def _tap_kind(tap: Tap) -> str:
    """What a tap's items are, from its settings' ``kind`` (a tap that does not say: "mixed")."""
    kind = str(tap.settings.get("kind", ""))
    return "can" if kind == "can" else "bytes" if kind.startswith("serial") else "mixed"


class CaptureSource(Source):
    """A capture file, read on the session's thread; ``speed`` paces it to its own timing
    (1 = real time, 10 = ten times faster, None = as fast as possible)."""

    def __init__(self, reader: CaptureReader, speed: float | None = None) -> None:
        self.reader = reader
        self.speed = speed
        self.positional = reader.single_stream
        self.kind = reader.kind
        self.frames: Any = None  # the native core's reader of the frames (read_natively)

    @property
    def errors(self) -> list[str]:
        return self.reader.errors

    def read_natively(self) -> None:
        """A candump log read at full speed is read by the native core, as ``decode`` reads
        it (analyzer/session/engine.py ``candump_frames``): the same frames, bus names and
        errors."""
        from ..session.engine import candump_frames

        if self.speed is None and self.frames is None:
            self.frames = candump_frames(self.reader)

    @property
    def protocols(self) -> dict[str, str]:
        """The protocols the capture says its byte buses speak (a recording's)."""
        return self.reader.protocols

    def batches(self, stop: threading.Event) -> Iterator[Batch]:
        if self.frames is not None:
            yield from self._native_batches(stop)
            return
        if self.speed is not None:  # paced: each item as it falls due (a stop wakes it)

            def nap(seconds: float) -> None:
                stop.wait(seconds)

            for x in paced(self.reader, self.speed, sleep=nap):
                yield [x]
                if stop.is_set():
                    return
            return
        batch: Batch = []
        size = 0
        for x in self.reader:
            batch.append(x)
            if type(x) is Item:
                size += len(x.payload.data)
            if len(batch) >= CAPTURE_BATCH_ITEMS or size >= CAPTURE_BATCH_BYTES:
                yield batch
                batch, size = [], 0
                if stop.is_set():
                    return
        if batch:
            yield batch

    def _native_batches(self, stop: threading.Event) -> Iterator[Any]:
        """Native frame batches (``FrameBatch``: CAN frames only, no events among them); the
        reader's position and, at the end, its errors, as the Python reader keeps them."""
        frames, reader = self.frames, self.reader
        while (batch := frames.read(CAPTURE_BATCH_ITEMS)) is not None:
            reader.position = frames.position
            yield batch
            if stop.is_set():
                return
        reader.position = reader.size
        reader.errors += frames.errors
