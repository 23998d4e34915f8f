"""Columns of many entities sent in few calls: entities whose rows have the same times and seqs
(the force, opening, current and temperature of one CAN reply; the state and fault of another)
go into one Arrow record batch, which ``RecordingStream.send_record_batch`` splits into one chunk
per entity. A ``send_columns`` call costs about 0.4 ms of Python whatever its size; a batch of four
entities costs about as much as one call, which is what lets a live viewer of dozens of grippers
be updated ten times a second.

Columns carry Rerun's own Arrow metadata (``rerun:entity_path``, ``rerun:component``, ...), with
the component descriptors taken from the archetypes, so nothing here restates Rerun's names. A
component column is a plain array (one instance per row), which Rerun wraps in its list type; the
fields and schemas are made once and reused, since a live viewer gets dozens of batches ten times
a second.
"""

from __future__ import annotations

from typing import Any, Final

import numpy as np
import pyarrow as pa
import rerun as rr
from rerun.chunk import Chunk

from .entities import CAPTURE_TIME, FRAME

_INDEX: Final = {
    CAPTURE_TIME: pa.field(
        CAPTURE_TIME,
        pa.timestamp("ns"),
        metadata={b"rerun:kind": b"index", b"rerun:index_name": CAPTURE_TIME.encode()},
    ),
    FRAME: pa.field(
        FRAME, pa.int64(), metadata={b"rerun:kind": b"index", b"rerun:index_name": FRAME.encode()}
    ),
}

SCALARS: Final = (rr.Scalars.descriptor_scalars(),)
STATE: Final = (rr.StateChange.descriptor_state(),)
TEXT_LOG: Final = (rr.TextLog.descriptor_text(), rr.TextLog.descriptor_level())


class Batches:
    """Entity columns gathered by their rows; ``send`` sends one record batch per kind of rows."""

    def __init__(self) -> None:
        self._groups: dict[tuple[bytes | None, bytes | None], _Group] = {}
        self._fields: dict[tuple[str, str], pa.Field] = {}  # an entity's columns never change
        self._schemas: dict[tuple[int, ...], pa.Schema] = {}  # by the ids of their fields

    def add(
        self,
        path: str,
        seconds: np.ndarray | None,
        seq: np.ndarray | None,
        descriptors: tuple[Any, ...],
        values: list[pa.Array],
    ) -> None:
        """One entity's rows: times (float seconds) and/or seqs, and one array per component
        (``descriptors``: the archetype's, in the same order)."""
        key = (
            None if seconds is None else seconds.tobytes(),
            None if seq is None else seq.tobytes(),
        )
        group = self._groups.get(key)
        if group is None:
            stamps = None if seconds is None else nanoseconds(seconds)
            group = self._groups[key] = _Group(stamps, seq)
        fields = self._fields
        for descriptor, array in zip(descriptors, values, strict=True):
            field = fields.get((path, descriptor.component))
            if field is None:
                field = fields[(path, descriptor.component)] = _field(path, descriptor, array)
            group.fields.append(field)
            group.arrays.append(array)

    def send(self, stream: rr.RecordingStream) -> None:
        """Every group as one record batch, its chunks sent in one call (what
        ``send_record_batch`` does a batch at a time)."""
        schemas = self._schemas
        chunks: list[Chunk] = []
        for group in self._groups.values():
            key = tuple(map(id, group.fields))
            schema = schemas.get(key)
            if schema is None:
                schema = schemas[key] = pa.schema(group.fields)
            batch = pa.RecordBatch.from_arrays(group.arrays, schema=schema)
            chunks += Chunk.from_record_batch(batch)
        self._groups.clear()
        if chunks:
            stream.send_chunks(chunks)


class _Group:
    """Component columns that share their index columns."""

    __slots__ = ("arrays", "fields")

    def __init__(self, stamps_ns: np.ndarray | None, seq: np.ndarray | None) -> None:
        self.fields: list[pa.Field] = []
        self.arrays: list[pa.Array] = []
        if stamps_ns is not None:
            self.fields.append(_INDEX[CAPTURE_TIME])
            self.arrays.append(pa.array(stamps_ns).view(pa.timestamp("ns")))
        if seq is not None:
            self.fields.append(_INDEX[FRAME])
            self.arrays.append(pa.array(seq, pa.int64()))


def _field(path: str, descriptor: Any, column: pa.Array) -> pa.Field:
    """A component column of ``path``, described with Rerun's own metadata keys."""
    metadata = {
        b"rerun:kind": b"data",
        b"rerun:entity_path": path.encode(),
        b"rerun:archetype": (descriptor.archetype or "").encode(),
        b"rerun:component": descriptor.component.encode(),
        b"rerun:component_type": (descriptor.component_type or "").encode(),
    }
    return pa.field(f"{path}:{descriptor.component}", column.type, metadata=metadata)


def nanoseconds(t: np.ndarray) -> np.ndarray:
    """Seconds (float) to int64 nanoseconds, to the nanosecond the float holds (a float of epoch
    seconds times 1e9 would be off by up to a few hundred ns)."""
    whole = np.floor(t)
    return np.asarray(
        whole.astype(np.int64) * 1_000_000_000 + np.round((t - whole) * 1e9).astype(np.int64)
    )
