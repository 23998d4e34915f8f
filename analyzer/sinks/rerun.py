"""The Rerun listener: every state sample of a session plotted on two timelines, with the
commands, errors, fault marks and bus health around them (the entity contract: docs/rerun.md,
its names: ``analyzer/rerun_entities.py``).

Values are buffered as typed columns per entity and sent in batches (``rerun_batch.py``: one
Arrow record batch for the entities that share their rows, one chunk per entity; never one
``log`` call per value): every ``flush_interval`` seconds (a live viewer is updated ten times a
second), whenever ``max_rows`` records and samples are waiting, and at the end. Nothing is
downsampled. Each row carries ``capture_time`` (the record's ``t``) and ``frame``
(its ``seq``); a capture without timestamps (a raw serial dump) has ``frame`` only. The default
blueprint is sent again whenever a gripper or bus appears.
"""

from __future__ import annotations

import time
from array import array
from typing import Any, Final

import numpy as np
import pyarrow as pa

from decoders.eg2_can import OP_READ
from decoders.eg2_serial import Cmd
from decoders.flags import DEVICE_FAULT, ESTIMATED_TIME, FOREIGN, UNANSWERED
from decoders.modbus_pdu import READ_HOLDING
from decoders.model import EG2_CAN, EG2_SERIAL, FRAME, MODBUS_RTU, REQUEST, Record

from .. import rerun_entities as ent
from ..listener import Listener
from ..model import LEVEL_NAMES, WARNING, SourceEvent, StateSample
from ..rerun_blueprint import Layout, blueprint
from ..rerun_target import RerunOutput, RerunTarget, parse_target
from .rerun_batch import SCALARS, STATE, TEXT_LOG, Batches

NAN: Final = float("nan")  # no timestamp
# a live viewer is updated at least ten times a second: flushes are due on a fixed 80 ms grid
# (12.5 a second) because they happen at the session's ticks, a step late at worst
LIVE_FLUSH_S: Final = 0.08
CAPTURE_FLUSH_S: Final = 2.0  # a capture read at full speed: few, large chunks
LAYOUT_EVERY_S: Final = 1.0  # the blueprint is sent again at most this often
MAX_ROWS: Final = 250_000  # records and samples waiting before a flush, whatever the time

RATES: Final = ("frames_per_s", "errors_per_s", "unanswered_per_s")
SCALAR: Final = "scalar"
LANE: Final = "lane"
TEXT: Final = "text"

# requests that only read (polls), by (protocol, code): the readings are plotted, the polls
# are not listed as commands
_POLLS: Final = frozenset(
    {(EG2_SERIAL, c.value) for c in Cmd if c.name.startswith("READ_")}
    | {(MODBUS_RTU, READ_HOLDING), (EG2_CAN, OP_READ)}
)
# flags that say nothing is wrong: not logged as problems
_QUIET_FLAGS: Final = frozenset({FOREIGN, ESTIMATED_TIME})
_LEVELS: Final = {"debug": "DEBUG", "info": "INFO", "warning": "WARN", "error": "ERROR"}


class _Columns:
    """The rows of one entity waiting to be sent, as typed arrays (no conversion when sent):
    ``t`` in seconds (NaN: no timestamp), ``seq`` (None for entities that live on
    ``capture_time`` only: health rates, source events), ``values`` (numbers for scalars,
    a list for lanes and text)."""

    __slots__ = ("convert", "kind", "levels", "path", "seq", "style", "t", "values")

    def __init__(
        self,
        path: str,
        kind: str,
        style: Any = None,
        *,
        frame: bool = True,
        convert: Any = None,
    ) -> None:
        self.path = path
        self.kind = kind
        self.style = style  # static style, logged with the first rows (then None)
        self.convert = convert  # value -> what is plotted (None: as it is)
        self.t = array("d")
        self.seq: array[int] | None = array("q") if frame else None
        self.values: Any = array("d") if kind == SCALAR else []
        self.levels: list[str] = []

    def add(self, t: float | None, seq: int | None, value: Any, level: str = "") -> None:
        self.t.append(NAN if t is None else t)
        if self.seq is not None:
            self.seq.append(-1 if seq is None else seq)
        self.values.append(value)
        if self.kind == TEXT:
            self.levels.append(level)

    def appenders(self) -> tuple[Any, Any, Any]:
        """The append methods of t, seq and values, for the hot loop (the buffers are
        emptied in place, so these stay valid)."""
        assert self.seq is not None
        return self.t.append, self.seq.append, self.values.append

    def take(self) -> tuple[np.ndarray, np.ndarray | None, Any, list[str]]:
        """The rows so far (t, seq, values, levels), copied; the columns start empty."""
        t = np.frombuffer(self.t, dtype=np.float64).copy()
        seq = None if self.seq is None else np.frombuffer(self.seq, dtype=np.int64).copy()
        values: Any = self.values[:]
        if self.kind == SCALAR:
            values = np.frombuffer(self.values, dtype=np.float64).copy()
        rows = (t, seq, values, self.levels[:])
        for buffer in (self.t, self.seq, self.values, self.levels):
            if buffer is not None:
                del buffer[:]
        return rows


class _Gripper:
    """One gripper's columns: state field -> columns, plus commands and fault marks."""

    __slots__ = ("appenders", "by_field", "commands", "force", "key", "marks")

    def __init__(self, bus: str, device: int) -> None:
        base = ent.gripper_path(bus, device)
        self.key = (bus, device)
        self.by_field: dict[str, _Columns] = {
            s.field: _Columns(
                f"{base}/{s.entity}",
                SCALAR,
                ent.series_style(s),
                convert=s.convert,
            )
            for s in ent.SERIES
        }
        self.by_field["state"] = _Columns(f"{base}/{ent.STATE}", LANE, ent.state_configuration())
        self.by_field["fault"] = _Columns(f"{base}/{ent.FAULT}", LANE, ent.fault_configuration())
        self.appenders = {field: c.appenders() for field, c in self.by_field.items()}
        self.commands = _Columns(f"{base}/{ent.COMMANDS}", TEXT)
        self.marks = _Columns(f"{base}/{ent.FAULT_MARKS}", SCALAR, ent.fault_marks_style())
        self.force: Any = None  # the force last read: where a fault mark sits

    def readings(self) -> bool:
        """Whether readings or settings wait to be sent (the gripper gets a column)."""
        return any(c.values for c in self.by_field.values())

    def columns(self) -> list[_Columns]:
        return [*self.by_field.values(), self.commands, self.marks]


class _Bus:
    """One bus's error log and health: frames, errors and unanswered requests per second of
    capture time (a point at the end of each second; a silent stretch drops to zero), and every
    latency. Record times are gathered as they come and counted per second when sent."""

    __slots__ = ("errors", "health", "latency", "nonframes", "problems", "times", "unanswered")

    def __init__(self, bus: str) -> None:
        base = ent.bus_path(bus)
        self.errors = _Columns(f"{base}/{ent.ERRORS}", TEXT)
        health = f"{base}/{ent.HEALTH}"
        self.latency = _Columns(f"{health}/latency_ms", SCALAR, ent.health_style("latency_ms"))
        self.health = {
            name: _Columns(f"{health}/{name}", SCALAR, ent.health_style(name), frame=False)
            for name in RATES
        }
        self.times = array("d")  # every record's t
        self.nonframes = array("d")  # ... of garbage and truncated records
        self.problems = array("d")  # ... of records with errors
        self.unanswered = array("d")  # ... of unanswered requests

    def count_seconds(self, final: bool) -> None:
        """Count the finished seconds into the health columns; the second still being
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
        frames = np.bincount(np.searchsorted(secs, seconds[done]), minlength=len(secs))
        counts = {
            "frames_per_s": frames - self._per_second("nonframes", secs, last, final),
            "errors_per_s": self._per_second("problems", secs, last, final),
            "unanswered_per_s": self._per_second("unanswered", secs, last, final),
        }
        ends, zeros = secs + 1, _silent(secs)
        for name, values in counts.items():
            t = np.concatenate([ends, zeros])
            order = np.argsort(t, kind="stable")
            column = self.health[name]
            column.t.extend(t[order].tolist())
            column.values.extend(np.concatenate([values, np.zeros(len(zeros))])[order].tolist())

    def _per_second(self, name: str, secs: np.ndarray, last: float, final: bool) -> np.ndarray:
        """How many of the times in list ``name`` fall in each of ``secs``; times in the second
        still being captured stay in the list."""
        seconds = np.floor(np.frombuffer(getattr(self, name), dtype=np.float64))
        done = seconds < last if not final else np.ones(len(seconds), bool)
        setattr(self, name, array("d", seconds[~done].tobytes()))

        idx = np.searchsorted(secs, seconds[done])
        return np.bincount(idx[idx < len(secs)], minlength=len(secs))

    def columns(self) -> list[_Columns]:
        return [self.errors, self.latency, *self.health.values()]


def _silent(secs: np.ndarray) -> np.ndarray:
    """Zero points for the seconds without records between ``secs``: at the end of the first
    and of the last silent second of each gap."""
    gap = np.nonzero(secs[1:] > secs[:-1] + 1)[0]
    first = secs[gap] + 2
    last = secs[gap + 1]
    return np.unique(np.concatenate([first, last[last > first]]))


class RerunListener(Listener):
    """Plots a session in Rerun. ``where``: an open ``RerunOutput``, a ``RerunTarget``, or a
    ``--rerun`` target string (``run.rrd``, ``spawn``, ``web``, a viewer URL). ``live``: a live
    session (plots follow a sliding 10 s window; source events go to the error logs)."""

    wants_states = True
    label = "rerun"

    def __init__(
        self,
        where: RerunOutput | RerunTarget | str,
        *,
        live: bool = False,
        flush_interval: float | None = None,
        max_rows: int = MAX_ROWS,
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
        self.session_errors: _Columns | None = None
        self._timed = self._untimed = False  # rows with and without capture_time were sent
        self._sent_layout: Layout | None = self.layout if live else None
        self._pending = 0
        self._next_flush = time.monotonic() + self.flush_interval  # when a flush is due
        self._marked: set[tuple[str, int]] = set()  # (bus, seq) marked in this batch
        self._batches = Batches()
        self._next_layout = 0.0  # when the blueprint may be sent again
        self._closed = False

    # -- what the session gives ------------------------------------------------------------

    def on_states(self, samples: list[StateSample]) -> None:
        grippers = self.grippers
        for s in samples:
            g = grippers.get((s.bus, s.device)) or self._gripper(s.bus, s.device)
            t, seq, appenders = NAN if s.t is None else s.t, s.seq, g.appenders
            for field, value in s.changed.items():
                add = appenders.get(field)
                if add is not None and value is not None:
                    add[0](t)
                    add[1](seq)
                    add[2](value)
            if s.changed.get("fault") and (s.bus, seq) not in self._marked:  # a fault reading
                self._mark(g, t, seq)
        self._pending += len(samples)

    def on_records(self, records: list[Record]) -> None:
        self._marked.clear()  # the seqs marked in this batch (its samples come next)
        buses = self.buses
        name: str | None = None
        bus: _Bus | None = None
        for rec in records:
            if rec.bus != name:
                name = rec.bus
                bus = buses.get(name) or self._bus(name)
            assert bus is not None
            t = rec.t
            if t is not None:
                bus.times.append(t)
            if rec.errors or rec.warnings:
                self._problem(bus, rec)
            elif rec.direction == REQUEST and (rec.protocol, rec.code) not in _POLLS:
                self._command(rec, "INFO")
            if rec.latency_ms is not None and t is not None:
                latency = bus.latency
                latency.t.append(t)  # a latency needs both times: never NaN
                latency.seq.append(rec.seq)  # type: ignore[union-attr]
                latency.values.append(rec.latency_ms)
        self._pending += len(records)

    def _problem(self, bus: _Bus, rec: Record) -> None:
        """A record with errors or warnings: the error log, a fault mark, the health counts."""
        t = rec.t
        quiet = bool(rec.flags) and _QUIET_FLAGS.issuperset(rec.flags)  # nothing wrong
        if rec.errors:
            bus.errors.add(t, rec.seq, _problem_text(rec), "ERROR")
        elif not quiet:
            bus.errors.add(t, rec.seq, _problem_text(rec), "WARN")
        if t is not None:
            if rec.kind != FRAME:
                bus.nonframes.append(t)
            if rec.errors:
                bus.problems.append(t)
            if UNANSWERED in rec.flags:
                bus.unanswered.append(t)
        if rec.device is not None and (rec.errors or DEVICE_FAULT in rec.flags):
            self._mark(self._gripper_of(rec), t, rec.seq)
        elif rec.direction == REQUEST and (rec.protocol, rec.code) not in _POLLS:
            self._command(rec, "INFO" if quiet else "WARN")

    def _command(self, rec: Record, level: str) -> None:
        """A command of the controller (not a poll), in words, in its gripper's log."""
        if rec.device is not None and rec.kind == FRAME:
            self._gripper_of(rec).commands.add(rec.t, rec.seq, rec.summary or rec.name, level)

    def on_event(self, event: SourceEvent) -> None:
        """Warnings and errors of a live source (a port lost, drops) in the bus's error log.
        A capture's events carry the wall clock, not the capture's: they are not plotted."""
        if not self.live or event.level < WARNING:
            return
        bus = self.buses.get(event.bus)
        if bus is not None:
            columns = bus.errors
        else:
            if self.session_errors is None:
                path = f"/{ent.SESSION}/{ent.ERRORS}"
                self.session_errors = _Columns(path, TEXT, frame=False)
                self.layout = self.layout.with_session_log()
            columns = self.session_errors
        level = _LEVELS.get(LEVEL_NAMES.get(event.level, "info"), "INFO")
        columns.add(event.t, None, event.message, level)

    def tick(self, now: float) -> None:
        if self._pending >= self.max_rows or (
            self._pending and time.monotonic() >= self._next_flush
        ):
            self.flush()

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self.flush(final=True)
        self.output.finish(blueprint(self.layout))

    def on_error(self, exc: BaseException) -> None:
        self._closed = True
        try:
            self.output.finish(blueprint(self.layout))
        except Exception:
            pass  # already detached; the session reports the first error

    # -- sending ---------------------------------------------------------------------------

    def flush(self, final: bool = False) -> None:
        """Send every buffered column, then the layout if a gripper or bus appeared."""
        self._schedule(time.monotonic())
        for g in self.grippers.values():
            forces = g.by_field["force"].values
            if forces:
                g.force = forces[-1]
            if g.readings():
                self.layout = self.layout.with_gripper(*g.key)
            for columns in g.columns():
                self._send(columns)
        for bus in self.buses.values():
            bus.count_seconds(final)
            for columns in bus.columns():
                self._send(columns)
        if self.session_errors is not None:
            self._send(self.session_errors)
        self._batches.send(self.stream)
        self._pending = 0
        if not self._timed and self._untimed:  # a capture without timestamps: frames only
            self.layout = self.layout.with_timeline(ent.FRAME)
        mono = time.monotonic()
        if self.layout != self._sent_layout and (final or mono >= self._next_layout):
            # grippers appear in bursts when a session starts: one blueprint per second at most
            self.output.show(blueprint(self.layout))
            self._sent_layout = self.layout
            self._next_layout = mono + LAYOUT_EVERY_S

    def _schedule(self, now: float) -> None:
        """The next flush is due one interval after the one due now (a fixed cadence: a late
        tick does not delay the next), or one interval from now after a missed interval. A
        flush before its time (too many rows waiting) leaves the cadence as it is."""
        if now < self._next_flush:
            return
        due = self._next_flush + self.flush_interval
        self._next_flush = due if due > now else now + self.flush_interval

    def _send(self, c: _Columns) -> None:
        """The rows of ``c`` as one chunk (two when only some rows have a timestamp)."""
        if not c.values:
            return
        if c.style is not None:
            self.stream.log(c.path, c.style, static=True, strict=True)
            c.style = None
        t, seq, data, levels = c.take()
        if c.kind == SCALAR and c.convert is not None:
            data = c.convert(data)
        elif c.kind == LANE:
            data = list(map(str, data))
        untimed = np.isnan(t)
        if not untimed.any():
            self._send_rows(c, t, seq, data, levels)
            return
        # a capture without timestamps (or a few records without one): frame timeline only
        timed = ~untimed
        data = np.asarray(data, dtype=None if c.kind == SCALAR else object)
        level = np.array(levels, dtype=object)
        if timed.any():
            part = None if seq is None else seq[timed]
            self._send_rows(c, t[timed], part, data[timed], level[timed] if levels else levels)
        if seq is not None:
            self._send_rows(
                c, None, seq[untimed], data[untimed], level[untimed] if levels else levels
            )

    def _send_rows(
        self,
        c: _Columns,
        stamps: np.ndarray | None,
        seq: np.ndarray | None,
        data: Any,
        levels: Any,
    ) -> None:
        if stamps is not None:
            self._timed = True
        else:
            self._untimed = True
        descriptors: tuple[Any, ...]
        if c.kind == SCALAR:
            descriptors, values = SCALARS, [pa.array(data, pa.float64())]
        elif c.kind == LANE:
            descriptors, values = STATE, [pa.array(list(data), pa.utf8())]
        else:
            descriptors = TEXT_LOG
            values = [pa.array(list(data), pa.utf8()), pa.array(list(levels), pa.utf8())]
        self._batches.add(c.path, stamps, seq, descriptors, values)

    # -- parts -----------------------------------------------------------------------------

    def _gripper(self, bus: str, device: int) -> _Gripper:
        g = self.grippers[(bus, device)] = _Gripper(bus, device)
        if bus not in self.buses:
            self._bus(bus)
        return g

    def _gripper_of(self, rec: Record) -> _Gripper:
        assert rec.device is not None
        return self.grippers.get((rec.bus, rec.device)) or self._gripper(rec.bus, rec.device)

    def _bus(self, name: str) -> _Bus:
        bus = self.buses[name] = _Bus(name)
        self.layout = self.layout.with_bus(name)
        return bus

    def _mark(self, g: _Gripper, t: float | None, seq: int) -> None:
        """A red mark on the force plot, at the force last read (0 before any)."""
        forces = g.by_field["force"].values
        force = forces[-1] if forces else g.force
        g.marks.add(t, seq, 0 if force is None else force)
        self._marked.add((g.key[0], seq))


def _problem_text(rec: Record) -> str:
    who = f"ID {rec.device} " if rec.device is not None else ""
    what = rec.summary or rec.name or rec.kind
    return f"{who}{what}: {'; '.join([*rec.errors, *rec.warnings])}"
