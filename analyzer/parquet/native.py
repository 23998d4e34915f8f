"""``eg2scope decode --format parquet`` on the native core: the core builds the Arrow columns of
its records itself (native/src/parquet/records.rs, ``PARSE_SCHEMA``'s layout, no JSON); they go to
``ParquetRecordWriter.write_parsed`` (analyzer/parquet/writer.py), the Python engine's own
flattening and writing: the same Parquet from both engines (tests/native/test_native_parquet.py).

The columns are described to the core from ``PARSE_SCHEMA`` at the start of a run (one home for
them: analyzer/parquet/schema.py); the core mirrors ``_line_by_line``/``_split_fields`` of
the Python path for each record, ``other_fields`` included. Batches are Parquet row groups.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import IO, Any, Final

import pyarrow as pa

from ..interrupts import noted_interrupts
from .schema import FAMILY, OTHER_FIELDS, PARSE_SCHEMA, VALUES_KEY, parse_key
from .writer import ROW_GROUP_ROWS, ParquetRecordWriter

# the Arrow types the core builds, by the names it knows them
_TYPES: Final = {
    pa.int64(): "int64",
    pa.float64(): "float64",
    pa.string(): "string",
    pa.bool_(): "bool",
}


def _describe(name: str, type_: pa.DataType, out: list[tuple[str, str, int]]) -> None:
    """A column and its children, depth first, as the core takes them."""
    if pa.types.is_struct(type_):
        out.append((name, "struct", type_.num_fields))
        for child in type_:
            _describe(child.name, child.type, out)
    elif pa.types.is_list(type_):
        out.append((name, "list", 1))
        _describe("item", type_.value_type, out)
    else:
        out.append((name, _TYPES[type_], 0))


def columns(schema: pa.Schema = PARSE_SCHEMA) -> list[tuple[str, str, int]]:
    """A schema described for the core (``PARSE_SCHEMA``'s records by default; the fleet's
    state columns, analyzer/fleet/tables.py)."""
    out: list[tuple[str, str, int]] = []
    for f in schema:
        _describe(f.name, f.type, out)
    return out


def families() -> list[tuple[str, str]]:
    """protocol -> the column its ``fields`` go to."""
    return [(protocol, parse_key(family)) for protocol, family in FAMILY.items()]


def open_run(native: Any, path: str, states: pa.Schema | None = None, **options: Any) -> Any:
    """The core's ``ArrowRun`` over a capture (the options of ``DecodeRun`` that apply);
    ``states``: also the state samples of its records, in these columns (the fleet dataset)."""
    return native.ArrowRun(
        path,
        columns(),
        families(),
        OTHER_FIELDS,
        VALUES_KEY,
        states=None if states is None else columns(states),
        **options,
    )


def _skip(type_: pa.DataType, parts: Iterator[Any]) -> None:
    """Pass over the children of an all-null column (the core hands them out too)."""
    for child in _children(type_):
        next(parts)
        _skip(child, parts)


def _children(type_: pa.DataType) -> list[pa.DataType]:
    if pa.types.is_struct(type_):
        return [c.type for c in type_]
    if pa.types.is_list(type_):
        return [type_.value_type]
    return []


_NULLS: dict[pa.DataType, pa.Array] = {}


def _nulls(rows: int, type_: pa.DataType) -> pa.Array:
    """A column of nulls: a slice of one array per type (most columns are empty)."""
    array = _NULLS.get(type_)
    if array is None or len(array) < rows:
        array = _NULLS[type_] = pa.nulls(max(rows, ROW_GROUP_ROWS), type_)
    return array.slice(0, rows)


def _array(type_: pa.DataType, parts: Iterator[Any]) -> pa.Array:
    """The next array of a batch (its children after it), from the core's buffers: an int
    (the length) for a column of nulls, else Arrow's buffers."""
    part = next(parts)
    if type(part) is int:
        _skip(type_, parts)
        return _nulls(part, type_)
    children = [_array(c, parts) for c in _children(type_)] or None
    length, nulls, validity, values, data = part
    buffers = [None if validity is None else pa.py_buffer(validity)]
    if not pa.types.is_struct(type_):
        buffers.append(pa.py_buffer(values))
    if data is not None:
        buffers.append(pa.py_buffer(data))
    return pa.Array.from_buffers(type_, length, buffers, nulls, 0, children)


def batch_table(parts: list[Any], schema: pa.Schema = PARSE_SCHEMA) -> pa.Table:
    """One batch of the core's columns as a table of ``schema`` (the one they were described
    from: ``PARSE_SCHEMA``'s records by default)."""
    it = iter(parts)
    return pa.Table.from_arrays([_array(f.type, it) for f in schema], schema=schema)


def write(run: Any, out: str | IO[bytes], tick: Callable[[], None] | None = None) -> int:
    """Write a native run's records as Parquet (``tick``: called after each batch, for a
    progress bar); the number of rows. Interrupted (Ctrl-C, SIGTERM, SIGHUP: noted, acted on
    between batches), what was decoded stays written, footer included, and KeyboardInterrupt
    is raised, as with the Python engine; on any other failure nothing more is written."""
    writer = ParquetRecordWriter(out)
    try:
        # noted, acted on between batches: most of the time goes to Arrow writing a batch, and
        # a write broken off leaves a file no reader opens
        with noted_interrupts() as interrupted:
            for _rows, parts, _states in run:
                writer.write_parsed(batch_table(parts))
                if tick is not None:
                    tick()
                if interrupted:
                    break
    except BaseException:
        run.close()
        writer.abandon()
        raise
    if interrupted:
        run.close()
        writer.close()
        raise KeyboardInterrupt
    writer.close()
    return writer.rows
