"""Parquet output: the records as typed columns (analyzer/parquet/schema.py), for pandas, polars
and DuckDB.

One code path for both engines: records arrive as JSONL bytes (the native core's batches, or
the Python engine's records serialised with orjson, byte for byte the ``--format jsonl``
output), are parsed by Arrow's multithreaded JSON reader and flattened into the columns. Arrow
infers the types (twice as fast as an explicit nested schema); every parsed column is then
checked against ``SCHEMA`` and converted only where that is exact (all null, integers as
floats). The families give one key different types (``id``, ``values``), so a batch of several
families has each record's ``fields`` renamed after its family first. A batch that does not fit
(a register outside the map, a key a newer decoder added, a value of another type, source
events) is rewritten line by line against the explicit ``PARSE_SCHEMA``, with what no column
holds kept as JSON in ``other_fields``: slower, and exact. Parsing JSON is most of the cost
(tests/benchmarks/bench_parquet.py); a producer that builds Arrow itself hands its records to
``ParquetRecordWriter.write_parsed`` in ``PARSE_SCHEMA``'s layout and skips it.

Row groups of ``ROW_GROUP_ROWS`` rows are written as the records arrive: memory stays flat at
any input size. Source events have no rows (as in the CSV output).
"""

from __future__ import annotations

import io
import re
from collections import deque
from collections.abc import Iterable
from concurrent.futures import Future, ThreadPoolExecutor, wait
from typing import IO, TYPE_CHECKING, Any, Final

import orjson
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.json as pj
import pyarrow.parquet as pq

from ..session.listener import Listener
from .schema import (
    FAMILY,
    FLOAT,
    INT,
    KNOWN_PATHS,
    MM_TWINS,
    OTHER_FIELDS,
    PARSE_SCHEMA,
    PATHS,
    RECORD_COLUMNS,
    REGISTER_PATHS,
    REGISTER_VALUES,
    SCHEMA,
    SINGLE_WRITE,
    VALUES_KEY,
    Path,
    family_struct,
    millimetres,
    parse_key,
)

if TYPE_CHECKING:
    from ..session.batches import RecordSequence

ROW_GROUP_ROWS: Final = 65_536
# JSONL parsed at a time, in two blocks (one per thread): Arrow's parser needs several times
# the text while it works, so more costs memory and gains no speed
PARSE_BYTES: Final = 4 << 20
COMPRESSION: Final = "zstd"  # level 1: as fast as snappy, files half the size
COMPRESSION_LEVEL: Final = 1
# few distinct values ("summary": the same readings recur)
DICTIONARY: Final = ["bus", "protocol", "kind", "direction", "name", "summary"]
# min/max statistics, for the filters readers push down (time, device, which frame); on the
# hundred value columns they would cost a quarter of the writing and prune nothing
STATISTICS: Final = [*DICTIONARY, "t", "device", "code", "seq", "offset", "index", "latency_ms"]

_READ = pj.ReadOptions(block_size=PARSE_BYTES // 2)
_POOL = pa.system_memory_pool()
_PARSE = pj.ParseOptions(explicit_schema=PARSE_SCHEMA, unexpected_field_behavior="error")
_FIELDS_KEY: Final = b'"fields":'
_PROTOCOL_KEY: Final = b'"protocol":'
_PROTOCOL_RE: Final = re.compile(rb'"protocol":"((?:[^"\\]|\\.)*)"')
# protocol -> the marker of its records in JSONL (orjson writes no spaces)
_MARKERS: Final = {p: _PROTOCOL_KEY + orjson.dumps(p) for p in FAMILY}
_INT64: Final = range(-(1 << 63), 1 << 63)


# -- JSONL -> the parse schema -----------------------------------------------------------------


def _by_family(batch: bytes) -> tuple[bytes, str | None]:
    """The batch with each record's ``fields`` told apart by family, and the family whose
    ``fields`` are still under that key. The usual batch holds one family: it stays as it is.
    Otherwise each record's ``"fields":`` is renamed (``"fields_can":``): a JSON string holds
    no bare ``"fields":`` (its quotes are escaped), and no decoder has a key so named."""
    found = [p for p, marker in _MARKERS.items() if marker in batch]
    present = {FAMILY[p] for p in found}
    known = sum(batch.count(_MARKERS[p]) for p in found)
    if len(present) <= 1 and known == batch.count(_PROTOCOL_KEY):  # no other protocol either
        return batch, present.pop() if present else None
    lines = []  # records of several families (a recording of several buses): line by line
    for line in batch.splitlines():
        m = _PROTOCOL_RE.search(line)
        family = FAMILY.get(m.group(1).decode()) if m else None
        if family is not None:
            line = line.replace(_FIELDS_KEY, _renamed(family), 1)
        lines.append(line)
    return b"\n".join(lines), None


def _renamed(family: str) -> bytes:
    return orjson.dumps(parse_key(family)) + b":"


def _fits(value: Any, type_: pa.DataType) -> bool:
    """Whether a JSON value converts to ``type_`` exactly (null always does)."""
    if value is None:
        return True
    if pa.types.is_int64(type_):
        return type(value) is int and value in _INT64
    if pa.types.is_float64(type_):
        return type(value) in (int, float)
    if pa.types.is_string(type_):
        return type(value) is str
    if pa.types.is_boolean(type_):
        return type(value) is bool
    if pa.types.is_list(type_):
        item = type_.value_type
        return type(value) is list and all(_fits(v, item) for v in value)
    if pa.types.is_struct(type_):
        return type(value) is dict and all(
            type_.get_field_index(k) >= 0 and _fits(v, type_.field(k).type)
            for k, v in value.items()
        )
    return False


def _split_fields(
    fields: dict[str, Any], family: str | None
) -> tuple[dict[str, Any], dict[str, Any]]:
    """(what the family's columns hold, the rest)."""
    if family is None:
        return {}, fields
    kept: dict[str, Any] = {}
    other: dict[str, Any] = {}
    struct = family_struct(family)
    for key, value in fields.items():
        if key == VALUES_KEY and family != "serial" and type(value) is dict:
            regs = {k: v for k, v in value.items() if _fits({k: v}, REGISTER_VALUES)}
            rest = {k: v for k, v in value.items() if k not in regs}
            kept[key] = regs
            if rest:
                other[key] = rest
        elif struct.get_field_index(key) >= 0 and _fits(value, struct.field(key).type):
            kept[key] = value
        else:
            other[key] = value
    return kept, other


def _line_by_line(batch: bytes) -> bytes:
    """The records of a batch the explicit schema does not fit, rewritten so that it does:
    source events left out, what no column holds moved to ``other_fields`` as JSON."""
    out = []
    keys = [name for name, _, _ in RECORD_COLUMNS]
    for line in batch.splitlines():
        if not line.strip():
            continue
        try:
            d = orjson.loads(line)
        except orjson.JSONDecodeError as exc:
            raise ValueError(f"not a JSONL record ({exc}): {line[:60]!r}") from None
        if d.get("kind") == "event" or "protocol" not in d:
            continue  # a source event: no row, as in CSV
        family = FAMILY.get(d["protocol"])
        kept, other = _split_fields(d.get("fields") or {}, family)
        row: dict[str, Any] = {k: d.get(k) for k in keys}
        if family is not None:
            row[parse_key(family)] = kept
        if other:
            row[OTHER_FIELDS] = orjson.dumps(other).decode()
        out.append(orjson.dumps(row))
    return b"\n".join(out)


class _Mismatch(Exception):
    """The parsed batch does not fit the columns exactly: parse it line by line."""


def _leaves(table: pa.Table, family: str | None = None) -> dict[Path, pa.ChunkedArray]:
    """Every value column of a parsed table by its path, nested objects opened (a value is
    null where an object around it is); ``fields`` is ``family``'s."""
    out: dict[Path, pa.ChunkedArray] = {}
    todo: list[tuple[Path, pa.ChunkedArray]] = [
        ((parse_key(family) if name == "fields" and family else name,), table.column(name))
        for name in table.column_names
    ]
    while todo:
        path, column = todo.pop()
        if pa.types.is_struct(column.type):
            todo += [
                ((*path, c.name), a) for c, a in zip(column.type, column.flatten(), strict=True)
            ]
        else:
            out[path] = column
    return out


_NULLS: dict[pa.DataType, pa.Array] = {}


def _nulls(rows: int, type_: pa.DataType) -> pa.ChunkedArray:
    """A column of nulls: a slice of one array per type, so that the many columns a record
    leaves empty share their memory."""
    array = _NULLS.get(type_)
    if array is None or len(array) < rows:
        array = _NULLS[type_] = pa.nulls(max(rows, 1 << 16), type_)
    return pa.chunked_array([array.slice(0, rows)])


def _conform(column: pa.ChunkedArray, type_: pa.DataType) -> pa.ChunkedArray:
    """A parsed column as ``type_``, where that is exact: as it is, all null, integers as floats,
    empty or null lists and objects with keys left out; _Mismatch otherwise."""
    if column.type == type_:
        return column
    got = column.type
    if pa.types.is_null(got):
        return _nulls(len(column), type_)
    if pa.types.is_float64(type_) and pa.types.is_int64(got):
        return column.cast(type_)
    if pa.types.is_list(got) and pa.types.is_list(type_):
        item = got.value_type
        if pa.types.is_null(item):
            return column.cast(type_)
        if pa.types.is_struct(item) and pa.types.is_struct(type_.value_type):
            want = type_.value_type
            fits = all(want.get_field_index(c.name) >= 0 for c in item)
            fits = fits and all(
                want.field(c.name).type == c.type or pa.types.is_null(c.type) for c in item
            )
            if fits:
                return column.cast(type_)
    raise _Mismatch(f"{got} is not {type_}")


def parse_jsonl(batch: bytes) -> dict[Path, pa.ChunkedArray]:
    """JSONL records (whole lines) as their value columns by path: Arrow infers the types (twice
    as fast as an explicit nested schema), and the columns are checked against ``SCHEMA`` in
    ``flatten``; a batch that does not fit is rewritten line by line and parsed against the
    explicit ``PARSE_SCHEMA``."""
    try:
        text, family = _by_family(batch)
        leaves = _leaves(pj.read_json(io.BytesIO(text), _READ, memory_pool=_POOL), family)
        if not leaves.keys() <= KNOWN_PATHS:
            raise _Mismatch("keys no column holds")
        return leaves
    except (pa.ArrowInvalid, _Mismatch):
        exact = _line_by_line(batch)
        table = (
            pj.read_json(io.BytesIO(exact), _READ, _PARSE) if exact else PARSE_SCHEMA.empty_table()
        )
        return _leaves(table)


# -- the parsed values -> the Parquet columns --------------------------------------------------


def _register(
    name: str, leaves: dict[Path, pa.ChunkedArray], written: set[str], rows: int
) -> pa.ChunkedArray:
    """A register's column: its value in a Modbus or CAN frame's ``values``, or in a Modbus
    single write (``written``: the registers single writes name); frames of other families are
    null in each part."""
    parts = [_conform(leaves[p], INT) for p in REGISTER_PATHS[name] if p in leaves]
    if name in written:
        names, value = (leaves[p] for p in SINGLE_WRITE)
        parts.append(pc.if_else(pc.equal(names, name), _conform(value, INT), None))
    parts = [p for p in parts if p.null_count < rows]
    if not parts:
        return _nulls(rows, INT)
    return parts[0] if len(parts) == 1 else pc.coalesce(*parts)


def _single_writes(leaves: dict[Path, pa.ChunkedArray]) -> set[str]:
    """The registers the batch's Modbus single writes name."""
    names, value = (leaves.get(p) for p in SINGLE_WRITE)
    if names is None or value is None or names.null_count == len(names):
        return set()
    return {n for n in pc.unique(names).to_pylist() if n is not None}


def _millimetres(opening: pa.ChunkedArray) -> pa.ChunkedArray:
    if opening.null_count == len(opening):
        return _nulls(len(opening), FLOAT)
    return millimetres(opening)


def flatten(leaves: dict[Path, pa.ChunkedArray], rows: int) -> pa.Table:
    """Parsed value columns in the Parquet columns (``SCHEMA``); _Mismatch if one does not fit."""
    columns: dict[str, pa.ChunkedArray] = {}
    written = _single_writes(leaves)
    for f in SCHEMA:
        if f.name in REGISTER_PATHS:
            columns[f.name] = _register(f.name, leaves, written, rows)
        elif f.name in MM_TWINS:
            columns[f.name] = _millimetres(columns[MM_TWINS[f.name]])
        else:
            column = leaves.get(PATHS[f.name])
            columns[f.name] = _nulls(rows, f.type) if column is None else _conform(column, f.type)
    return pa.Table.from_arrays(list(columns.values()), schema=SCHEMA)


def jsonl_to_table(batch: bytes) -> pa.Table:
    """JSONL records (whole lines, as ``--format jsonl`` writes them) in the Parquet columns."""
    if not batch.strip():
        return SCHEMA.empty_table()
    leaves = parse_jsonl(batch)
    rows = len(next(iter(leaves.values()))) if leaves else 0
    try:
        return flatten(leaves, rows)
    except _Mismatch:
        table = pj.read_json(io.BytesIO(_line_by_line(batch)), _READ, _PARSE)
        return flatten(_leaves(table), table.num_rows)


# -- writing ------------------------------------------------------------------------------------


_ENCODER: ThreadPoolExecutor | None = None  # encodes row groups while the next are made
IN_FLIGHT: Final = 1  # row groups handed to it and not yet written, per file


def _encoder() -> ThreadPoolExecutor:
    global _ENCODER
    if _ENCODER is None:
        _ENCODER = ThreadPoolExecutor(1, thread_name_prefix="parquet-encoder")
    return _ENCODER


class RowGroupWriter:
    """One Parquet file written a row group of ``ROW_GROUP_ROWS`` at a time: tables of any size
    in, memory flat. The records output and the fleet dataset's partitions use it.

    Encoding and compressing a row group is about half the cost of a Parquet output, and
    pyarrow does it without Python's GIL: a thread of its own encodes one group while the
    caller makes the next (``IN_FLIGHT`` bounds what waits, so memory stays flat). A failed
    write is raised by the next call."""

    def __init__(
        self, out: str | IO[bytes], schema: pa.Schema = SCHEMA, dictionary: tuple[str, ...] = ()
    ) -> None:
        self.writer = pq.ParquetWriter(
            out,
            schema,
            compression=COMPRESSION,
            compression_level=COMPRESSION_LEVEL,
            use_dictionary=[c for c in (*DICTIONARY, *dictionary) if c in schema.names],
            write_statistics=[c for c in (*STATISTICS, *dictionary) if c in schema.names],
            data_page_version="2.0",  # pages with their levels uncompressed: faster to write
            write_batch_size=8192,
        )
        self.tables: list[pa.Table] = []  # not written yet
        self.table_rows = 0
        self.rows = 0  # handed to the encoder
        self.pending: deque[Future[None]] = deque()

    def add(self, table: pa.Table, final: bool = False) -> None:
        if table.num_rows:
            self.tables.append(table)
            self.table_rows += table.num_rows
        while self.table_rows >= ROW_GROUP_ROWS or (final and self.table_rows):
            self._write_group()

    def _write_group(self) -> None:
        table = pa.concat_tables(self.tables)
        group = table.slice(0, ROW_GROUP_ROWS)
        while len(self.pending) >= IN_FLIGHT:
            self.pending.popleft().result()
        self.pending.append(
            _encoder().submit(self.writer.write_table, group, row_group_size=ROW_GROUP_ROWS)
        )
        self.rows += group.num_rows
        rest = table.slice(group.num_rows)
        self.tables = [rest] if rest.num_rows else []
        self.table_rows = rest.num_rows

    def _wait(self) -> None:
        while self.pending:
            self.pending.popleft().result()

    def close(self) -> None:
        """Write what is left and the footer."""
        self.add(SCHEMA.empty_table(), final=True)
        self._wait()
        self.writer.close()

    def abandon(self) -> None:
        """Writing failed: drop what is held and write nothing more, not even the footer when
        the writer is collected (the output is discarded, or is closed already)."""
        self.tables = []
        for future in self.pending:
            future.cancel()
        wait(self.pending)  # the one being encoded: the file is not closed under it
        self.pending.clear()
        self.writer.is_open = False


class JsonlTables:
    """JSONL records in any pieces in, tables in the Parquet columns (``SCHEMA``) out to
    ``add``, a parse of ``PARSE_BYTES`` at a time."""

    def __init__(self) -> None:
        self.text: list[bytes] = []  # JSONL not parsed yet
        self.text_bytes = 0

    def add(self, table: pa.Table, final: bool = False) -> None:
        raise NotImplementedError

    def write_jsonl(self, batch: bytes) -> None:
        self.text.append(batch)
        self.text_bytes += len(batch)
        if self.text_bytes >= PARSE_BYTES:
            self._parse(final=False)

    def write_parsed(self, parsed: pa.Table) -> None:
        """Records already in Arrow, laid out as ``PARSE_SCHEMA`` (the JSONL keys, ``fields``
        as ``fields_serial``, ``fields_modbus`` or ``fields_can``): the way for a producer that
        builds Arrow itself to skip JSON (JSONL given before must be whole lines)."""
        self.flush_text(final=False)
        leaves = _leaves(parsed)
        unknown = leaves.keys() - KNOWN_PATHS
        if unknown:
            raise ValueError(f"no column holds {', '.join('.'.join(p) for p in sorted(unknown))}")
        self.add(flatten(leaves, parsed.num_rows))

    def flush_text(self, final: bool) -> None:
        """Parse the JSONL held (``final``: and write everything held)."""
        self._parse(final=True, write=final)

    def _parse(self, final: bool, write: bool = True) -> None:
        text = b"".join(self.text)
        cut = len(text) if final else text.rfind(b"\n") + 1  # a line may be on its way
        self.text = [text[cut:]] if cut < len(text) else []
        self.text_bytes = len(text) - cut
        self.add(jsonl_to_table(text[:cut]), final and write)


class ParquetRecordWriter(JsonlTables):
    """Takes JSONL bytes in any pieces, writes row groups of ``ROW_GROUP_ROWS`` as they fill."""

    def __init__(self, out: str | IO[bytes]) -> None:
        super().__init__()
        self.groups = RowGroupWriter(out)

    @property
    def rows(self) -> int:
        return self.groups.rows

    def add(self, table: pa.Table, final: bool = False) -> None:
        self.groups.add(table, final)

    def close(self) -> None:
        """Write what is left and the footer."""
        self.flush_text(final=True)
        self.groups.close()

    def abandon(self) -> None:
        self.text = []
        self.groups.abandon()


def write_jsonl_batches(batches: Iterable[bytes], out: str | IO[bytes]) -> int:
    """Write JSONL record batches (whole lines or any pieces) as a Parquet file; the number of
    rows written. The native engine's path to Parquet."""
    writer = ParquetRecordWriter(out)
    for batch in batches:
        writer.write_jsonl(batch)
    writer.close()
    return writer.rows


class ParquetListener(Listener):
    """The Python engine's Parquet output: its records, as JSONL bytes, to a ParquetRecordWriter."""

    def __init__(self, out: IO[bytes]) -> None:
        self.label = f"Parquet output to {getattr(out, 'name', 'a stream')}"
        self.writer = ParquetRecordWriter(out)

    def on_records(self, records: RecordSequence) -> None:
        self.writer.write_jsonl(records.jsonl())

    def close(self) -> None:
        self.writer.close()

    def on_error(self, exc: BaseException) -> None:
        self.writer.abandon()
