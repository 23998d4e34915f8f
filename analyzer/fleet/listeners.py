"""What fills one capture's partitions: its records (the same columns as ``decode --format
parquet``), its state samples, the counts of its ``captures/`` row; as tables (the native
core's columns) or as a session's listeners (records as JSONL, by the path ``decode --format
parquet`` takes, samples as objects or a native ``SampleBatch``). Its grip cycles and each
bus's health seconds (``BusViews``) come from a ``CyclesListener`` and a ``HealthListener``, in
the session or fed the native run's columns and the capture's frames."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Final

import pyarrow as pa
import pyarrow.compute as pc

from ..cycles.commands import CODES
from ..cycles.listener import CyclesListener
from ..health.listener import HealthListener
from ..health.rates import BusRates
from ..parquet.writer import JsonlTables
from ..session.listener import Listener
from . import layout
from .arrow_sequences import ArrowRecords, ArrowSamples
from .cycle_tables import FleetCycles
from .health_tables import health_table, write_health
from .partitions import PartitionFiles
from .summary import RecordSummary
from .tables import RECORDS_SCHEMA, STATES_SCHEMA, state_rows, states_table, with_source

if TYPE_CHECKING:
    from ..session.batches import RecordSequence, SampleSequence

_CODES: Final = pa.array(sorted(CODES), pa.int64())

#: how far a capture has got: (bytes of the file read, records decoded)
Progress = Callable[[int, int], None]


class CaptureTables(JsonlTables):
    """One capture's tables into its partitions: record tables (as ``decode --format parquet``
    makes them: ``write_jsonl`` or ``write_parsed``) and state samples (``add_states``), and
    the counts of its records (``summary``)."""

    def __init__(self, files: PartitionFiles, path: str) -> None:
        JsonlTables.__init__(self)
        self.files = files
        self.path = path
        self.summary = RecordSummary()

    def add(self, table: pa.Table, final: bool = False) -> None:
        self.summary.add(table)
        self.files.add(layout.RECORDS, RECORDS_SCHEMA, self._sourced(table))

    def add_states(self, samples: SampleSequence | pa.Table) -> None:
        """State samples: objects, a native ``SampleBatch``, or a table of ``STATE_COLUMNS``."""
        rows = state_rows(samples) if isinstance(samples, pa.Table) else states_table(samples)
        self.files.add(layout.STATES, STATES_SCHEMA, self._sourced(rows))

    def _sourced(self, table: pa.Table) -> pa.Table:
        return with_source(table, self.path, self.files.hash)

    def close(self) -> None:
        self.flush_text(final=True)


class BusViews:
    """A capture's grip cycles (``cycles/``) and its buses' health seconds (``health/``): the
    listeners a session carries beside its records (``listeners``), or fed the native run's
    columns (``add_columns``) and the capture's raw frames (``add_raw``), then ended
    (``close_cycles``; a session closes its own). The seconds every bus has completed are
    written as they come (``write_health``: after every batch; ``final``, at the end, the
    rest), so memory holds only the open ones; ``cycles`` and ``seconds``: the rows written."""

    def __init__(self, files: PartitionFiles, path: str, rates: BusRates) -> None:
        self.files = files
        self.path = path
        self.output = FleetCycles(files, path)
        self.cycles_listener = CyclesListener(self.output)
        self.health = HealthListener(rates, seconds=True)
        self.seconds = 0

    @property
    def listeners(self) -> list[Listener]:
        return [self.cycles_listener, self.health, _HealthRows(self)]

    @property
    def cycles(self) -> int:
        return self.output.count

    def add_columns(self, records: pa.Table, samples: pa.Table | None) -> None:
        """One batch of a native run: records in ``PARSE_SCHEMA``, samples in ``STATE_COLUMNS``."""
        # the listener reads a sequence's bulk methods only, which these have (as a native
        # batch has them); of the records it takes only those of a candidate's code: the
        # others are left out here, in one pass over the column
        candidates = records.filter(pc.is_in(records.column("code"), value_set=_CODES))
        batch: Any = ArrowRecords(candidates)
        self.cycles_listener.on_records(batch)
        if samples is not None:
            states: Any = ArrowSamples(samples)
            self.cycles_listener.on_states(states)

    def add_raw(self, items: object) -> None:
        self.health.on_raw(items)
        self.write_health()

    def close_cycles(self) -> None:
        """The end of a native run (a session closes its listeners itself)."""
        self.cycles_listener.close()

    def write_health(self, final: bool = False) -> None:
        seconds = self.health.take_seconds(final)
        if seconds:
            self.seconds += len(seconds)
            write_health(self.files, self.path, health_table(seconds, self.health.rates))


class _HealthRows(Listener):
    """After every batch of a session (its records come after its raw input, and reach this
    listener after the health's), the health seconds its buses completed, written."""

    def __init__(self, views: BusViews) -> None:
        self.views = views
        self.label = "fleet health"

    def on_records(self, records: RecordSequence) -> None:
        self.views.write_health()


class SessionTables(Listener):
    """A session's records and samples into ``CaptureTables``."""

    wants_states = True

    def __init__(self, tables: CaptureTables) -> None:
        self.tables = tables
        self.label = "fleet dataset"

    def on_records(self, records: RecordSequence) -> None:
        self.tables.write_jsonl(records.jsonl())

    def on_states(self, samples: SampleSequence) -> None:
        self.tables.add_states(samples)

    def close(self) -> None:
        self.tables.close()


class Checkpoint(Listener):
    """After every batch of a session: report how far the capture has got (``progress``, at
    most every ``PROGRESS_S``), and stop at an interrupt that was noted (``interrupted``):
    KeyboardInterrupt raised here, between batches, ends the session as Ctrl-C does."""

    def __init__(
        self, position: Callable[[], int], progress: Progress, interrupted: Callable[[], bool]
    ) -> None:
        self.position = position
        self.progress = Throttled(progress)
        self.interrupted = interrupted
        self.records = 0
        self.label = "fleet progress"

    def on_records(self, records: RecordSequence) -> None:
        self.records += len(records)

    def tick(self, now: float) -> None:
        if self.interrupted():
            raise KeyboardInterrupt
        self.progress(self.position(), self.records)


#: seconds between two reports of one capture's progress (a bar redraws ten times a second)
PROGRESS_S = 0.1


class Throttled:
    """``progress`` called at most every ``seconds``."""

    def __init__(self, progress: Progress, seconds: float = PROGRESS_S) -> None:
        self.progress = progress
        self.seconds = seconds
        self.due = 0.0

    def __call__(self, position: int, records: int) -> None:
        now = time.monotonic()
        if now >= self.due:
            self.due = now + self.seconds
            self.progress(position, records)
