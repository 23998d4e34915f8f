"""One capture's rows written into the dataset's partitions: one file per table, day and bus,
each under a temporary name until ``commit`` renames them all into place."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc

from ..sinks.parquet import RowGroupWriter
from . import layout
from .tables import BUS, HASH, PATH, days

_KEY_SEPARATOR = "\x00"  # between day and bus in a row's partition key (in neither)


class PartitionFiles:
    """Tables with ``t`` and ``bus`` columns in, split by UTC day and bus, streamed into one
    Parquet file per partition (row groups as they fill: memory stays flat)."""

    def __init__(self, root: Path, content_hash: str, fallback_day: str) -> None:
        self.root = root
        self.hash = content_hash
        self.fallback_day = fallback_day  # for rows without a time (raw dumps have no clock)
        self.writers: dict[tuple[str, str, str], tuple[RowGroupWriter, Path]] = {}
        self.first_day: str | None = None

    @property
    def buses(self) -> list[str]:
        return sorted({bus for table, _, bus in self.writers if table == layout.RECORDS})

    def add(self, table_name: str, schema: pa.Schema, table: pa.Table) -> None:
        if not table.num_rows:
            return
        day = days(table.column("t"), self.fallback_day)
        if self.first_day is None and table_name == layout.RECORDS:
            self.first_day = day[0].as_py()
        bus = table.column(BUS)
        key = pc.binary_join_element_wise(day, bus, _KEY_SEPARATOR)
        rest = table.drop_columns([BUS])
        values = pc.unique(key).to_pylist()
        for value in values:
            part = rest if len(values) == 1 else rest.filter(pc.equal(key, value))
            day_of, bus_of = value.split(_KEY_SEPARATOR)
            self._writer(table_name, schema, day_of, bus_of).add(part.select(schema.names))

    def _writer(self, table_name: str, schema: pa.Schema, day: str, bus: str) -> RowGroupWriter:
        key = (table_name, day, bus)
        held = self.writers.get(key)
        if held is None:
            folder = layout.partition_dir(self.root, table_name, day, bus)
            folder.mkdir(parents=True, exist_ok=True)
            final = layout.data_file(folder, self.hash)
            writer = RowGroupWriter(str(layout.temp_name(final)), schema, (PATH, HASH))
            held = self.writers[key] = (writer, final)
        return held[0]

    def commit(self) -> None:
        """Finish every file and rename it into place."""
        for writer, _ in self.writers.values():
            writer.close()
        for _, final in self.writers.values():
            layout.temp_name(final).replace(final)

    def discard(self) -> None:
        """Drop everything written (an interrupted or failed capture)."""
        for writer, final in self.writers.values():
            writer.abandon()
            layout.temp_name(final).unlink(missing_ok=True)
        self.writers.clear()
