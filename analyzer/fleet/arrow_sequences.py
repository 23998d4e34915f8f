"""The native core's Arrow columns of a capture (``ArrowRun``: records in ``PARSE_SCHEMA``'s
layout, state samples in ``STATE_COLUMNS``) read as the sequences a session hands its listeners,
as far as a ``CyclesListener`` reads them: records by ``column`` and ``take``, samples by
``series`` (analyzer/session/batches.py is the reference of each method). So a capture the core
decodes in one pass is cut into grip cycles from the same columns its records and states are
written from, with no second decode and no object per record.

Only the records ``take`` picks become ``Record`` objects: their ``fields`` are the family's
column (``fields_serial``, ``fields_modbus`` or ``fields_can``, the keys without a value left
out) with what ``other_fields`` held, as the JSONL record had them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Final

import numpy as np
import orjson
import pyarrow as pa
import pyarrow.compute as pc

from decoders.model import Record

from ..parquet.schema import FAMILY, OTHER_FIELDS, VALUES_KEY, parse_key
from ..session.batches import Series

_FAMILY_KEYS: Final = {protocol: parse_key(family) for protocol, family in FAMILY.items()}
_FIELD_KEYS: Final = frozenset(_FAMILY_KEYS.values()) | {OTHER_FIELDS}
_KEY_SEPARATOR: Final = pa.scalar("\x00", pa.string())  # in no bus name


class ArrowRecords:
    """A batch of records in ``PARSE_SCHEMA``'s columns."""

    def __init__(self, table: pa.Table) -> None:
        self.table = table

    def __len__(self) -> int:
        return self.table.num_rows

    def __getitem__(self, index: int) -> Record:
        return self.take([index])[0]

    def column(self, name: str) -> list[Any]:
        return self.table.column(name).to_pylist()

    def take(self, indexes: Sequence[int]) -> list[Record]:
        table = self.table
        if len(indexes) != table.num_rows:  # (every row: a batch of candidates, as a rule)
            table = table.take(pa.array(indexes, pa.int64()))
        return [Record.from_dict(_record_dict(row)) for row in table.to_pylist()]


def _record_dict(row: dict[str, Any]) -> dict[str, Any]:
    """A parsed row as ``Record.to_dict`` had it: ``fields`` gathered back."""
    fields = _present(row.get(_FAMILY_KEYS.get(row["protocol"], "")) or {})
    other = row.get(OTHER_FIELDS)
    if other:
        for key, value in orjson.loads(other).items():
            if key == VALUES_KEY and isinstance(fields.get(key), dict):
                fields[key].update(value)
            else:
                fields[key] = value
    d = {k: v for k, v in row.items() if k not in _FIELD_KEYS}
    d["fields"] = fields
    return d


def _present(struct: dict[str, Any]) -> dict[str, Any]:
    """A struct's keys that have a value (nested structs too): a JSON object's keys."""
    out = {}
    for key, value in struct.items():
        if isinstance(value, dict):
            value = _present(value)
        if value is not None:
            out[key] = value
    return out


class ArrowSamples:
    """A batch of state samples in ``STATE_COLUMNS`` (``changed``: the names each one set)."""

    def __init__(self, table: pa.Table) -> None:
        self.table = table

    def __len__(self) -> int:
        return self.table.num_rows

    def series(self, fields: Sequence[str]) -> list[Series]:
        """``SampleSequence.series``: per gripper and set of ``fields`` changed, in the order
        the groups first appear, the samples' times, seqs and a column per name."""
        table = self.table
        which = _changed_bits(table.column("changed"), fields)
        kept = np.flatnonzero(which)
        if not len(kept):
            return []
        table = table.select(["bus", "device", "t", "seq", *fields]).take(pa.array(kept))
        key = pc.binary_join_element_wise(
            table.column("bus"),
            pc.cast(table.column("device"), pa.string()),
            pc.cast(pa.array(which[kept]), pa.string()),
            _KEY_SEPARATOR,
        )
        groups, ends, table = _grouped(table, key)
        values = {name: table.column(name).to_pylist() for name in ("t", "seq", *fields)}
        out = []
        for value, start, end in zip(groups, [0, *ends], ends, strict=False):
            bus, device, bits = value.split(_KEY_SEPARATOR.as_py())
            names = tuple(f for i, f in enumerate(fields) if int(bits) >> i & 1)
            columns = [values[name][start:end] for name in names]
            times, seqs = values["t"][start:end], values["seq"][start:end]
            out.append((bus, int(device), names, times, seqs, columns))
        return out


def _grouped(table: pa.Table, key: pa.Array) -> tuple[list[str], list[int], pa.Table]:
    """The distinct keys in the order they first appear, where each one's rows end, and the
    rows with each key's together (in their order)."""
    groups = pc.unique(key)
    group = pc.index_in(key, value_set=groups).to_numpy(zero_copy_only=False)
    order = np.argsort(group, kind="stable")
    ends = np.cumsum(np.bincount(group, minlength=len(groups))).tolist()
    return groups.to_pylist(), ends, table.take(pa.array(order))


def _changed_bits(changed: pa.ChunkedArray, fields: Sequence[str]) -> np.ndarray:
    """Per sample, which of ``fields`` it changed: bit i for ``fields[i]``."""
    lists = changed.combine_chunks()
    names, parents = lists.flatten(), pc.list_parent_indices(lists)
    bits = np.zeros(len(lists), dtype=np.int64)
    for i, name in enumerate(fields):
        rows = parents.filter(pc.equal(names, pa.scalar(name, pa.string())))
        bits[rows.to_numpy(zero_copy_only=False)] |= 1 << i
    return bits
