"""``stats``' grouping of a batch's records (analyzer/stats.py ``stats_groups``, the reference;
the native ``RecordBatch.stats_groups``, native/src/sinks/stats.rs): the same groups of the same
records on damaged serial and Modbus streams and hostile CAN traffic, and ``CaptureStats`` the
same whether it adds the records in one batch or in batches of any size."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import orjson
import pytest
from native_core import needs_native

from analyzer.model import Item
from analyzer.session.batches import RecordSequence, session_engine
from analyzer.stats import CaptureStats, stats_groups
from decoders.flags import RETRANSMISSION, UNANSWERED
from decoders.model import EG2_SERIAL, FRAME, GARBAGE, MODBUS_RTU, TRUNCATED, Record

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from test_cycles_native import on_two_buses  # tests/native is on sys.path
from traffic import can_frames, warning_can_frames

pytestmark = needs_native


def hostile_can(n: int) -> list[Item]:
    """Two buses of polls and writes, some breaking the rules, with foreign, error and remote
    frames, lost replies and frames without a time, or with NaN for one; a second log appended
    halfway (the clock goes back: with NaN times about, tests/decoders/test_pairing.py's case)."""
    frames = [*warning_can_frames(n // 2), *can_frames(n // 2, seed=3)]
    return on_two_buses(frames, seed=7, nan=True)


def byte_stream(protocol: str) -> list[Item]:
    import test_byte_stage as bs  # tests/native is on sys.path

    data = bs.damaged(bs.traffic(protocol, 4000, seed=3), seed=3)
    return bs.chunks(data, "random", bs.BUS[protocol], t0=bs.T0)


INPUTS = {
    "can": lambda: ("can", None, hostile_can(20_000)),
    "serial": lambda: ("bytes", EG2_SERIAL, byte_stream(EG2_SERIAL)),
    "modbus": lambda: ("bytes", MODBUS_RTU, byte_stream(MODBUS_RTU)),
}


def decoded(engine: str, name: str) -> Any:
    kind, protocol, items = INPUTS[name]()
    decoding, _ = session_engine(engine, kind, kind == "bytes", protocol)
    records = decoding.feed_items(items)
    records += decoding.finish()
    return records


@pytest.mark.parametrize("name", list(INPUTS))
def test_native_groups_are_the_python_groups(name: str) -> None:
    native = decoded("native", name)
    objects: list[Record] = list(native)
    assert type(native).__name__ == "RecordBatch"
    assert native.jsonl() == RecordSequence(decoded("python", name)).jsonl()
    groups = native.stats_groups()
    assert orjson.dumps(groups) == orjson.dumps(stats_groups(objects))  # NaN latencies: null
    kinds = {g[1] for g in groups[0]}
    flags = {f for g in groups[0] for f in g[6]}
    assert FRAME in kinds and (kinds & {GARBAGE, TRUNCATED} or name == "can")
    assert UNANSWERED in flags and (RETRANSMISSION in flags or name == "can")
    assert groups[1], "responses with their latency"


@pytest.mark.parametrize("name", list(INPUTS))
def test_stats_are_the_same_in_batches_of_any_size(name: str) -> None:
    """Counted in one batch, in batches of 1, 7 and 500: the same statistics, and they say
    what the records say."""
    records = RecordSequence(decoded("python", name))
    whole = CaptureStats()
    whole.add_groups(records.stats_groups())
    counted = whole.as_dict()
    assert whole.records == len(records)
    assert whole.frames == sum(1 for r in records if r.kind == FRAME)
    assert whole.valid == sum(1 for r in records if r.kind == FRAME and not r.errors)
    assert whole.bytes_garbage == sum(r.length for r in records if r.kind == GARBAGE)
    responses = [r for r in records if r.kind == FRAME and r.direction == "response"]
    assert sum(c.responses for c in whole.devices.values()) == sum(
        1 for r in responses if r.device is not None
    )
    for size in (1, 7, 500):
        stats = CaptureStats()
        for i in range(0, len(records), size):
            stats.add_groups(RecordSequence(records[i : i + size]).stats_groups())
        assert stats.as_dict() == counted, size
