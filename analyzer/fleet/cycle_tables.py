"""The fleet dataset's ``cycles/`` table: every grip cycle of a capture, in the columns of
``eg2scope cycles --format parquet`` (analyzer/cycles/parquet.py: one home for them; ``bus`` in
the folder name) and the capture's source columns; filed by the day of its start.

``FleetCycles`` is the ``CycleOutput`` a capture's ``CyclesListener`` writes to: the cycles as
they end, held until a row group's worth waits or the capture is over.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Final

import pyarrow as pa

from ..cycles.outputs import CycleOutput
from ..cycles.parquet import ROW_GROUP_ROWS, cycles_table
from ..cycles.parquet import SCHEMA as CYCLE_SCHEMA
from . import layout
from .tables import BUS, SOURCE_FIELDS, with_source

if TYPE_CHECKING:
    from ..cycles.model import Cycle
    from .partitions import PartitionFiles

#: cycles/: a cycle's columns (bus in the folder) and the capture's
CYCLES_SCHEMA: Final = pa.schema(
    [f for f in CYCLE_SCHEMA if f.name != BUS] + SOURCE_FIELDS,
    metadata={b"eg2scope": b"fleet cycles"},
)
#: the time a cycle is filed by (its day)
CYCLE_TIME: Final = "start_t"


class FleetCycles(CycleOutput):
    """A capture's cycles into its ``cycles/`` partitions. ``count``: the cycles written."""

    label = "fleet cycles"

    def __init__(self, files: PartitionFiles, path: str) -> None:
        self.files = files
        self.path = path
        self.held: list[Cycle] = []
        self.count = 0

    def write(self, cycles: list[Cycle]) -> None:
        self.held += cycles
        if len(self.held) >= ROW_GROUP_ROWS:
            self._write()

    def close(self) -> None:
        self._write()

    def _write(self) -> None:
        if not self.held:
            return
        cycles, self.held = self.held, []
        self.count += len(cycles)
        table = with_source(cycles_table(cycles), self.path, self.files.hash)
        self.files.add(layout.CYCLES, CYCLES_SCHEMA, table, time=CYCLE_TIME)
