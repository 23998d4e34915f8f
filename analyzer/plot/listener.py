"""The Rerun listener: every state sample of a session plotted on two timelines, with the
commands, errors, fault marks and bus health around them (the entity contract: docs/rerun.md,
its names: ``analyzer/plot/entities.py``).

Values are buffered and sent as typed columns in batches (``plot/batch.py``: one Arrow record
batch for the entities that share their rows, one chunk per entity; never one ``log`` call per
value): every ``flush_interval`` seconds (a live viewer is updated ten times a second), whenever
``max_rows`` records and samples are waiting, and at the end. Nothing is downsampled. Each row
carries ``capture_time`` (the record's ``t``) and ``frame`` (its ``seq``); a capture without
timestamps (a raw serial dump) has ``frame`` only. The default blueprint (``plot/blueprint.py``)
shows the entities that have rows: a viewer that watches gets a new one whenever a gripper, a
bus or a quantity appears; a capture's file gets that of the whole capture at the end.

The hot path does as little per value as it can. A state sample is filed under its gripper and
the fields it changed (its "shape": a CAN reply of force, opening, current and temperature is one
shape, a reply of state and fault another): one C-level call cuts the plotted values out of it
into the shape's row-major array, two appends add its time and seq; a shape's fields share their
rows, so they go out as one record batch. Records are read as columns; the few the logs show
(problems, commands) are gathered per bus and gripper by ``plot/logs.log_rows``, which the
native core does for its batches without making a Record per record. Live, the session flushes
at its ticks when a flush is due, and a timer thread flushes when a long batch keeps the session
busy past that; the Arrow columns are built and sent outside the buffers' lock, so the session
goes on decoding meanwhile.
"""

from __future__ import annotations

import math
import threading
import time
from array import array
from itertools import groupby
from typing import TYPE_CHECKING, Any, Final

import numpy as np
import pyarrow as pa

from decoders.model import Record

from ..cycles.listener import CyclesListener
from ..health.listener import HealthListener
from ..health.rates import BusRates
from ..model import LEVEL_NAMES, WARNING, SourceEvent
from ..session.listener import Listener
from . import entities as ent
from .batch import SCALARS, STATE, TEXT_LOG, Batches, nanoseconds
from .blueprint import LATENCY_PLOT, LOAD_PLOT, RATES_PLOT, Layout, blueprint
from .columns import LANE, NAN, SCALAR, TEXT, Columns, Entity
from .cycles import RerunCycles
from .health import BusHealthColumns, silent
from .logs import log_rows
from .target import RerunOutput, RerunTarget, parse_target

if TYPE_CHECKING:
    from ..session.batches import RecordSequence, SampleSequence

# a live viewer is updated at least ten times a second: flushes are due on a fixed 80 ms grid
# (12.5 a second), at the session's ticks or, when a batch keeps it busy, from a timer thread
LIVE_FLUSH_S: Final = 0.08
CAPTURE_FLUSH_S: Final = 2.0  # a capture read at full speed: few, large chunks
LAYOUT_EVERY_S: Final = 1.0  # the blueprint is sent again at most this often
# records and samples waiting before a flush, whatever the time: what waits (with its Arrow
# copies and Rerun's) is most of a capture's peak memory; flushing more often costs no more CPU
MAX_ROWS: Final = 40_000

_LEVELS: Final = {"debug": "DEBUG", "info": "INFO", "warning": "WARN", "error": "ERROR"}
# the state fields plotted, in the order their entities are sent
_PLOTTED: Final = (*(s.field for s in ent.SERIES), *ent.LANES)


def _runs(buses: list[str]) -> list[tuple[str, int, int]]:
    """(bus, first index, end index) of each run of records of one bus."""
    if buses and buses.count(buses[0]) == len(buses):
        return [(buses[0], 0, len(buses))]
    runs = []
    for name, group in groupby(range(len(buses)), buses.__getitem__):
        indexes = list(group)
        runs.append((name, indexes[0], indexes[-1] + 1))
    return runs


# a field's rows: (field, t, seq, values)
_Rows = tuple[str, np.ndarray, np.ndarray, Any]


class _Shape:
    """The samples of one gripper that changed the same plotted fields (a reply to one kind of
    read), as columns: times (NaN: none), seqs, and one column of values per field. A sample
    with a value that is not a number (None: named without a value) goes to its gripper's
    ``odd`` columns instead."""

    __slots__ = ("fields", "gripper", "seq", "t", "values")

    def __init__(self, gripper: _Gripper, fields: tuple[str, ...]) -> None:
        self.gripper = gripper
        self.fields = fields
        self._start()

    def _start(self) -> None:
        self.t = array("d")
        self.seq = array("q")
        self.values = [array("d") for _ in self.fields]

    def extend(
        self, times: list[float | None], seqs: list[int], columns: list[list[Any]]
    ) -> list[int]:
        """Add rows (a group of ``samples.series``); the rows with a value that is not
        a number are left out and their indexes returned."""
        try:
            numbers = [array("d", c) for c in columns]
        except TypeError:  # None, or not a number: row by row
            return self._extend_rows(times, seqs, columns)
        stamps: list[Any] = times if None not in times else [NAN if t is None else t for t in times]
        self.t.fromlist(stamps)
        self.seq.fromlist(seqs)
        for values, new in zip(self.values, numbers, strict=True):
            values.extend(new)
        return []

    def _extend_rows(
        self, times: list[float | None], seqs: list[int], columns: list[list[Any]]
    ) -> list[int]:
        odd = []
        for k, row in enumerate(zip(*columns, strict=True)):
            try:
                numbers = array("d", row)
            except TypeError:
                odd.append(k)
                continue
            t = times[k]
            self.t.append(NAN if t is None else t)
            self.seq.append(seqs[k])
            for values, x in zip(self.values, numbers, strict=True):
                values.append(x)
        return odd

    def take(self) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        """(t, seq, values: one column per field); the shape starts empty."""
        t, seq, values = self.t, self.seq, self.values
        self._start()
        columns = [np.frombuffer(v, dtype=np.float64) for v in values]
        return np.frombuffer(t), np.frombuffer(seq, dtype=np.int64), columns


class _Gripper:
    """One gripper: its entities by state field, its shapes, commands and fault marks (times
    and seqs; a mark sits at the force last read, found when it is sent)."""

    __slots__ = (
        "by_field",
        "commands",
        "force",
        "key",
        "mark_seq",
        "mark_t",
        "marks",
        "odd",
        "shapes",
    )

    def __init__(self, bus: str, device: int) -> None:
        base = ent.gripper_path(bus, device)
        self.key = (bus, device)
        self.by_field: dict[str, Entity] = {
            s.field: Entity(f"{base}/{s.entity}", SCALAR, ent.series_style(s), s.convert)
            for s in ent.SERIES
        }
        self.by_field["state"] = Entity(f"{base}/{ent.STATE}", LANE, ent.state_configuration())
        self.by_field["fault"] = Entity(f"{base}/{ent.FAULT}", LANE, ent.fault_configuration())
        self.commands = Columns(f"{base}/{ent.COMMANDS}", TEXT)
        self.marks = Entity(f"{base}/{ent.FAULT_MARKS}", SCALAR, ent.fault_marks_style())
        self.mark_t: list[float | None] = []  # marks of records with errors or fault flags
        self.mark_seq: list[int] = []
        self.shapes: list[_Shape] = []
        self.odd: dict[str, Columns] = {}  # field -> rows of samples not filed by shape
        self.force: Any = None  # the force last read (sent): where a later fault mark sits

    def take(self) -> tuple[list[_Rows], list[float | None], list[int]]:
        """The rows waiting, per field (a shape's fields share their times and seqs), and the
        marks of faulty records; the gripper starts empty."""
        rows: list[_Rows] = []
        for shape in self.shapes:
            if shape.seq:
                t, seq, columns = shape.take()
                rows += [(f, t, seq, c) for f, c in zip(shape.fields, columns, strict=True)]
        for field, c in self.odd.items():
            if c.values:
                t, odd_seq, values, _ = c.take()
                assert odd_seq is not None
                rows.append((field, t, odd_seq, values))
        marks = self.mark_t, self.mark_seq
        self.mark_t, self.mark_seq = [], []
        return rows, *marks


class _Bus:
    """One bus's error log and health: its load, frames and errors per second
    (``plot/health.py``, from the bus health's seconds), unanswered requests per second of
    capture time (a point at the end of each second; a silent stretch drops to zero), and
    every latency. Record times are gathered as they come and counted per second when sent."""

    __slots__ = (
        "errors",
        "first_t",
        "health",
        "highest_latency",
        "last_t",
        "latency",
        "times",
        "unanswered",
        "unanswered_per_s",
    )

    def __init__(self, bus: str, index: int) -> None:
        base = ent.bus_path(bus)
        self.errors = Columns(f"{base}/{ent.ERRORS}", TEXT)
        health = f"{base}/{ent.HEALTH}"
        self.latency = Columns(
            f"{health}/{ent.LATENCY}", SCALAR, ent.health_style(ent.LATENCY, bus, index)
        )
        self.unanswered_per_s = Columns(
            f"{health}/{ent.UNANSWERED_PER_S}",
            SCALAR,
            ent.health_style(ent.UNANSWERED_PER_S, bus, index),
            frame=False,
        )
        self.health = BusHealthColumns(bus, index)
        self.highest_latency = 0.0  # the latency plot's y range leaves room above it
        self.first_t = math.inf  # the bus's first record: where its controller state begins
        self.last_t = -math.inf  # the bus's last record: where the last, partial second ends
        self.times = array("d")  # every record's t
        self.unanswered = array("d")  # ... of unanswered requests

    def count_seconds(self, final: bool) -> None:
        """Count the unanswered requests of the finished seconds; the second still being
        captured waits for the next call (unless ``final``)."""
        if not self.times:
            return
        times = np.frombuffer(self.times, dtype=np.float64)
        seconds = np.floor(times)
        last = seconds.max()
        done = seconds < last if not final else np.ones(len(times), bool)
        self.times = array("d", times[~done].tobytes())
        secs = np.unique(seconds[done])
        if not len(secs):
            return
        unanswered = np.floor(np.frombuffer(self.unanswered, dtype=np.float64))
        kept = unanswered >= last if not final else np.zeros(len(unanswered), bool)
        self.unanswered = array("d", unanswered[kept].tobytes())
        idx = np.searchsorted(secs, unanswered[~kept])
        counts = np.bincount(idx[idx < len(secs)], minlength=len(secs))
        # a point at the end of each second; the capture's last, partial second at its end
        ends, zeros = np.minimum(secs + 1, self.last_t), silent(secs)
        t = np.concatenate([ends, zeros])
        order = np.argsort(t, kind="stable")
        column = self.unanswered_per_s
        column.t.extend(t[order].tolist())
        column.values.extend(np.concatenate([counts, np.zeros(len(zeros))])[order].tolist())

    def columns(self) -> list[Columns]:
        return [self.errors, self.latency, self.unanswered_per_s, *self.health.columns()]


class RerunListener(Listener):
    """Plots a session in Rerun. ``where``: an open ``RerunOutput``, a ``RerunTarget``, or a
    ``--rerun`` target string (``run.rrd``, ``spawn``, ``web``, a viewer URL). ``live``: a live
    session (plots follow a sliding 10 s window; source events go to the error logs; a timer
    thread keeps the flushes on their grid however long the session's batches take)."""

    wants_states = True
    wants_raw = True  # the bus health counts the raw frames (a native FrameBatch too)
    reads_frame_batches = True
    label = "rerun"

    def __init__(
        self,
        where: RerunOutput | RerunTarget | str,
        *,
        live: bool = False,
        flush_interval: float | None = None,
        max_rows: int = MAX_ROWS,
        rates: BusRates | None = None,
    ) -> None:
        self.live = live
        self.layout = Layout(live=live)
        if isinstance(where, str):
            where = parse_target(where)
        if isinstance(where, RerunTarget):
            where = RerunOutput(where)
        self.output = where
        self.stream = where.stream
        if live:  # the viewer opens at once; a capture is attached when its layout is known
            where.show(blueprint(self.layout))
        self.flush_interval = flush_interval or (LIVE_FLUSH_S if live else CAPTURE_FLUSH_S)
        self.max_rows = max_rows
        self.grippers: dict[tuple[str, int], _Gripper] = {}
        self.buses: dict[str, _Bus] = {}
        self.session_errors: Columns | None = None
        # the bus health's seconds and the grip cycles, by their own listeners
        self.health = HealthListener(rates, seconds=True)
        self.cycles = RerunCycles()
        self._cycles = CyclesListener(self.cycles)
        # (bus, device, *fields changed) -> the shape its samples are filed under; False: a
        # shape with nothing plotted (a poll's last_command, a write's latency)
        self._shapes: dict[tuple[str, int, tuple[str, ...]], _Shape] = {}
        self._timed = self._untimed = False  # rows with and without capture_time were sent
        self._seq_span = (math.inf, -math.inf)  # the first and last record's seq and t
        self._time_span = (math.inf, -math.inf)
        self._sent_paths: set[str] = set()  # entities with rows (only flushes add to it)
        self._highest: dict[str, float] = {}  # plot origin -> its highest value sent
        self._sent_layout: Layout | None = self.layout if live else None
        self._pending = 0
        self._next_flush = time.monotonic() + self.flush_interval  # when a flush is due
        self._batches = Batches()
        self._next_layout = 0.0  # when the blueprint may be sent again
        self._closed = False
        # the buffers: the session's calls and a flush's taking of what waits take turns on
        # ``_lock`` (the sending is done outside it: the session goes on meanwhile); flushes
        # take turns on ``_sending``. A batch's records and its samples are never sent apart
        # (a fault mark is found once, at the force last read).
        self._lock = threading.RLock()
        self._batch_done = threading.Condition(self._lock)
        self._sending = threading.Lock()
        self._mid_batch = False
        self._failure: BaseException | None = None  # the timer's, raised on the session's thread
        self._stop_timer = threading.Event()
        self._timer: threading.Thread | None = None
        if live:
            self._timer = threading.Thread(target=self._run_timer, name="rerun-flush", daemon=True)
            self._timer.start()

    # -- what the session gives ------------------------------------------------------------

    def reads_tracker(self, tracker: Any) -> bool:
        """Its grip cycles read the native tracker themselves; the samples it plots still
        come to it (False)."""
        self._cycles.reads_tracker(tracker)
        return False

    def on_states(self, samples: SampleSequence) -> None:
        """File the samples under their shapes, a column per plotted field
        (``samples.series``: a native batch makes no samples)."""
        with self._lock:
            self._raise_failure()
            for bus, device, fields, times, seqs, columns in samples.series(_PLOTTED):
                shape = self._shapes.get((bus, device, fields))
                if shape is None:
                    shape = self._new_shape(bus, device, fields)
                for k in shape.extend(times, seqs, columns):
                    self._odd(shape, times[k], seqs[k], [c[k] for c in columns])
            self._cycles.on_states(samples)
            self._pending += len(samples)
            self._mid_batch = False
            self._batch_done.notify_all()

    def on_records(self, records: RecordSequence) -> None:
        """Times per bus for the health rates, latencies, and the few records the logs show
        (problems, commands), made into objects only those (columns otherwise, in C loops:
        a capture's million records pass through here)."""
        with self._lock:
            self._raise_failure()
            self._mid_batch = True  # its samples come next
            times = records.column("t")
            stamps = np.array(times, dtype=np.float64)  # None -> NaN
            latencies = np.array(records.column("latency_ms"), dtype=np.float64)
            seqs = np.array(records.column("seq"), dtype=np.int64)
            self._extend_span(stamps, seqs)
            for name, lo, hi in _runs(records.column("bus")):
                bus = self.buses.get(name) or self._bus(name)
                part = times[lo:hi]
                if None in part:
                    part = [t for t in part if t is not None]
                if part:
                    bus.times.fromlist(part)
                    bus.last_t = max(bus.last_t, max(part))
                    bus.first_t = min(bus.first_t, min(part))
                # a latency needs both times: never NaN
                timed = ~(np.isnan(latencies[lo:hi]) | np.isnan(stamps[lo:hi]))
                if timed.any():
                    latency = bus.latency
                    latency.t.frombytes(stamps[lo:hi][timed].tobytes())
                    latency.seq.frombytes(seqs[lo:hi][timed].tobytes())  # type: ignore[union-attr]
                    latency.values.frombytes(latencies[lo:hi][timed].tobytes())
                    highest = float(latencies[lo:hi][timed].max())
                    bus.highest_latency = max(bus.highest_latency, highest)
            self._logs(records)
            self.health.on_records(records)
            self._cycles.on_records(records)
            self._pending += len(records)

    def on_raw(self, items: Any) -> None:
        """The raw input, for the bus health (a list of Items, or a native FrameBatch)."""
        with self._lock:
            self.health.on_raw(items)

    def _logs(self, records: RecordSequence) -> None:
        """The records the logs show: problems in their bus's error log and health counts,
        commands and fault marks under their gripper (``plot/logs.log_rows``: columns, not
        one object per record, on the native path)."""
        buses, grippers = log_rows(records)
        for name, (t, seq, text, level, _, _, unanswered) in buses.items():
            bus = self.buses[name]  # made for the records' runs
            bus.errors.extend(t, seq, text, level)
            bus.unanswered.fromlist(unanswered)
        for key, (t, seq, text, level, mark_t, mark_seq) in grippers.items():
            g = self.grippers.get(key) or self._gripper(*key)
            g.commands.extend(t, seq, text, level)
            g.mark_t += mark_t
            g.mark_seq += mark_seq

    def _extend_span(self, stamps: np.ndarray, seqs: np.ndarray) -> None:
        """The first and last record on each timeline so far (the plots of a capture span
        them)."""
        if len(seqs):
            first, last = self._seq_span
            self._seq_span = (min(first, int(seqs.min())), max(last, int(seqs.max())))
        timed = stamps[~np.isnan(stamps)]
        if len(timed):
            first_t, last_t = self._time_span
            self._time_span = (min(first_t, float(timed.min())), max(last_t, float(timed.max())))

    def on_event(self, event: SourceEvent) -> None:
        """Warnings and errors of a live source (a port lost, drops) in the bus's error log.
        A capture's events carry the wall clock, not the capture's: they are not plotted."""
        if not self.live or event.level < WARNING:
            return
        with self._lock:
            bus = self.buses.get(event.bus)
            if bus is not None:
                columns = bus.errors
            else:
                if self.session_errors is None:
                    self.session_errors = Columns(ent.SESSION_ERRORS, TEXT, frame=False)
                columns = self.session_errors
            level = _LEVELS.get(LEVEL_NAMES.get(event.level, "info"), "INFO")
            columns.add(event.t, None, event.message, level)

    def tick(self, now: float) -> None:
        with self._lock:
            self._mid_batch = False  # the batch is complete
            self._batch_done.notify_all()
            self._raise_failure()
            self._cycles.tick(now)
            due = self._pending >= self.max_rows or (
                self._pending and time.monotonic() >= self._next_flush
            )
        if due and not self._sending.locked():  # (not while the timer's flush is sending)
            self.flush()

    def close(self) -> None:
        self._stop()
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._mid_batch = False
            self._cycles.close()  # the cycles still open end with the session
        self.flush(final=True)
        self.output.finish(blueprint(self.layout))

    def on_error(self, exc: BaseException) -> None:
        self._stop()
        with self._lock:
            self._closed = True
        try:
            self.output.finish(blueprint(self.layout))
        except Exception:
            pass  # already detached; the session reports the first error

    # -- the timer (live) ------------------------------------------------------------------

    def _run_timer(self) -> None:
        """The session flushes at its ticks when a flush is due; when a batch keeps it busy a
        whole interval past the due time, this thread flushes instead, so the viewer is updated
        however long the session's batches take. (Not sooner: in a process whose threads share
        one GIL, a flush on this thread runs slower than the same flush at a tick.)"""
        stop = self._stop_timer
        late = self.flush_interval  # a whole interval late: the session is in a long batch
        while not stop.wait(max(self._next_flush + late - time.monotonic(), 0.001)):
            with self._lock:
                if self._closed:
                    return
                now = time.monotonic()
                if now < self._next_flush + late:
                    continue  # flushed at a tick meanwhile
                if not self._pending:
                    self._schedule(now)  # nothing new: the next slot of the grid
                    continue
            try:
                self.flush()  # looked up on the instance: a wrapper sees every flush
            except Exception as exc:  # the session detaches us at its next call
                self._failure = exc
                return

    def _stop(self) -> None:
        self._stop_timer.set()
        timer = self._timer
        if timer is not None and timer is not threading.current_thread():
            timer.join()

    def _raise_failure(self) -> None:
        if self._failure is not None:
            failure, self._failure = self._failure, None
            raise failure

    # -- sending ---------------------------------------------------------------------------

    def flush(self, final: bool = False) -> None:
        """Send every buffered column, then the layout if a gripper or bus appeared. What
        waits is taken under the buffers' lock (on the timer's thread, once the batch whose
        records came has given its samples); it is turned into Arrow and sent outside it."""
        with self._sending:
            with self._lock:
                if threading.current_thread() is self._timer:
                    self._batch_done.wait_for(lambda: not self._mid_batch, timeout=1.0)
                self._schedule(time.monotonic())
                grippers = [(g, g.take()) for g in self.grippers.values()]
                columns = [(c, c.take()) for c in self._columns(final) if c.values]
                self._pending = 0
            readings = [g.key for g, taken in grippers if self._send_gripper(g, *taken)]
            for c, rows in columns:
                self._send_entity(c, *rows)
            self._batches.send(self.stream)
            with self._lock:
                self.layout = self._grown_layout(readings, final)
                layout = self.layout
            mono = time.monotonic()
            # grippers appear in bursts when a session starts: a blueprint a second at most,
            # and only for a viewer that watches; a capture read at full speed gets the one
            # it attaches with (a file: none, the data goes there from now on) and the last
            watched = self.flush_interval < CAPTURE_FLUSH_S
            if not (final or watched or self.output.attached) and self.output.is_file:
                self.output.attach(None)
            due = final or not self.output.attached or (watched and mono >= self._next_layout)
            if layout != self._sent_layout and due:
                self.output.show(blueprint(layout))
                self._sent_layout = layout
                self._next_layout = mono + LAYOUT_EVERY_S

    def _grown_layout(self, readings: list[tuple[str, int]], final: bool) -> Layout:
        """The layout with what this flush sent: grippers with readings, entities with rows,
        the timeline, the plots' y ranges; at the end of a capture, its span."""
        layout = self.layout.with_paths(self._sent_paths)
        for key in readings:
            layout = layout.with_gripper(*key)
        for key, cycles in self.cycles.grippers.items():  # a gripper whose cycles alone show
            if cycles.lane.path in self._sent_paths:
                layout = layout.with_gripper(*key)
        if not self._timed and self._untimed:  # no timestamps: the frame timeline only
            layout = layout.with_timeline(ent.FRAME)
        for bus in self.buses.values():
            for plot, highest in (
                (RATES_PLOT, bus.health.highest_rate),
                (LOAD_PLOT, bus.health.highest_load),
                (LATENCY_PLOT, bus.highest_latency),
            ):
                if highest:
                    self._highest[plot] = max(self._highest.get(plot, 0.0), highest)
        for origin, highest in self._highest.items():
            layout = layout.with_ceiling(origin, highest)
        if final and not self.live:
            first, last = self._seq_span if layout.timeline == ent.FRAME else self._time_span
            if first <= last:
                if layout.timeline == ent.CAPTURE_TIME:
                    first, last = nanoseconds(np.array([first, last])).tolist()
                layout = layout.with_span(int(first), int(last))
        return layout

    def _columns(self, final: bool) -> list[Columns]:
        """The commands, cycles, error logs and health columns (the finished seconds
        counted)."""
        out = [g.commands for g in self.grippers.values()]
        out += self.cycles.columns()
        seconds: dict[str, list[Any]] = {}
        for row in self.health.take_seconds(final):
            seconds.setdefault(row.bus, []).append(row)
        for name in seconds:
            if name not in self.buses:
                self._bus(name)
        for name, bus in self.buses.items():
            bus.health.add(seconds.get(name, []), bus.first_t, bus.last_t)
            bus.count_seconds(final)
            out += bus.columns()
        if self.session_errors is not None:
            out.append(self.session_errors)
        return out

    def _schedule(self, now: float) -> None:
        """The next flush is due one interval after the one due now (a fixed cadence: a late
        flush does not delay the next), or one interval from now after a missed interval. A
        flush before its time (too many rows waiting) leaves the cadence as it is."""
        if now < self._next_flush:
            return
        due = self._next_flush + self.flush_interval
        self._next_flush = due if due > now else now + self.flush_interval

    def _send_gripper(
        self, g: _Gripper, rows: list[_Rows], mark_t: list[float | None], mark_seq: list[int]
    ) -> bool:
        """A gripper's columns (a shape's share their rows: one record batch), then its fault
        marks. Whether readings or settings were sent."""
        forces: list[tuple[np.ndarray, np.ndarray]] = []  # (seq, force) of the readings sent
        faults: list[tuple[np.ndarray, np.ndarray]] = []  # (t, seq) of fault readings
        force_plot = f"{ent.gripper_path(*g.key)}/{ent.FORCE}"
        for field, t, seq, values in rows:
            if field in ("force", "force_setting") and len(values):  # the plot's y range
                highest = float(np.max(values))
                self._highest[force_plot] = max(self._highest.get(force_plot, 0.0), highest)
            if field == "force":
                forces.append((seq, values))
            elif field == "fault":
                bad = np.fromiter(map(bool, values), bool, len(values))
                if bad.any():
                    faults.append((t[bad], seq[bad]))
            self._send_entity(g.by_field[field], t, seq, values, [])
        self._send_marks(g, mark_t, mark_seq, forces, faults)
        return bool(rows)

    def _send_marks(
        self,
        g: _Gripper,
        mark_t: list[float | None],
        mark_seq: list[int],
        forces: list[tuple[np.ndarray, np.ndarray]],
        faults: list[tuple[np.ndarray, np.ndarray]],
    ) -> None:
        """The red marks: records with errors or fault flags, and fault readings (once per
        record), each at the force last read at or before it (0 before any)."""
        force_seq = force = np.zeros(0)
        if forces:
            force_seq = np.concatenate([f[0] for f in forces])
            order = np.argsort(force_seq, kind="stable")
            force_seq, force = force_seq[order], np.concatenate([f[1] for f in forces])[order]
        if mark_seq or faults:
            t = np.concatenate([np.array(mark_t, dtype=np.float64), *(f[0] for f in faults)])
            seq = np.concatenate([np.array(mark_seq, dtype=np.int64), *(f[1] for f in faults)])
            seq, first = np.unique(seq, return_index=True)  # a faulty record's reading: once
            t = t[first]
            last = np.searchsorted(force_seq, seq, side="right") - 1
            before = 0.0 if g.force is None else float(g.force)
            at = force[last.clip(0)] if len(force) else np.zeros(len(seq))
            self._send_entity(g.marks, t, seq, np.where(last >= 0, at, before), [])
        if len(force):
            g.force = force[-1]

    def _send_entity(
        self, e: Entity, t: np.ndarray, seq: np.ndarray | None, data: Any, levels: list[str]
    ) -> None:
        """Rows of ``e`` as one chunk (two when only some rows have a timestamp)."""
        if e.style is not None:
            self.stream.log(e.path, e.style, static=True, strict=True)
            e.style = None
        if e.kind == SCALAR and e.convert is not None:
            data = e.convert(data)
        elif e.kind == LANE:
            data = _lane_values(data)
        untimed = np.isnan(t)
        if not untimed.any():
            self._send_rows(e, t, seq, data, levels)
            return
        # a capture without timestamps (or a few records without one): frame timeline only
        timed = ~untimed
        data = np.asarray(data, dtype=None if e.kind == SCALAR else object)
        level = np.array(levels, dtype=object)
        if timed.any():
            part = None if seq is None else seq[timed]
            self._send_rows(e, t[timed], part, data[timed], level[timed] if levels else levels)
        if seq is not None:
            self._send_rows(
                e, None, seq[untimed], data[untimed], level[untimed] if levels else levels
            )

    def _send_rows(
        self,
        e: Entity,
        stamps: np.ndarray | None,
        seq: np.ndarray | None,
        data: Any,
        levels: Any,
    ) -> None:
        if stamps is not None:
            self._timed = True
        else:
            self._untimed = True
        self._sent_paths.add(e.path)
        descriptors: tuple[Any, ...]
        if e.kind == SCALAR:
            descriptors, values = SCALARS, [pa.array(data, pa.float64())]
        elif e.kind == LANE:
            descriptors, values = STATE, [pa.array(list(data), pa.utf8())]
        else:
            descriptors = TEXT_LOG
            values = [pa.array(list(data), pa.utf8()), pa.array(list(levels), pa.utf8())]
        self._batches.add(e.path, stamps, seq, descriptors, values)

    # -- parts -----------------------------------------------------------------------------

    def _new_shape(self, bus: str, device: int, fields: tuple[str, ...]) -> _Shape:
        g = self.grippers.get((bus, device)) or self._gripper(bus, device)
        shape = self._shapes[(bus, device, fields)] = _Shape(g, fields)
        g.shapes.append(shape)
        return shape

    def _odd(self, shape: _Shape, t: float | None, seq: int, row: list[Any]) -> None:
        """A sample with a value that is not a number: its fields one by one (None: none)."""
        g = shape.gripper
        for field, value in zip(shape.fields, row, strict=True):
            if value is None:
                continue
            c = g.odd.get(field)
            if c is None:
                e = g.by_field[field]
                c = g.odd[field] = Columns(e.path, e.kind)
            c.add(t, seq, value)

    def _gripper(self, bus: str, device: int) -> _Gripper:
        g = self.grippers[(bus, device)] = _Gripper(bus, device)
        if bus not in self.buses:
            self._bus(bus)
        return g

    def _gripper_of(self, rec: Record) -> _Gripper:
        assert rec.device is not None
        return self.grippers.get((rec.bus, rec.device)) or self._gripper(rec.bus, rec.device)

    def _bus(self, name: str) -> _Bus:
        bus = self.buses[name] = _Bus(name, len(self.buses))
        self.layout = self.layout.with_bus(name)
        return bus


def _lane_values(values: Any) -> list[str]:
    """A lane's values as the viewer's state names: numbers as they are written ("3", not
    "3.0": a shape's columns hold them as floats)."""
    if isinstance(values, np.ndarray):
        whole = values.astype(np.int64)
        if (whole == values).all():
            return list(map(str, whole.tolist()))
        values = values.tolist()
    return list(map(str, values))


def rerun_listener(
    target: str | None,
    source: str | None = None,
    live: bool = True,
    rates: BusRates | None = None,
) -> RerunListener | None:
    """The Rerun listener ``--rerun TARGET`` asks for (``target``: the option's value), or None
    without it. ``source`` names the default .rrd file (None: a dated name); ``live``: a live
    session (False for a capture replayed in the TUI); ``rates``: each bus's rate (None: the
    EG2's)."""
    if target is None:
        return None
    return RerunListener(parse_target(target, source), live=live, rates=rates)
