"""The fleet dataset's columns: ``records/`` (decode's Parquet columns, plus where each came
from), ``states/`` (one row per state sample) and ``captures/`` (one row per capture).

``bus`` and ``day`` are the Hive partition keys: they are in the folder names, not in the files,
and readers (pyarrow datasets, DuckDB, polars with ``hive_partitioning``) add them back.
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Callable
from typing import Any, Final

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from decoders.registers import fault_text, state_text

from ..parquet import native as native_parquet
from ..parquet.schema import SCHEMA as RECORD_SCHEMA
from ..parquet.schema import described_field, millimetres
from ..session.batches import SampleSequence
from ..sources.candump import RELATIVE_LIMIT

BUS: Final = "bus"
PATH: Final = "capture_path"
HASH: Final = "capture_hash"
INT: Final = pa.int64()
FLOAT: Final = pa.float64()
STR: Final = pa.string()
STRINGS: Final = pa.list_(STR)

#: the columns that say which capture a row came from, last in every bus table
SOURCE_FIELDS: Final = [
    described_field(PATH, STR, description="the capture file, as given to eg2scope batch"),
    described_field(HASH, STR, description="sha256 of the capture file's bytes"),
]

#: records/: the columns of ``decode --format parquet`` (bus in the folder name) and the source
RECORDS_SCHEMA: Final = pa.schema(
    [f for f in RECORD_SCHEMA if f.name != BUS] + SOURCE_FIELDS,
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
        *SOURCE_FIELDS,
    ],
    metadata={b"eg2scope": b"fleet states"},
)
_STATE_KEYS: Final = [f.name for f in STATES_SCHEMA if f.name not in (PATH, HASH)]
#: the states/ columns written dictionary-encoded: a gripper's values repeat from sample to
#: sample (half the size, and faster to write); times, seqs, latencies and counters do not
STATE_DICTIONARY: Final = tuple(
    k for k in _STATE_KEYS if k not in ("t", "seq", "latency_ms", "frames", "errors", "unanswered")
)
_TYPES_SCHEMA: Final = pa.schema(
    [pa.field(BUS, STR), *(STATES_SCHEMA.field(k) for k in _STATE_KEYS)]
)
#: what a state sample holds (its bus kept, for partitioning), the columns the native core
#: fills (analyzer/parquet/native.py describes them to it); the words and millimetres are
#: derived from them (``_derived``)
_DERIVED: Final = ("opening_mm", "target_mm", "state_text", "fault_text")
STATE_COLUMNS: Final = pa.schema([f for f in _TYPES_SCHEMA if f.name not in _DERIVED])

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
        described_field(
            "decode_options",
            STR,
            description="the options it was decoded with that change its records "
            "('--protocol auto', '--protocol modbus'); with capture_hash, its key",
        ),
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


# the times a day can be told of: from 1991-01-01 (an earlier time is a capture's own clock,
# relative to its start, as candump's reader tells -tz/-td stamps from Unix time) to
# 9999-12-31 UTC. Scalars for compute functions are made once, typed: pyarrow infers the type
# of a Python value anew at every call (and tries to import dateutil each time)
_FIRST_S: Final = pa.scalar(RELATIVE_LIMIT, FLOAT)
_END_S: Final = pa.scalar(253_402_300_800.0, FLOAT)
_MICRO: Final = pa.scalar(1e6, FLOAT)
_NO_TIME: Final = pa.scalar(None, FLOAT)


def days(t: pa.ChunkedArray | pa.Array, fallback: str) -> str | pa.Array | pa.ChunkedArray:
    """Each row's UTC day from its time in seconds (rounded to the microsecond, as
    ``datetime.fromtimestamp`` does); ``fallback`` where there is no calendar time: none
    (raw dumps), one relative to the capture's start (before 1991), or one no calendar holds
    (NaN, infinite, beyond year 9999). One string when every row has the same day (the usual
    batch: its first and last times fall on one day)."""
    if t.null_count == len(t):
        return fallback
    if not t.null_count and math.isfinite(pc.sum(t).as_py()):  # no NaN nor infinity
        first, last = pc.min_max(t).values()
        if first.as_py() < _FIRST_S.as_py() and last.as_py() < _FIRST_S.as_py():
            return fallback  # the capture's own clock throughout
        if first.as_py() >= _FIRST_S.as_py() and last.as_py() < _END_S.as_py():
            ends = _days(pa.array([first.as_py(), last.as_py()], FLOAT), fallback).to_pylist()
            if ends[0] == ends[1]:
                return str(ends[0])
    return _days(t, fallback)


def _days(t: pa.ChunkedArray | pa.Array, fallback: str) -> pa.Array | pa.ChunkedArray:
    inside = pc.and_(pc.greater_equal(t, _FIRST_S), pc.less(t, _END_S))
    micros = pc.round(
        pc.multiply(pc.if_else(inside, t, _NO_TIME), _MICRO), round_mode="half_to_even"
    )
    stamps = pc.cast(pc.cast(micros, INT), pa.timestamp("us", "UTC"))
    text = pc.cast(pc.cast(stamps, pa.date32()), STR)  # ISO 8601: YYYY-MM-DD
    return pc.fill_null(text, fallback)


def states_table(samples: SampleSequence) -> pa.Table:
    """State samples as rows, the fields of ``StateSample.to_dict()`` (``bus`` kept, for
    partitioning; the source columns not yet), from the Arrow columns the samples build
    (``samples.arrow``: a native ``SampleBatch`` makes no object per sample)."""
    _rows, parts = samples.arrow(native_parquet.columns(STATE_COLUMNS))
    return state_rows(native_parquet.batch_table(parts, STATE_COLUMNS))


def state_rows(samples: pa.Table) -> pa.Table:
    """The ``states/`` rows (bus kept) of samples in ``STATE_COLUMNS``: with the openings in
    millimetres and the state's and faults' words, as ``StateSample.to_dict()`` derives them."""
    derived = {
        "opening_mm": millimetres(samples.column("opening")),
        "target_mm": millimetres(samples.column("target_opening")),
        "state_text": _words(samples.column("state"), state_text, STR),
        "fault_text": _words(samples.column("fault"), fault_text, STRINGS, unknown=[]),
    }
    columns = [derived[f.name] if f.name in derived else samples[f.name] for f in _TYPES_SCHEMA]
    return pa.table(columns, schema=_TYPES_SCHEMA)


def _words(
    codes: pa.ChunkedArray,
    words: Callable[[int], Any],
    type_: pa.DataType,
    unknown: Any = None,
) -> pa.ChunkedArray:
    """A state's or fault's words per row (as ``derived`` gives them), each distinct code
    looked up once; ``unknown`` where there is no code."""
    distinct = pc.unique(codes).drop_null()
    table = pa.array([words(code) for code in distinct.to_pylist()], type_)
    found = pc.take(table, pc.index_in(codes, value_set=distinct))
    if unknown is None:
        return found
    return pc.if_else(pc.is_null(codes), pa.scalar(unknown, type_), found)


def with_source(table: pa.Table, path: str, content_hash: str) -> pa.Table:
    rows = table.num_rows
    table = table.append_column(SOURCE_FIELDS[0], _repeated(path, rows))
    return table.append_column(SOURCE_FIELDS[1], _repeated(content_hash, rows))


_REPEATED: dict[str, pa.Array] = {}


def _repeated(text: str, rows: int) -> pa.Array:
    """``text`` on every row: a slice of one array per text (a capture's path and hash), made
    from its bytes (converting Python objects looks for optional libraries every time)."""
    array = _REPEATED.get(text)
    if array is None or len(array) < rows:
        if len(_REPEATED) > 4:
            _REPEATED.clear()  # the captures before
        size = max(rows, 1 << 16)
        data = text.encode()
        offsets = np.arange(0, (size + 1) * len(data), len(data), dtype=np.int32)
        buffers = [None, pa.py_buffer(offsets), pa.py_buffer(data * size)]
        array = _REPEATED[text] = pa.Array.from_buffers(STR, size, buffers)
    return array.slice(0, rows)


def captures_table(row: dict[str, Any]) -> pa.Table:
    return pa.Table.from_pylist([row], schema=CAPTURES_SCHEMA)
