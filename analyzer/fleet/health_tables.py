"""The fleet dataset's ``health/`` table: one row per bus and whole second of a capture, the
``HealthListener``'s per-second rows (analyzer/health/seconds.py ``HealthSecond``: one home for
the counting) with the rate each bus was counted at and where that figure came from (its
``rates``), and the capture's source columns; filed by the day of its second.

A capture without times (a raw dump) has no seconds, so no rows.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Final

import pyarrow as pa
import pyarrow.compute as pc

from ..health.bus import CAN
from ..parquet.schema import described_field
from ..sources.candump import RELATIVE_LIMIT
from . import layout
from .tables import BUS, FLOAT, INT, SOURCE_FIELDS, STR, with_source

if TYPE_CHECKING:
    from ..health.rates import BusRates
    from ..health.seconds import HealthSecond
    from .partitions import PartitionFiles

#: health/: a bus's second (bus in the folder) and the capture's
HEALTH_SCHEMA: Final = pa.schema(
    [
        described_field("kind", STR, description="can or serial"),
        described_field("second", INT, "s", "the whole second of capture time, floor(t)"),
        described_field(
            "timestamp",
            pa.timestamp("s", "UTC"),
            description="the second as a time (null: the capture's own clock, before 1991, as "
            "in a capture's day)",
        ),
        described_field("frames", INT, description="frames in this second"),
        described_field("bits", INT, "bits", "their bits on the wire (CAN: stuff bits included)"),
        described_field("load_pct", FLOAT, "%", "bits over the rate (null: untimed or unknown)"),
        described_field(
            "errors", INT, description="CAN error frames, or serial records with errors"
        ),
        described_field(
            "state",
            STR,
            description="the CAN controller's state at the second's end (null on serial)",
        ),
        described_field("worst", STR, description="the worst event of the second, in words"),
        described_field("rate", INT, "bit/s", "the bus's CAN bit rate or serial baud"),
        described_field(
            "rate_from",
            STR,
            description="where the rate came from: --bitrate, --baud, recording or default",
        ),
        *SOURCE_FIELDS,
    ],
    metadata={b"eg2scope": b"fleet health"},
)
_KEYS: Final = ("kind", "second", "frames", "bits", "load_pct", "errors", "state", "worst")
_TIME: Final = "t"  # the second in seconds: what a row's day is told by (not written)


def health_table(seconds: Sequence[HealthSecond], rates: BusRates) -> pa.Table:
    """The rows of ``seconds`` (``bus`` kept, for partitioning, and ``t``, its day)."""
    columns: dict[str, list[object]] = {key: [] for key in (BUS, *_KEYS, "rate", "rate_from")}
    for s in seconds:
        rate = rates.can(s.bus) if s.kind == CAN else rates.serial(s.bus)
        for key, value in ((BUS, s.bus), *((k, getattr(s, k)) for k in _KEYS)):
            columns[key].append(value)
        columns["rate"].append(rate.value)
        columns["rate_from"].append(rate.source)
    types = {BUS: STR} | {f.name: f.type for f in HEALTH_SCHEMA}
    table = pa.table({k: pa.array(v, types[k]) for k, v in columns.items()})
    t = pc.cast(table.column("second"), FLOAT)
    stamps = pc.if_else(
        pc.greater_equal(t, pa.scalar(RELATIVE_LIMIT, FLOAT)),
        pc.cast(table.column("second"), pa.timestamp("s", "UTC")),
        pa.scalar(None, pa.timestamp("s", "UTC")),
    )
    return table.append_column("timestamp", stamps).append_column(_TIME, t)


def write_health(files: PartitionFiles, path: str, rows: pa.Table) -> None:
    """A capture's health rows into its partitions."""
    files.add(layout.HEALTH, HEALTH_SCHEMA, with_source(rows, path, files.hash), time=_TIME)
