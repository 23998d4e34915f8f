"""The fleet dataset's columns: ``records/`` (decode's Parquet columns, plus where each came
from), ``states/`` (one row per state sample) and ``captures/`` (one row per capture).

``bus`` and ``day`` are the Hive partition keys: they are in the folder names, not in the files,
and readers (pyarrow datasets, DuckDB, polars with ``hive_partitioning``) add them back.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from typing import Any, Final

import pyarrow as pa
import pyarrow.compute as pc

from decoders.registers import fault_text, state_text

from ..model import StateSample
from ..parquet_schema import SCHEMA as RECORD_SCHEMA
from ..parquet_schema import described_field, millimetres
from ..tracker import VALUE_KEYS

BUS: Final = "bus"
DAY: Final = "day"
PATH: Final = "capture_path"
HASH: Final = "capture_hash"
INT: Final = pa.int64()
FLOAT: Final = pa.float64()
STR: Final = pa.string()
STRINGS: Final = pa.list_(STR)

_SOURCE: Final = [
    described_field(PATH, STR, description="the capture file, as given to eg2scope batch"),
    described_field(HASH, STR, description="sha256 of the capture file's bytes"),
]

#: records/: the columns of ``decode --format parquet`` (bus in the folder name) and the source
RECORDS_SCHEMA: Final = pa.schema(
    [f for f in RECORD_SCHEMA if f.name != BUS] + _SOURCE,
    metadata={b"eg2scope": b"fleet records"},
)

#: states/: a ``StateSample.to_dict()`` per row (the MCAP /state topic's fields), bus in the folder
STATES_SCHEMA: Final = pa.schema(
    [
        described_field(
            "t", FLOAT, "s", "the record's capture time (null: the capture has no clock)"
        ),
        described_field("device", INT),
        described_field("protocol", STR),
        described_field("seq", INT, description="the record's seq"),
        described_field("opening", INT, "0-1000", "measured opening"),
        described_field("opening_mm", FLOAT, "mm"),
        described_field("force", INT, description="measured force"),
        described_field("current", INT),
        described_field("temperature_c", INT, "°C"),
        described_field("state", INT),
        described_field("state_text", STR),
        described_field("fault", INT, description="fault bits"),
        described_field("fault_text", STRINGS),
        described_field("target_opening", INT, "0-1000"),
        described_field("target_mm", FLOAT, "mm"),
        described_field("speed", INT),
        described_field("force_setting", INT, "g"),
        described_field("catch_mode", INT),
        described_field("max_opening", INT, "0-1000"),
        described_field("min_opening", INT, "0-1000"),
        described_field("last_command", STR),
        described_field("latency_ms", FLOAT, "ms"),
        described_field("frames", INT),
        described_field("errors", INT),
        described_field("unanswered", INT),
        described_field("changed", STRINGS, description="the fields this record set"),
        *_SOURCE,
    ],
    metadata={b"eg2scope": b"fleet states"},
)
_STATE_KEYS: Final = [f.name for f in STATES_SCHEMA if f.name not in (PATH, HASH)]
_TYPES_SCHEMA: Final = [pa.field(BUS, STR), *(STATES_SCHEMA.field(k) for k in _STATE_KEYS)]
_TYPES: Final = {f.name: f.type for f in _TYPES_SCHEMA}

DEVICE: Final = pa.struct([("bus", STR), ("protocol", STR), ("device", INT)])
LATENCY: Final = ("latency_p50_ms", "latency_p95_ms", "latency_max_ms")
COUNTS: Final = (
    "records",
    "frames",
    "valid_frames",
    "garbage_bytes",
    "truncated",
    "requests",
    "responses",
    "unanswered",
    "retransmissions",
    "errors",
    "warnings",
)

#: captures/: one row per capture, the commit of its rows in records/ and states/
CAPTURES_SCHEMA: Final = pa.schema(
    [
        described_field(PATH, STR, description="the capture file, as given to eg2scope batch"),
        described_field(HASH, STR, description="sha256 of the capture file's bytes"),
        described_field("size", INT, "bytes"),
        described_field(
            "mtime", pa.timestamp("us", "UTC"), description="the file's modification time"
        ),
        described_field(
            "format", STR, description="the capture's suffix: .log, .log.gz, .mcap, .bin..."
        ),
        described_field("protocols", STRINGS),
        described_field("buses", STRINGS),
        described_field("devices", pa.list_(DEVICE)),
        described_field("t_start", FLOAT, "s", "the first record's time (null: no clock)"),
        described_field("t_end", FLOAT, "s", "the last record's time"),
        *(described_field(name, INT) for name in COUNTS),
        *(described_field(name, FLOAT, "ms") for name in LATENCY),
        described_field("flags", pa.map_(STR, INT), description="records per flag code"),
        described_field(
            "damaged", pa.bool_(), description="decoded as far as possible, but damaged"
        ),
        described_field("damage", STRINGS, description="what was found wrong in the file"),
        described_field(
            "engine",
            STR,
            description="eg2scope version that decoded it",
        ),
        described_field("decoded_at", pa.timestamp("ms", "UTC")),
    ],
    metadata={b"eg2scope": b"fleet captures"},
)


def utc_day(t: float) -> str:
    return dt.datetime.fromtimestamp(t, dt.UTC).strftime("%Y-%m-%d")


def days(t: pa.ChunkedArray | pa.Array, fallback: str) -> pa.Array:
    """Each row's UTC day from its time in seconds; ``fallback`` where there is no time."""
    stamps = pc.cast(pc.multiply(t, 1e6), INT)
    text = pc.strftime(pc.cast(stamps, pa.timestamp("us", "UTC")), format="%Y-%m-%d")
    return pc.fill_null(text, fallback)


def states_table(samples: list[StateSample]) -> pa.Table:
    """State samples as rows, the fields of ``StateSample.to_dict()`` (``bus`` kept, for
    partitioning; the source columns not yet). Built column by column: one sample per reading
    makes this the busiest table."""
    values = [s.values for s in samples]
    columns: dict[str, Any] = {
        BUS: [s.bus for s in samples],
        "t": [s.t for s in samples],
        "device": [s.device for s in samples],
        "protocol": [s.protocol for s in samples],
        "seq": [s.seq for s in samples],
        **{key: [v[key] for v in values] for key in VALUE_KEYS},
        "changed": [list(s.changed) for s in samples],
    }
    arrays = {key: pa.array(col, _TYPES[key]) for key, col in columns.items()}
    arrays["opening_mm"] = millimetres(arrays["opening"])
    arrays["target_mm"] = millimetres(arrays["target_opening"])
    arrays["state_text"] = pa.array(_words(columns["state"], state_text), STR)
    arrays["fault_text"] = pa.array(_words(columns["fault"], fault_text, []), STRINGS)
    names = [BUS, *_STATE_KEYS]
    return pa.table([arrays[n] for n in names], schema=pa.schema(_TYPES_SCHEMA))


def _words(codes: list[int | None], words: Callable[[int], Any], unknown: Any = None) -> list[Any]:
    """A state's or fault's words per row (as ``derived`` gives them), each distinct code
    looked up once; ``unknown`` where there is no code."""
    table = {code: words(code) for code in set(codes) if code is not None}
    return [unknown if code is None else table[code] for code in codes]


def with_source(table: pa.Table, path: str, content_hash: str) -> pa.Table:
    rows = table.num_rows
    table = table.append_column(_SOURCE[0], pa.repeat(path, rows).cast(STR))
    return table.append_column(_SOURCE[1], pa.repeat(content_hash, rows).cast(STR))


def captures_table(row: dict[str, Any]) -> pa.Table:
    return pa.Table.from_pylist([row], schema=CAPTURES_SCHEMA)
