"""A capture's ``captures/`` counts, from the tables of its records as they are written: the
numbers ``eg2scope stats`` gives (analyzer/stats.py ``CaptureStats``), gathered from columns a
batch at a time, so that no record needs to be a Python object (the native core hands out
columns). Whatever engine decoded the records, the counts come from the same columns."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from decoders.flags import RETRANSMISSION, UNANSWERED
from decoders.model import FRAME, GARBAGE, REQUEST, RESPONSE, TRUNCATED

from ..stats import CaptureStats, Counts

_DEVICE_KEY = ["bus", "protocol", "device"]
# per device: the flags of Counts.add, summed over its frames
_COUNTED = ("requests", "responses", "unanswered", "retransmissions", "errors", "warnings")


class RecordSummary:
    """``CaptureStats`` of the records, filled from tables in the records' Parquet columns
    (``analyzer.parquet_schema.SCHEMA``, ``bus`` included): the capture's counts, flags and
    devices with their counts and latency. (``commands``, the ID-scan notes and source events,
    which the ``captures/`` row does not hold, are left empty.)"""

    def __init__(self) -> None:
        self.stats = CaptureStats()

    def add(self, table: pa.Table) -> None:
        rows = table.num_rows
        if not rows:
            return
        stats = self.stats
        stats.records += rows
        times = table.column("t").drop_null()
        if len(times):
            if stats.first_t is None:
                stats.first_t = times[0].as_py()
            stats.last_t = times[-1].as_py()
        stats.by_protocol.update(_counts(table.column("protocol")))
        kind = table.column("kind")
        frames = pc.equal(kind, FRAME)
        errors = pc.greater(pc.list_value_length(table.column("errors")), 0)
        garbage = pc.sum(pc.if_else(pc.equal(kind, GARBAGE), table.column("length"), 0))
        stats.bytes_garbage += garbage.as_py() or 0
        stats.truncated += _true(pc.equal(kind, TRUNCATED))
        stats.frames += _true(frames)
        stats.valid += _true(pc.and_(frames, pc.invert(errors)))
        flags = table.column("flags")
        stats.flags.update(_counts(pc.list_flatten(flags)))
        on_device = pc.and_(frames, pc.is_valid(table.column("device")))
        if _true(on_device):
            self._devices(table, flags, errors, on_device)

    def _devices(
        self, table: pa.Table, flags: pa.ChunkedArray, errors: pa.Array, on_device: pa.Array
    ) -> None:
        """``Counts.add`` for every frame of a device, a group of them at a time."""
        direction = table.column("direction")
        request = pc.fill_null(pc.equal(direction, REQUEST), False)
        response = pc.fill_null(pc.equal(direction, RESPONSE), False)
        counted = {
            "requests": request,
            "responses": response,
            "unanswered": pc.and_(request, _has_flag(flags, UNANSWERED)),
            "retransmissions": pc.and_(request, _has_flag(flags, RETRANSMISSION)),
            "errors": errors,
            "warnings": pc.greater(pc.list_value_length(table.column("warnings")), 0),
        }
        latency = table.column("latency_ms")
        frames = pa.table(
            {
                **{k: table.column(k) for k in _DEVICE_KEY},
                **{k: pc.cast(v, pa.int64()) for k, v in counted.items()},
                "latency_ms": pc.if_else(response, latency, None),
            }
        ).filter(on_device)
        devices = self.stats.devices
        sums = frames.group_by(_DEVICE_KEY, use_threads=False).aggregate(
            [(k, "sum") for k in _COUNTED]
        )
        for row in sums.to_pylist():
            key = (row["bus"], row["protocol"], row["device"])
            counts = devices.get(key)
            if counts is None:
                counts = devices[key] = Counts()
            for name in _COUNTED:
                setattr(counts, name, getattr(counts, name) + row[f"{name}_sum"])
        timed = frames.filter(pc.is_valid(frames.column("latency_ms")))
        latencies = timed.group_by([*_DEVICE_KEY, "latency_ms"], use_threads=False).aggregate(
            [([], "count_all")]
        )
        for row in latencies.to_pylist():
            key = (row["bus"], row["protocol"], row["device"])
            devices[key].latency.add(row["latency_ms"], row["count_all"])


def _true(mask: pa.Array | pa.ChunkedArray) -> int:
    return int(pc.sum(pc.cast(mask, pa.int64())).as_py() or 0)


def _counts(values: pa.Array | pa.ChunkedArray) -> Counter[str]:
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


def _has_flag(flags: pa.ChunkedArray, code: str) -> pa.Array:
    """Per row: whether its flags hold ``code``."""
    mask = np.zeros(len(flags), dtype=bool)
    offset = 0
    for chunk in flags.chunks:
        hit = pc.equal(pc.list_flatten(chunk), code)
        rows = pc.filter(pc.list_parent_indices(chunk), hit).to_numpy()
        mask[offset + rows] = True
        offset += len(chunk)
    return pa.array(mask)
