"""A capture's ``captures/`` counts, from the tables of its records as they are written: the
numbers ``eg2scope stats`` gives (analyzer/stats.py ``CaptureStats``), gathered from columns a
batch at a time, so that no record needs to be a Python object (the native core hands out
columns). Whatever engine decoded the records, the counts come from the same columns."""

from __future__ import annotations

from collections import Counter
from typing import Any, Final

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from decoders.flags import RETRANSMISSION, UNANSWERED
from decoders.model import FRAME, GARBAGE, REQUEST, RESPONSE, TRUNCATED

from ..stats import CaptureStats, Counts

# scalars for compute functions, typed once (a Python value's type is inferred at every call)
_ZERO: Final = pa.scalar(0, pa.int64())
_FALSE: Final = pa.scalar(False, pa.bool_())
_NO_LATENCY: Final = pa.scalar(None, pa.float64())
_FRAME, _GARBAGE, _TRUNCATED, _REQUEST, _RESPONSE, _UNANSWERED, _RETRANSMISSION = (
    pa.scalar(text, pa.string())
    for text in (FRAME, GARBAGE, TRUNCATED, REQUEST, RESPONSE, UNANSWERED, RETRANSMISSION)
)
_KEY_SEPARATOR: Final = pa.scalar("\x00", pa.string())  # in no bus or protocol name
_DEVICE_KEY = ["bus", "protocol", "device"]
# the columns counted, as they are (errors and warnings: whether a record has any)
_KEPT = ("t", "protocol", "kind", "length", "flags", "direction", "latency_ms", *_DEVICE_KEY)


#: rows held before they are counted: counting costs per call more than per row, and the
#: columns held (a few bytes a row) stay small
FOLD_ROWS = 1 << 18


class RecordSummary:
    """``CaptureStats`` of the records, filled from tables in the records' Parquet columns
    (``analyzer.parquet.schema.SCHEMA``, ``bus`` included): the capture's counts, flags and
    devices with their counts and latency. (``commands``, the ID-scan notes and source events,
    which the ``captures/`` row does not hold, are left empty.) The columns counted are held
    until ``FOLD_ROWS`` of them wait, or ``stats`` is read."""

    def __init__(self) -> None:
        self._stats = CaptureStats()
        self.held: list[pa.Table] = []
        self.held_rows = 0

    @property
    def stats(self) -> CaptureStats:
        self._fold()
        return self._stats

    def add(self, table: pa.Table) -> None:
        if not table.num_rows:
            return
        columns = {name: table.column(name) for name in _KEPT}
        for name in ("errors", "warnings"):  # only whether there are any: lists of text
            columns[name] = pc.greater(pc.list_value_length(table.column(name)), _ZERO)
        self.held.append(pa.table(columns))
        self.held_rows += table.num_rows
        if self.held_rows >= FOLD_ROWS:
            self._fold()

    def _fold(self) -> None:
        if not self.held:
            return
        table = pa.concat_tables(self.held)
        self.held, self.held_rows = [], 0
        stats = self._stats
        stats.records += table.num_rows
        times = table.column("t").drop_null()
        if len(times):  # the span (records of several buses come per bus), as Stats.add
            low, high = pc.min_max(times).values()
            first, last = low.as_py(), high.as_py()
            stats.first_t = first if stats.first_t is None else min(stats.first_t, first)
            stats.last_t = last if stats.last_t is None else max(stats.last_t, last)
        stats.by_protocol.update(_counts(table.column("protocol")))
        kind = table.column("kind")
        frames = pc.equal(kind, _FRAME)
        errors = table.column("errors")
        garbage = pc.sum(pc.if_else(pc.equal(kind, _GARBAGE), table.column("length"), _ZERO))
        stats.bytes_garbage += garbage.as_py() or 0
        stats.truncated += _true(pc.equal(kind, _TRUNCATED))
        stats.frames += _true(frames)
        stats.valid += _true(pc.and_(frames, pc.invert(errors)))
        flags = table.column("flags")
        stats.flags.update(_counts(pc.list_flatten(flags)))
        on_device = pc.and_(frames, pc.is_valid(table.column("device")))
        if _true(on_device):
            self._devices(table, flags, on_device)

    def _devices(self, table: pa.Table, flags: pa.ChunkedArray, on_device: pa.Array) -> None:
        """``Counts.add`` for every frame of a device: each count summed per device, whose
        frames are told apart by a key of their bus, protocol and number."""
        direction = table.column("direction")
        request = pc.fill_null(pc.equal(direction, _REQUEST), _FALSE)
        response = pc.fill_null(pc.equal(direction, _RESPONSE), _FALSE)
        counted = {
            "requests": request,
            "responses": response,
            "unanswered": pc.and_(request, _has_flag(flags, _UNANSWERED)),
            "retransmissions": pc.and_(request, _has_flag(flags, _RETRANSMISSION)),
            "errors": table.column("errors"),
            "warnings": table.column("warnings"),
        }
        number = pc.cast(table.column("device"), pa.string())
        key = pc.binary_join_element_wise(
            table.column("bus"), table.column("protocol"), number, _KEY_SEPARATOR
        )
        devices = self._stats.devices
        for name, mask in counted.items():
            for text, n in _counts(key.filter(pc.and_(on_device, mask))).items():
                counts = devices.get(_device(text))
                if counts is None:
                    counts = devices[_device(text)] = Counts()
                setattr(counts, name, getattr(counts, name) + n)
        timed = pc.and_(pc.and_(on_device, response), pc.is_valid(table.column("latency_ms")))
        latency, key = table.column("latency_ms").filter(timed), key.filter(timed)
        for text in _counts(key):
            histogram = devices[_device(text)].latency
            mine = pc.equal(key, pa.scalar(text, pa.string()))
            for ms, n in _counts(latency.filter(mine)).items():
                histogram.add(ms, n)


def _device(key: str) -> tuple[str, str, int]:
    bus, protocol, number = key.split(_KEY_SEPARATOR.as_py())
    return bus, protocol, int(number)


def _true(mask: pa.Array | pa.ChunkedArray) -> int:
    return int(pc.sum(pc.cast(mask, pa.int64())).as_py() or 0)


def _counts(values: pa.Array | pa.ChunkedArray) -> Counter[Any]:
    """How often each value occurs, in the order values first occur (as a Counter fed one
    value at a time keeps them)."""
    counted = pc.value_counts(values)
    return Counter(
        dict(
            zip(
                counted.field("values").to_pylist(),
                counted.field("counts").to_pylist(),
                strict=True,
            )
        )
    )


def _has_flag(flags: pa.ChunkedArray, code: pa.Scalar) -> pa.Array:
    """Per row: whether its flags hold ``code``. (numpy reads and writes Arrow's buffers
    directly: ``to_numpy`` and ``pa.array`` of numpy look for pandas and numpy.ma first.)"""
    lists = flags.combine_chunks()
    rows = pc.filter(pc.list_parent_indices(lists), pc.equal(lists.flatten(), code))
    mask = np.zeros(len(lists), dtype=bool)
    mask[np.frombuffer(rows.buffers()[1], np.int64, len(rows), rows.offset * 8)] = True
    bits = pa.py_buffer(np.packbits(mask, bitorder="little"))
    return pa.Array.from_buffers(pa.bool_(), len(mask), [None, bits])
