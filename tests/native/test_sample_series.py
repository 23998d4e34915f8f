"""``SampleBatch.series(fields)`` against the Python reference,
``analyzer.session.batches.SampleSequence`` of the same samples (the Python path).

The groups must be equal with identical types, recursively (an int is not a float or a bool,
``-0.0`` is not ``0.0``, a list is not a tuple): the same groups in the same order, the same
names, times, seqs and values. Samples come from the generators of the other native tests:
realistic CAN traffic with what real buses add, hostile frames, Hypothesis sessions through
``CanStage`` and the native Tracker, Modbus and serial records and Hypothesis records with lists,
dicts and signed zeros as values (``Tracker._update_records``); and also against the Python
tracker's samples of the same records. Field tuples: what the Rerun listener plots, none,
unknown names, counters (never changed), duplicates, every field in both orders, str
subclasses, non-str objects (an unhashable one raises TypeError as the Python does, and only
when there is a sample). Also: empty batches, batches of records joined with ``+=``, no
StateSample is made. Skipped when the extension is not built or its SampleBatch has no
``series``.
"""

from __future__ import annotations

import gc
import random
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from native_core import skip_or_fail, why_not

from analyzer.model import StateSample
from analyzer.session import engine as native
from analyzer.session.batches import SampleSequence
from analyzer.session.stage import Decoding
from analyzer.session.tracker import VALUE_KEYS, Tracker
from decoders.model import EG2_SERIAL, MODBUS_RTU, Record

if why := why_not():
    skip_or_fail(why)
_native: Any = native._native

# the generators and the comparison of the other native tests (tests/native is on sys.path)
import test_batch_columns as bc  # noqa: E402
import test_live_native as lv  # noqa: E402
import test_tracker_native as tt  # noqa: E402

RecordBatch = _native.RecordBatch
SampleBatch = _native.SampleBatch
CanStage = _native.CanStage


class Name(str):
    """A str subclass: found in a dict as the str it equals (names keep the caller's object)."""


PLOTTED = ("opening", "target_opening", "force", "force_setting", "current", "temperature_c")
PLOTTED += ("state", "fault")
FIELD_SETS: list[tuple[Any, ...]] = [
    PLOTTED,
    (),
    ("opening",),
    ("last_command", "latency_ms"),
    ("nope", "", "Opening", "frames", "errors", "unanswered"),  # none is ever changed
    ("state", "opening", "state", "fault", "opening"),  # given twice: named twice
    VALUE_KEYS,
    VALUE_KEYS[::-1],
    (*PLOTTED[::2], "frames", "speed", "catch_mode", "nope"),
    (Name("opening"), "force", 1, None, b"state", 2.5, ("fault",)),  # hashable non-str: no match
]


def check(batch: Any, want: list[StateSample] | None = None, where: str = "") -> int:
    """``batch.series`` for every field tuple against the Python function on the materialized
    samples (taken after the series, which must not make them) and on ``want`` when given (the
    Python tracker's samples of the same records). The number of series compared."""
    got = {fields: batch.series(fields) for fields in FIELD_SETS}
    samples = list(batch)
    n = 0
    for fields, series in got.items():
        label = f"{where} {fields!r}"
        assert type(series) is list, label
        ref = SampleSequence(samples).series(fields)
        assert (why := bc.differs(series, ref)) is None, f"{label}: {why}"
        if want is not None:
            assert (why := bc.differs(series, SampleSequence(want).series(fields))) is None, label
        # asked again: the same
        assert (why := bc.differs(batch.series(fields), ref)) is None, label
        for _, _, names, times, seqs, columns in series:
            assert type(names) is tuple and len(columns) == len(names), label
            assert all(len(c) == len(times) == len(seqs) for c in columns), label
            # the names are the caller's objects, as the Python's are
            assert all(any(name is f for f in fields) for name in names), label
        n += len(series)
    return n


# -- CAN: CanStage and the native Tracker ----------------------------------------------------------


@pytest.mark.parametrize("seed", [5, 6])
def test_live_can_traffic(seed: int) -> None:
    """The tracker tests' CAN traffic (three buses, many grippers, out-of-range readings,
    error frames, frames without times, requests never answered), batch by batch; then all of
    it joined with += through a new tracker."""
    rng = random.Random(seed)
    items = list(tt.can_items(6000, seed))
    decoding, live = Decoding(), CanStage()
    py, nat = Tracker(), _native.Tracker()
    joined = RecordBatch()
    i = groups = 0
    while i < len(items):
        n = rng.choice((1, 10, 300, 2000))
        chunk = items[i : i + n]
        i += n
        want_records, batch = decoding.feed_items(chunk), live.feed(chunk)
        joined += batch
        groups += check(nat.update_many(batch), py.update_many(want_records), f"at {i}")
    check(nat.update_many(live.finish()), py.update_many(decoding.finish()))
    assert groups > 500, groups
    everything = _native.Tracker().update_many(joined)
    want = Tracker().update_many(list(joined))
    assert check(everything, want) > 100
    series = everything.series(PLOTTED)
    # the buses where a frame set a plotted value (one with any value out of range sets none)
    plotted = {s.bus for s in want if any(f in s.changed for f in PLOTTED)}
    assert {bus for bus, *_ in series} == plotted and len(plotted) >= 2
    assert any(len(names) > 1 for _, _, names, *_ in series)
    assert any(None in times for _, _, _, times, *_ in series)


def test_realistic_traffic_and_odd_frames() -> None:
    frames = lv.realistic(3000)
    t = lv.T0 + 100
    for k in range(5):
        frames += lv.odd_frames(t) + lv.exchanges(t + 0.01, dev=1 + k % 3)
        t += 1.5
    items = lv.items_of(frames, ("can0", "can1", "vcan2"), seed=4)
    steps = [*lv.batches(items, random.Random(7)), ("gap", "can1"), ("finish",)]
    live, nat = CanStage(), _native.Tracker()
    for step in steps:
        check(nat.update_many(lv.native_step(live, step)), where=step[0])


def test_corpus_frames() -> None:
    _, mined, _ = lv.corpus.mined()
    frames = [f for f in mined if 0 <= f.arbitration_id < 1 << 32 and isinstance(f.t, float | None)]
    batch = CanStage().feed(lv.items_of(frames * 2, ("can0", "can1")))
    check(_native.Tracker().update_many(batch))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(lv.sessions())
def test_generated_sessions(session: tuple[list[lv.Step], bool, int]) -> None:
    steps, positional, can_index = session
    live, nat = CanStage(positional, can_index), _native.Tracker()
    joined = RecordBatch()
    for step in steps:
        batch = lv.native_step(live, step)
        joined += batch
        check(nat.update_many(batch))
    check(_native.Tracker().update_many(joined))


# -- any protocol and odd values: Python records through _update_records ----------------------


@pytest.mark.parametrize("protocol", [MODBUS_RTU, EG2_SERIAL])
def test_byte_stream_samples(protocol: str) -> None:
    rng = random.Random(3)
    if protocol == MODBUS_RTU:
        frames = list(tt.modbus_frames(1500, seed=3)) + tt.modbus_extra(rng)
    else:
        frames = list(tt.serial_frames(1500, seed=3)) + tt.serial_extra(rng)
    records = tt.byte_records(protocol, frames, 3)
    py, nat = Tracker(), _native.Tracker()
    for part in tt.split(records, rng):
        check(nat._update_records(part), py.update_many(part))


def test_repeated_and_odd_values() -> None:
    """Values that repeat (one object may stand for the next) and values that must not be
    taken for the one before: 0.0 after -0.0, 1 after True, 1.0 after 1, equal lists."""
    positions: list[Any] = [-0.0, 0.0, 0.0, True, 1, 1, 1.0, [1], [1], {"a": 1}, {"a": 1}, "x"]
    positions += ["x", None, None, 2**70 // 2**10, -5, False, 0, 0.0, -0.0]
    records = []
    for k, p in enumerate(positions):
        records.append(bc.serial_record(2 * k, 1, p))
        records.append(bc.serial_record(2 * k + 1, 2, positions[-1 - k], bus="t"))
    got = _native.Tracker()._update_records(records)
    check(got, Tracker().update_many(records))
    (_, _, _, _, _, [column]), _ = got.series(("opening",))
    lists = [v for v in column if isinstance(v, list | dict)]
    assert len({id(v) for v in lists}) == len(lists) == 4  # each sample its own


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    batches=st.lists(st.lists(bc.odd_records(), max_size=12), max_size=6),
    fields=st.lists(st.sampled_from([*VALUE_KEYS, "nope"]), max_size=6),
)
def test_generated_records(batches: list[list[Record]], fields: list[str]) -> None:
    py, nat = Tracker(), _native.Tracker()
    for batch in batches:
        got, want = nat._update_records(batch), py.update_many(batch)
        series = got.series(tuple(fields))
        assert bc.differs(series, SampleSequence(list(got)).series(fields)) is None
        assert bc.differs(series, SampleSequence(want).series(fields)) is None
        check(got, want)


# -- edges ----------------------------------------------------------------------------------------


def test_empty_batches() -> None:
    for batch in (SampleBatch(), _native.Tracker().update_many(RecordBatch())):
        for fields in [*FIELD_SETS, ([],)]:  # an unhashable field is never looked up
            assert batch.series(fields) == [] == SampleSequence(list(batch)).series(fields)
    # records that change nothing (requests and errors only): samples none of the fields has
    batch = CanStage().feed(lv.items_of(lv.realistic(200)))
    got = _native.Tracker().update_many(batch)
    assert len(got) > 0
    assert (
        got.series(("frames", "nope")) == [] == SampleSequence(list(got)).series(("frames", "nope"))
    )


def test_unhashable_field_raises_as_python() -> None:
    got = _native.Tracker().update_many(lv.sample_batch(40)[0])
    for fields in ((["opening"],), ("opening", {}), (Name("x"), set())):
        with pytest.raises(TypeError, match="unhashable"):
            SampleSequence(list(got)).series(fields)
        with pytest.raises(TypeError, match="unhashable"):
            got.series(fields)
    with pytest.raises(TypeError):
        got.series(["opening"])  # a tuple, as the Rerun listener passes


def test_series_do_not_materialize() -> None:
    """No StateSample object is made (they are tracked by the garbage collector, so every
    live one is counted); materializing afterwards still gives one object per index."""
    got = _native.Tracker().update_many(CanStage().feed(lv.items_of(lv.realistic(500))))

    def samples_in_memory() -> int:
        gc.collect()
        return sum(1 for o in gc.get_objects() if type(o) is StateSample)

    before = samples_in_memory()
    for fields in FIELD_SETS:
        got.series(fields)
    assert samples_in_memory() == before
    assert got[3] is got[3]
    assert samples_in_memory() == before + 1


def test_series_are_new_lists() -> None:
    """Every call makes new lists: a caller may change what it was given."""
    got = _native.Tracker().update_many(lv.sample_batch(200)[0])
    a, b = got.series(PLOTTED), got.series(PLOTTED)
    assert a == b and len(a) > 1
    a[0][3].append(0.0)
    a[0][5][0].clear()
    assert got.series(PLOTTED) == b
