"""One capture's rows written into the dataset's partitions: one file per table, day and bus,
each under a temporary name until ``commit`` renames them all into place."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc

from ..parquet.writer import RowGroupWriter
from . import layout
from .tables import BUS, HASH, PATH, STATE_DICTIONARY, days

# between day and bus in a row's partition key (in neither); scalars typed, as pyarrow would
# infer a Python value's type at every call
_KEY_SEPARATOR = pa.scalar("\x00", pa.string())


class PartitionFiles:
    """Tables with a time column (``t``, or the one ``add`` names) and a ``bus`` column in,
    split by UTC day and bus, streamed into one Parquet file per partition (row groups as they
    fill: memory stays flat)."""

    def __init__(self, root: Path, content_hash: str, fallback_day: str) -> None:
        self.root = root
        self.hash = content_hash
        self.fallback_day = fallback_day  # rows without a calendar time: tables.days
        self.writers: dict[tuple[str, str, str], tuple[RowGroupWriter, Path]] = {}
        self.first_day: str | None = None

    @property
    def buses(self) -> list[str]:
        return sorted({bus for table, _, bus in self.writers if table == layout.RECORDS})

    def add(self, table_name: str, schema: pa.Schema, table: pa.Table, time: str = "t") -> None:
        """``table``'s rows into their partitions, each row's day from its ``time`` (seconds)."""
        if not table.num_rows:
            return
        day = days(table.column(time), self.fallback_day)
        if self.first_day is None and table_name == layout.RECORDS:
            self.first_day = day if isinstance(day, str) else day[0].as_py()
        bus = table.column(BUS)
        rest = table.drop_columns([BUS]).select(schema.names)
        first, last = (v.as_py() for v in pc.min_max(bus).values())
        if isinstance(day, str) and first == last:  # the usual table: one partition
            self._writer(table_name, schema, day, first).add(rest)
            return
        if isinstance(day, str):
            day = pa.repeat(pa.scalar(day, pa.string()), table.num_rows)
        key = pc.binary_join_element_wise(day, bus, _KEY_SEPARATOR)
        for value in pc.unique(key).to_pylist():
            part = rest.filter(pc.equal(key, pa.scalar(value, pa.string())))
            day_of, bus_of = value.split(_KEY_SEPARATOR.as_py())
            self._writer(table_name, schema, day_of, bus_of).add(part)

    def _writer(self, table_name: str, schema: pa.Schema, day: str, bus: str) -> RowGroupWriter:
        key = (table_name, day, bus)
        held = self.writers.get(key)
        if held is None:
            folder = layout.partition_dir(self.root, table_name, day, bus)
            folder.mkdir(parents=True, exist_ok=True)
            final = layout.data_file(folder, self.hash)
            encoded = (PATH, HASH, *(STATE_DICTIONARY if table_name == layout.STATES else ()))
            writer = RowGroupWriter(str(layout.temp_name(final)), schema, encoded)
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
