"""The session listeners that fill one capture's partitions: its records (the same columns as
``decode --format parquet``, by the same JSONL-to-Arrow path) and its state samples."""

from __future__ import annotations

from collections.abc import Sequence

import pyarrow as pa

from decoders.model import Record

from ..batches import records_jsonl
from ..listener import Listener
from ..model import StateSample
from ..sinks.parquet import ROW_GROUP_ROWS, JsonlTables
from . import layout
from .partitions import PartitionFiles
from .tables import RECORDS_SCHEMA, STATES_SCHEMA, states_table, with_source


class RecordPartitions(JsonlTables, Listener):
    """Records -> JSONL -> the Parquet columns (as ``decode --format parquet`` makes them) ->
    the capture's ``records/`` partitions."""

    def __init__(self, files: PartitionFiles, path: str) -> None:
        JsonlTables.__init__(self)
        self.files = files
        self.path = path
        self.label = "fleet records"

    def on_records(self, records: Sequence[Record]) -> None:
        self.write_jsonl(records_jsonl(records))

    def add(self, table: pa.Table, final: bool = False) -> None:
        table = with_source(table, self.path, self.files.hash)
        self.files.add(layout.RECORDS, RECORDS_SCHEMA, table)

    def close(self) -> None:
        self.flush_text(final=True)


class StatePartitions(Listener):
    """State samples -> the capture's ``states/`` partitions, a row group's worth at a time."""

    wants_states = True

    def __init__(self, files: PartitionFiles, path: str) -> None:
        self.files = files
        self.path = path
        self.held: list[StateSample] = []
        self.label = "fleet states"

    def on_records(self, records: Sequence[Record]) -> None:
        pass  # the samples are what this one keeps

    def on_states(self, samples: Sequence[StateSample]) -> None:
        self.held += samples
        if len(self.held) >= ROW_GROUP_ROWS:
            self._flush()

    def _flush(self) -> None:
        if self.held:
            table = with_source(states_table(self.held), self.path, self.files.hash)
            self.files.add(layout.STATES, STATES_SCHEMA, table)
            self.held = []

    def close(self) -> None:
        self._flush()
