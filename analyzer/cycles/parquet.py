"""Cycles as a Parquet file of typed columns (docs/contracts.md, "Grip cycles"): the JSONL keys
with their units in each column's metadata, row groups written as cycles end."""

from __future__ import annotations

from typing import IO, Any, Final

import pyarrow as pa
import pyarrow.parquet as pq

from .model import KEYS, Cycle
from .outputs import CycleOutput

ROW_GROUP_ROWS: Final = 65_536
_TEXT: Final = pa.string()
_INT: Final = pa.int64()
_FLOAT: Final = pa.float64()
# key -> (type, unit)
_COLUMNS: Final[dict[str, tuple[pa.DataType, str]]] = {
    "bus": (_TEXT, ""),
    "device": (_INT, ""),
    "start_t": (_FLOAT, "s"),
    "end_t": (_FLOAT, "s"),
    "start_seq": (_INT, ""),
    "end_seq": (_INT, ""),
    "command": (_TEXT, ""),
    "target_mm": (_FLOAT, "mm"),
    "outcome": (_TEXT, ""),
    "width_mm": (_FLOAT, "mm"),
    "force_peak": (_INT, ""),
    "time_to_contact_ms": (_FLOAT, "ms"),
    "settle_ms": (_FLOAT, "ms"),
    "retries": (_INT, ""),
    "faults": (pa.list_(_TEXT), ""),
    "warnings": (pa.list_(_TEXT), ""),
    "unknown": (pa.list_(_TEXT), ""),
    "evidence": (pa.list_(_INT), ""),
}
assert tuple(_COLUMNS) == KEYS, "one column per key of the cycles contract, in its order"

SCHEMA: Final = pa.schema(
    [
        pa.field(key, type_, metadata={"unit": unit} if unit else None)
        for key, (type_, unit) in _COLUMNS.items()
    ],
    metadata={"eg2scope": "cycles"},
)


class ParquetCycles(CycleOutput):
    """Cycles into a Parquet file on a binary stream, ``ROW_GROUP_ROWS`` at a time."""

    def __init__(self, out: IO[bytes]) -> None:
        self.label = f"Parquet cycles output to {getattr(out, 'name', 'a stream')}"
        self.writer = pq.ParquetWriter(out, SCHEMA, compression="zstd")
        self.rows: list[Cycle] = []

    def write(self, cycles: list[Cycle]) -> None:
        self.rows += cycles
        if len(self.rows) >= ROW_GROUP_ROWS:
            self._group()

    def close(self) -> None:
        self._group()
        self.writer.close()

    def _group(self) -> None:
        if not self.rows:
            return
        rows, self.rows = self.rows, []
        self.writer.write_table(cycles_table(rows))


def cycles_table(cycles: list[Cycle]) -> pa.Table:
    """Cycles as rows of ``SCHEMA`` (``eg2scope cycles --format parquet``'s row groups, and a
    ``batch`` dataset's ``cycles/`` table)."""
    columns: dict[str, list[Any]] = {key: [] for key in KEYS}
    for cycle in cycles:
        for key, value in cycle.to_dict().items():
            columns[key].append(value)
    return pa.table(columns, schema=SCHEMA)
