"""The session core: one Source -> Decoding -> Tracker -> listeners loop for every command.

```
source (live taps behind a bounded queue, or a capture file, paced or not)
   └─ batches of Items and SourceEvents ─> Decoding (framing, decoding, lint, pairing)
                                             └─ Records ─> Tracker ─> StateSamples
   listeners: on_raw(items), on_records(records), on_states(samples), on_event(event), tick, close
```

``decode``, ``stats``, ``live``, ``record``, ``bridge``, ``demo`` (and the TUI and Rerun views)
all run this loop; they differ only in their source and listeners. Every call into a listener is
guarded: a listener that raises is told (``on_error``), reported once to the others as an event,
and detached; it never ends the session or loses a recording. Ctrl-C, SIGTERM and SIGHUP end a
session cleanly, after the batch in hand: held bytes and requests are decided and every listener
is closed (a signal while it finishes is ignored: one is enough, and the recording must be
finished).

How it ends decides what held data means. A capture that ran to its end decides its held bytes
and waiting requests as damage (``truncated``, ``unanswered``). A capture that was stopped (a
user's stop, the end of ``duration``, or a live source's taps closed) cuts them off:
``cut_off`` records and requests, which are not errors of the bus. A source that was lost
(``lost``) keeps the damage: the bus went away under them.
"""

from __future__ import annotations

import gc
import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from .. import interrupts
from ..model import ERROR, SourceEvent
from ..sources.live import CLOSED, LOST, Tap
from ..sources.source import Batch, LiveSource, Source
from .batches import NativeCanDecoding, RecordSequence, session_engine
from .listener import Listener
from .timeorder import CAPTURE_HOLD_S, LIVE_HOLD_S, TimeMerge


@dataclass(frozen=True)
class SessionOptions:
    """How a session decodes. ``protocol``: the byte-stream protocol (None: detected per
    stream); ``per_bus``: fixed protocols of named buses; ``byte_time_s``: seconds per byte of
    named serial buses (10 bits / baud), to time frames inside a read; ``duration``: stop after
    this many seconds of wall time (None: run until the source ends or Ctrl-C); ``engine``:
    "auto" (the native core for CAN input and one byte stream where it is built), "python" or
    "native"
    (analyzer/session/batches.py)."""

    protocol: str | None = None
    per_bus: dict[str, str] = field(default_factory=dict)
    byte_time_s: dict[str, float] = field(default_factory=dict)
    duration: float | None = None
    engine: str = "auto"


@dataclass
class SessionCounts:
    items: int = 0
    records: int = 0
    errors: int = 0
    samples: int = 0
    dropped: int = 0
    interrupted: bool = False  # ended by Ctrl-C, SIGTERM or SIGHUP
    live: bool = False  # the source was live: a user's stop is how it ends

    def line(self) -> str:
        return (
            f"{self.items:,} chunks/frames captured, {self.records:,} records decoded, "
            f"{self.errors:,} with errors, {self.dropped:,} dropped"
        )


class Session:
    """Runs one source through the decoders into listeners. ``run()`` blocks until the source
    ends, ``stop()`` is called (from any thread), the duration passes or Ctrl-C."""

    def __init__(
        self,
        source: Source,
        listeners: list[Listener],
        options: SessionOptions | None = None,
    ) -> None:
        self.source = source
        self.options = options or SessionOptions()
        self.listeners: list[Listener] = list(listeners)
        opts = self.options
        self.decoding, self.tracker = session_engine(
            opts.engine,
            source.kind,
            source.positional,
            opts.protocol,
            opts.per_bus,
            opts.byte_time_s,
        )
        if isinstance(self.decoding, NativeCanDecoding) and not any(
            x.wants_raw and not x.reads_frame_batches for x in self.listeners
        ):
            source.read_natively()  # a capture's frames straight into the native decoding
        self.counts = SessionCounts(live=source.live)
        self.detached: list[tuple[Listener, BaseException]] = []
        self._stop = threading.Event()
        self._closed = False
        self._finishing = False  # in _finish: signals are ignored, the recording must end
        self._cut_short = True  # the source did not run to its end (set when it did)
        self._named = 0  # the source's bus protocols handed to the decoding
        self._direct: set[int] = set()  # the listeners that read the tracker itself
        # records of several buses in capture-time order (a byte stream's frames are finished
        # after CAN frames captured meanwhile); CAN input and one stream come in time order
        self._order: TimeMerge | None = None
        if source.kind != "can" and not source.positional:
            self._order = TimeMerge(LIVE_HOLD_S if source.live else CAPTURE_HOLD_S)

    # -- running ---------------------------------------------------------------------------

    def run(self) -> SessionCounts:
        deadline = None
        if self.options.duration is not None:
            deadline = time.monotonic() + self.options.duration
        # samples cost a copy of the state per reading: made only when someone reads them
        readers = [x for x in self.listeners if x.wants_states]
        self._direct = {id(x) for x in readers if x.reads_tracker(self.tracker)}
        readers = [x for x in readers if id(x) not in self._direct]
        self.tracker.samples = bool(readers)
        self.tracker.snapshots = any(x.reads_whole_states for x in readers)
        with _handled_by(self._on_signal), rare_gc():
            try:
                self.source.start()  # a live source that never opens raises SourceError
                for batch in self.source.batches(self._stop):
                    self._step(batch)
                    if deadline is not None and time.monotonic() >= deadline:
                        break
                    if self._stop.is_set() or not self.listeners:
                        break  # stopped, or every output failed: nothing left to do
                else:  # a live source never ends by itself: its end is a stop
                    self._cut_short = self._stop.is_set() or self.source.live
            except KeyboardInterrupt:
                self.counts.interrupted = True
            finally:
                self._finishing = True
                self._finish()
        return self.counts

    def stop(self) -> None:
        """End the session from another thread (the TUI's quit, a test)."""
        self._stop.set()

    def interrupt(self) -> None:
        """End the session as Ctrl-C ends it, from another thread (a signal that a view on the
        main thread received): a capture cut short exits 130, a live one is stopped (0)."""
        self.counts.interrupted = True
        self._stop.set()

    def _on_signal(self, signum: int, frame: Any) -> None:
        """Ctrl-C, SIGTERM, SIGHUP while the session runs on the main thread: the session
        ends after the batch in hand (never in the middle of a listener's write, which would
        leave a recording half-written); a second one, before the session got there, raises
        KeyboardInterrupt where it is (a stuck output); while it finishes they are ignored."""
        if self._finishing:
            return
        if self.counts.interrupted:
            raise KeyboardInterrupt
        self.interrupt()

    def _finish(self) -> None:
        try:
            rest = self.source.stop()
        except KeyboardInterrupt:
            self.counts.interrupted = True
            rest = []
        self._step(rest, final=True)
        self.counts.dropped = self.source.dropped
        self._finishing = False
        for listener in list(self.listeners):
            self._call(listener, "close")
        self._closed = True

    # -- one batch ---------------------------------------------------------------------------

    def _step(self, batch: Batch, final: bool = False) -> None:
        decoding = self.decoding
        named = self.source.protocols
        if len(named) > self._named:  # buses the source named after their protocol
            for bus, protocol in list(named.items())[self._named :]:
                decoding.set_protocol(bus, protocol)
            self._named = len(named)
        items: Any = []  # since the last event
        if not isinstance(batch, list):  # native frames (Source.read_natively): no events
            items, batch = batch, []
        for x in batch:
            if isinstance(x, SourceEvent):
                records = decoding.feed_items(items)
                # what was held for that bus ends before the gap (damage) or the stop (cut off)
                if x.kind == LOST:
                    records += decoding.gap(x.bus)
                elif x.kind == CLOSED:
                    records += decoding.cut_off(x.bus)
                # keep events in order with the data around them
                self._emit(items, records, x)
                items = []
            else:
                items.append(x)
        records = decoding.feed_items(items)
        now = time.time()
        if final:
            records += decoding.stop() if self._cut_short else decoding.finish()
        elif self.source.live:
            records += decoding.tick(now)
        self._emit(items, records, flush=final)
        for listener in tuple(self.listeners):  # a detach must not skip the next one
            try:
                listener.tick(now)
            except Exception as exc:
                self._detach(listener, exc)

    def _emit(
        self,
        items: list[Any],
        records: RecordSequence,
        event: SourceEvent | None = None,
        flush: bool = False,
    ) -> None:
        """The raw input, then the records and the event (if any) in capture-time order."""
        order = self._order
        if order is None:
            self._deliver(items, records)
            if event is not None:
                self._event(event)
            return
        order.hear(items)
        # a source event rides among the records (TimeMerge reads its bus and time as theirs)
        held = RecordSequence([*records, event] if event is not None else records)
        out = list(order.push(held, time.time() if self.source.live else None))
        if flush:
            out += order.flush()
        self._deliver(items, RecordSequence())
        run = RecordSequence()
        for x in out:  # runs of records, and the events between them
            if type(x) is SourceEvent:
                self._deliver([], run)
                run = RecordSequence()
                self._event(x)
            else:
                run.append(x)
        self._deliver([], run)

    def _deliver(self, items: list[Any], records: RecordSequence) -> None:
        counts = self.counts
        if items:
            counts.items += len(items)
            for listener in tuple(self.listeners):
                if listener.wants_raw:
                    self._call(listener, "on_raw", items)
        if not records:
            return
        counts.records += len(records)
        counts.errors += records.error_count()
        samples = self.tracker.update_many(records)
        counts.samples += len(samples)
        for listener in tuple(self.listeners):
            self._call(listener, "on_records", records)
            if samples and listener.wants_states and id(listener) not in self._direct:
                self._call(listener, "on_states", samples)

    def _event(self, event: SourceEvent) -> None:
        for listener in tuple(self.listeners):
            self._call(listener, "on_event", event)

    # -- guarding ----------------------------------------------------------------------------

    def _call(self, listener: Listener, method: str, *args: Any) -> None:
        if listener not in self.listeners:
            return  # detached earlier in this batch
        try:
            getattr(listener, method)(*args)
        except Exception as exc:
            self._detach(listener, exc)

    def _detach(self, listener: Listener, exc: BaseException) -> None:
        """Take a failing listener out of the session, tell it and everyone else, once."""
        if listener not in self.listeners:
            return
        self.listeners.remove(listener)
        self.detached.append((listener, exc))
        name = getattr(listener, "label", type(listener).__name__)
        event = SourceEvent(
            time.time(),
            "session",
            ERROR,
            f"output {name} failed and was detached: {type(exc).__name__}: {exc}",
            "listener_failed",
        )
        try:
            listener.on_error(exc)
        except Exception:
            pass  # it is already out; its own error report failing changes nothing
        try:
            if not self._closed:
                listener.close()
        except Exception:
            pass
        self._event(event)


def live_session(
    taps: list[Tap],
    listeners: list[Listener],
    *,
    queue_size: int = 200_000,
    **options: Any,
) -> Session:
    """A session on live taps (``options``: the fields of SessionOptions)."""
    return Session(LiveSource(taps, queue_size), listeners, SessionOptions(**options))


_gc_lock = threading.Lock()
_gc_users = 0
_gc_before: tuple[int, int, int] = (0, 0, 0)


@contextmanager
def rare_gc() -> Iterator[None]:
    """Records hold no reference cycles, so refcounting frees them; with the default
    thresholds the cyclic collector re-walks the live objects every few hundred allocations
    (a large decode's throughput halves; a live view's session thread spends a quarter of its
    time there). While sessions run it runs rarely instead, so memory stays bounded even if a
    library makes cycles. The thresholds are the process's: the first of concurrent sessions
    sets them, the last one restores them."""
    global _gc_users, _gc_before
    with _gc_lock:
        if _gc_users == 0:
            _gc_before = gc.get_threshold()
            gc.set_threshold(100_000, 50, 1000)
        _gc_users += 1
    try:
        yield
    finally:
        with _gc_lock:
            _gc_users -= 1
            if _gc_users == 0:
                gc.set_threshold(*_gc_before)


@contextmanager
def signals_call(callback: Callable[[], None]) -> Iterator[None]:
    """While the block runs (a view that owns the main thread: the TUI), Ctrl-C, SIGTERM and
    SIGHUP call ``callback`` on a thread of its own (a signal handler must not wait), once, so
    the view can close its session and finish its recording; nothing is raised."""
    called = threading.Event()

    def handler(signum: int, frame: Any) -> None:
        if not called.is_set():
            called.set()
            threading.Thread(target=callback, name="eg2scope stop", daemon=True).start()

    with _handled_by(handler):
        yield


@contextmanager
def _handled_by(handler: Callable[[int, Any], None]) -> Iterator[None]:
    """Ctrl-C, SIGTERM and SIGHUP go to ``handler`` in the block (main thread only). Ctrl-C
    and SIGHUP that the process was told to ignore (a background job of a script, ``nohup``)
    stay ignored; SIGTERM, which nothing ignores on purpose, never is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    wanted = [signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None)]
    previous = {
        sig: signal.signal(sig, handler)
        for sig in wanted
        if sig is not None
        and (sig == signal.SIGTERM or signal.getsignal(sig) is not signal.SIG_IGN)
        # a caller that notes them itself (eg2scope batch) stops the session at its own steps
        and not interrupts.notes(sig)
    }
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


@contextmanager
def signals_as_interrupt() -> Iterator[None]:
    """Ctrl-C, SIGTERM (kill, ``systemctl stop``) and SIGHUP (terminal closed) raise
    KeyboardInterrupt, wherever the command is (a session running meanwhile handles them its
    own way: ``Session._on_signal``). Only from the main thread; elsewhere nothing changes
    (``_handled_by`` says which signals)."""

    def handler(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    with _handled_by(handler):
        yield
