"""The TUI's session listener: fills the record store and the panels' tables on the session's
thread, and posts one ``FeedUpdate`` to the app every ``POST_INTERVAL_S`` (never one message
per record). It also carries the app's requests back to the session's thread: marks to write
into the recording, which only that thread may write.

Records reach the store in capture-time order across buses (``timeorder.TimeMerge``; within
a bus in stream order), so the frame list's time column never runs backwards.

The trigger (``--freeze-on``) is checked here, on every record as it is stored, so the first
match is found even when a batch holds thousands of records.

The device panel's changes are found by comparing each gripper's state with the one posted
before (cansniffer's way: a value that changed), so the feed asks the session for no state
samples: a sample copies the whole state for every reading, a cost the screen does not need.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Final, Protocol

from decoders import flags as F
from decoders.model import Record

from ..model import SourceEvent
from ..session.listener import Listener
from ..session.timeorder import CAPTURE_HOLD_S, LIVE_HOLD_S, TimeMerge
from .aggregates import Aggregates
from .messages import DeviceRow, FeedUpdate
from .store import RecordStore

if TYPE_CHECKING:
    from ..session.batches import RecordSequence, SampleSequence

POST_INTERVAL_S: Final = 0.1  # 10 updates a second
PANELS_INTERVAL_S: Final = 1.0  # the panels' tables (problems, registers, latency) this often

TRIGGERS: Final[dict[str, Callable[[Record], bool]]] = {
    "error": lambda r: bool(r.errors),
    "fault": lambda r: F.DEVICE_FAULT in r.flags,
    "unanswered": lambda r: F.UNANSWERED in r.flags,
}


class MarkWriter(Protocol):
    def write_mark(self, t: float | None, name: str, seq: int | None = None) -> None: ...


class Poster(Protocol):
    def post_message(self, message: Any) -> bool: ...


class TuiFeed(Listener):
    """See the module doc. ``post``: where updates go (the app); ``states``: the session
    tracker's states, read on the session's thread only."""

    wants_states = False
    wants_raw = True  # the input tells the time order which buses are still to be heard from

    def __init__(self, store: RecordStore | None = None, live: bool = False) -> None:
        self.store = store if store is not None else RecordStore()
        self.live = live  # records are timed by the wall clock: quiet buses age by it
        self.merge = TimeMerge(LIVE_HOLD_S if live else CAPTURE_HOLD_S)
        self.aggregates = Aggregates()
        self.label = "the TUI"
        self.target: Poster | None = None
        self.states: Callable[[], dict[tuple[str, int], Any]] | None = None
        self.counts: Callable[[], tuple[int, int]] | None = None  # (captured, dropped)
        self.recorder: MarkWriter | None = None
        self.trigger: str | None = None  # armed: the TRIGGERS key
        self._fired: int | None = None
        self._changed: set[tuple[str, int, str]] = set()
        self._posted: dict[tuple[str, int], dict[str, Any]] = {}  # the states last posted
        self._events: list[SourceEvent] = []
        self._marks: list[tuple[float | None, str, int | None]] = []
        self._lock = threading.Lock()  # guards _marks and trigger (set from the app)
        self._next_post = 0.0
        self._next_panels = 0.0
        self.closed = False

    # -- from the app (any thread) ---------------------------------------------------------

    def arm(self, trigger: str | None) -> None:
        """Arm the trigger (a TRIGGERS key) or disarm it (None); it fires once per arming."""
        if trigger is not None and trigger not in TRIGGERS:
            raise ValueError(f"unknown trigger {trigger!r}; choose from {', '.join(TRIGGERS)}")
        with self._lock:
            self.trigger = trigger

    def add_mark(self, t: float | None, name: str, seq: int | None) -> bool:
        """Queue a mark for the recording; False when nothing records."""
        if self.recorder is None:
            return False
        with self._lock:
            self._marks.append((t, name, seq))
        return True

    # -- the listener (the session's thread) -------------------------------------------------

    def on_records(self, records: RecordSequence) -> None:
        self._store(self.merge.push(records, time.time() if self.live else None))

    def _store(self, records: RecordSequence) -> None:
        if not records:
            return
        first = self.store.count
        self.store.append(records)
        self.aggregates.add(records, first)
        trigger = self.trigger
        if trigger is not None and self._fired is None:
            match = TRIGGERS[trigger]
            for k, rec in enumerate(records):
                if match(rec):
                    self._fired = first + k
                    with self._lock:
                        self.trigger = None  # one shot: the user re-arms
                    break

    def on_raw(self, items: list[Any]) -> None:
        self.merge.hear(items)

    def on_states(self, samples: SampleSequence) -> None:
        changed = self._changed
        for s in samples:
            for name in s.changed:
                changed.add((s.bus, s.device, name))

    def on_event(self, event: SourceEvent) -> None:
        self._events.append(event)

    def tick(self, now: float) -> None:
        if self.merge.held:
            self._store(self.merge.advance(now if self.live else None))
        self._write_marks()
        mono = time.monotonic()
        if mono >= self._next_post:
            self._post(mono)

    def close(self) -> None:
        self._store(self.merge.flush())
        self._write_marks()
        self.closed = True
        self._post(time.monotonic(), done=True)

    def on_error(self, exc: BaseException) -> None:
        self._events.append(
            SourceEvent(time.time(), "tui", 4, f"the screen failed: {exc}", "listener_failed")
        )

    # -- inside -----------------------------------------------------------------------------

    def _write_marks(self) -> None:
        if not self._marks or self.recorder is None:
            return
        with self._lock:
            marks, self._marks = self._marks, []
        for t, name, seq in marks:
            self.recorder.write_mark(t, name, seq)

    def _devices(self) -> list[DeviceRow]:
        """Every gripper's state, a copy; the fields that changed since the last post go into
        ``_changed``."""
        if self.states is None:
            return []
        rows = []
        changed, posted = self._changed, self._posted
        for key, st in list(self.states().items()):
            values = dict(st.values)
            before = posted.get(key, {})
            for name, value in values.items():
                if value is not None and before.get(name) != value:
                    changed.add((st.bus, st.device, name))
            posted[key] = values
            rows.append(DeviceRow(st.bus, st.device, st.protocol, st.t, values))
        return rows

    def _post(self, mono: float, done: bool = False) -> None:
        self._next_post = mono + POST_INTERVAL_S
        panels = done or mono >= self._next_panels
        if panels:
            self._next_panels = mono + PANELS_INTERVAL_S
        captured, dropped = self.counts() if self.counts is not None else (0, 0)
        update = FeedUpdate(
            count=self.store.count,
            devices=self._devices(),
            changed=self._changed,
            snapshot=self.aggregates.snapshot() if panels else None,
            events=self._events,
            trigger=self._fired,
            captured=captured,
            dropped=dropped,
            done=done,
        )
        self._changed, self._events, self._fired = set(), [], None
        if self.target is not None:
            self.target.post_message(update)
