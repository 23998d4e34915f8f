"""Bulk columns of the native batches: ``RecordBatch.column(name)`` and
``SampleBatch.column(name)`` against ``[getattr(x, name) for x in batch]``.

For every attribute of ``decoders.model.Record`` and ``analyzer.model.StateSample`` the column
must equal the materialized objects' attributes with identical types, recursively (an int is not
a float or a bool, ``-0.0`` is not ``0.0``, a list is not a tuple, dict keys in the same order),
and equal what the Python decoding and tracker make of the same input. Batches come from the
generators of test_live_native.py (realistic traffic, odd frames, hostile corpus frames,
Hypothesis sessions) and test_tracker_native.py (CAN with what real buses add, Modbus, serial,
Hypothesis records, here with list, dict and signed-zero values too). Also: unknown names raise
AttributeError, empty batches give ``[]``, columns of a batch grown by ``+=``, columns do not
materialize (no Record or StateSample object appears), ``changed`` and ``values`` are new dicts
on every call. Skipped when the extension is not built or its batches have no ``column``.
"""

from __future__ import annotations

import dataclasses
import gc
import itertools
import random
import re
from collections.abc import Sequence
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from native_core import skip_or_fail, why_not

from analyzer.model import Item, StateSample
from analyzer.session import engine as native
from analyzer.session.stage import Decoding
from analyzer.session.tracker import Tracker
from decoders.eg2_serial import Cmd
from decoders.model import EG2_CAN, EG2_SERIAL, FRAME, MODBUS_RTU, REQUEST, RESPONSE, Record

if why := why_not():
    skip_or_fail(why)
_native: Any = native._native

# the generators of the other native tests (tests/native is on sys.path)
import test_live_native as lv  # noqa: E402
import test_tracker_native as tt  # noqa: E402

RecordBatch = _native.RecordBatch
CanStage = _native.CanStage

RECORD_ATTRS = [f.name for f in dataclasses.fields(Record)]
SAMPLE_ATTRS = [f.name for f in dataclasses.fields(StateSample)]


def test_the_attributes() -> None:
    """The names the columns must answer (the brief's lists) are the dataclasses' fields."""
    want = "t bus protocol kind length raw offset index direction device code name fields errors"
    want += " warnings summary seq pair latency_ms pair_key expects_response is_save flags"
    assert want.split() == RECORD_ATTRS
    assert SAMPLE_ATTRS == ["t", "bus", "device", "protocol", "seq", "changed", "values"]


# -- comparing ----------------------------------------------------------------------------------


def differs(a: Any, b: Any) -> str | None:
    """Where ``a`` and ``b`` differ in value or in any type, recursively (None: identical)."""
    if type(a) is not type(b):
        return f"{type(a).__name__} {a!r} vs {type(b).__name__} {b!r}"
    if isinstance(a, float):
        # repr tells -0.0 from 0.0 (== does not)
        return None if repr(a) == repr(b) else f"{a!r} vs {b!r}"
    if isinstance(a, list | tuple):
        if len(a) != len(b):
            return f"length {len(a)} vs {len(b)}: {a!r} vs {b!r}"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            if (why := differs(x, y)) is not None:
                return f"[{i}] {why}"
        return None
    if isinstance(a, dict):
        if list(a) != list(b):
            return f"keys {list(a)} vs {list(b)}"
        for (k, x), (j, y) in zip(a.items(), b.items(), strict=True):
            if (why := differs(k, j) or differs(x, y)) is not None:
                return f"[{k!r}] {why}"
        return None
    return None if a == b else f"{a!r} vs {b!r}"


def assert_column(got: list[Any], want: Sequence[Any], where: str) -> None:
    assert type(got) is list, where
    assert (why := differs(got, list(want))) is None, f"{where}: {why}"


def check_record_columns(batch: Any, want: Sequence[Record] | None, where: str = "") -> None:
    """Every column of ``batch``, taken before anything is materialized, against the
    materialized records and (when given) the Python decoding's records."""
    columns = {name: batch.column(name) for name in RECORD_ATTRS}
    got = list(batch)
    for name, column in columns.items():
        assert_column(column, [getattr(r, name) for r in got], f"{where} {name} vs materialized")
        if want is not None:
            assert_column(column, [getattr(r, name) for r in want], f"{where} {name} vs Python")
    # the static strings are the very objects materialization uses
    for name in ("protocol", "kind", "direction"):
        assert all(a is getattr(r, name) for a, r in zip(columns[name], got, strict=True)), name
    # taken again after materialization: the same values
    for name in RECORD_ATTRS:
        assert_column(batch.column(name), columns[name], f"{where} {name} again")


def check_sample_columns(batch: Any, want: Sequence[StateSample] | None, where: str = "") -> None:
    columns = {name: batch.column(name) for name in SAMPLE_ATTRS}
    got = list(batch)
    for name, column in columns.items():
        assert_column(column, [getattr(s, name) for s in got], f"{where} {name} vs materialized")
        if want is not None:
            assert_column(column, [getattr(s, name) for s in want], f"{where} {name} vs Python")
    for name in ("changed", "values"):
        again = batch.column(name)
        assert_column(again, columns[name], f"{where} {name} again")
        # new dicts: none is another call's, another sample's or a materialized sample's
        ids = {id(d) for d in columns[name]} | {id(d) for d in again}
        ids |= {id(getattr(s, name)) for s in got}
        assert len(ids) == 3 * len(got), name


# -- RecordBatch ----------------------------------------------------------------------------------


def run_both(steps: list[lv.Step], positional: bool = False, can_index: int = 0) -> Any:
    """The steps through Decoding and CanStage, the columns of every step's batch checked; the
    batches joined with += (checked too) and returned."""
    dec = Decoding(positional_seq=positional, can_index=can_index)
    live = CanStage(positional, can_index)
    everything: list[Record] = []
    joined = RecordBatch()
    for n, step in enumerate(steps):
        want = lv.python_step(dec, step)
        batch = lv.native_step(live, step)
        check_record_columns(batch, want, f"step {n} {step[0]}")
        everything += want
        joined += batch
    check_record_columns(joined, everything, "joined")
    return joined


@pytest.mark.parametrize("positional", [False, True])
def test_realistic_traffic(positional: bool) -> None:
    items = lv.items_of(lv.realistic(4000), ("can0", "can1", "vcan2"), seed=4)
    steps = [*lv.batches(items, random.Random(7)), ("gap", "can1"), ("finish",)]
    joined = run_both(steps, positional=positional, can_index=3 if positional else 0)
    assert len(joined) == 4000
    assert any(p is not None for p in joined.column("pair"))


@pytest.mark.parametrize("positional", [False, True])
def test_odd_frames_and_exchanges(positional: bool) -> None:
    """Foreign, error, remote, FD, malformed frames, retransmissions, saves, time-outs: every
    optional attribute both set and None, errors, warnings and flags non-empty."""
    frames = []
    t = lv.T0
    for k in range(5):
        frames += lv.odd_frames(t) + lv.exchanges(t + 0.01, dev=1 + k % 3)
        t += 1.5
    for i, f in enumerate(frames):
        if i % 7 == 3:
            f.t = None
    items = lv.items_of(frames, ("can0", "can1"))
    steps: list[lv.Step] = [("feed", items[:50]), ("tick", lv.T0 + 0.5), ("feed", items[50:])]
    joined = run_both([*steps, ("tick", t + 10), ("finish",)], positional=positional)
    for name in ("errors", "warnings", "flags", "fields"):
        assert any(joined.column(name)), name
    for name in ("t", "direction", "device", "code", "name", "pair", "latency_ms", "pair_key"):
        values = joined.column(name)
        assert None in values and any(v is not None for v in values), name
    assert True in joined.column("expects_response") and True in joined.column("is_save")


def test_corpus_frames() -> None:
    """The hostile frames of the other native tests, repeated (memoised decodes share their
    fields dict and summary)."""
    _, mined, _ = lv.corpus.mined()
    frames = [f for f in mined if 0 <= f.arbitration_id < 1 << 32 and isinstance(f.t, float | None)]
    out = []
    for rep in range(3):
        out += [
            dataclasses.replace(f, t=None if rep == 2 else lv.T0 + rep + i * 0.002)
            for i, f in enumerate(frames)
        ]
    run_both([("feed", lv.items_of(out, ("can0", "can1"))), ("finish",)])


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(lv.sessions())
def test_generated_sessions(session: tuple[list[lv.Step], bool, int]) -> None:
    steps, positional, can_index = session
    run_both(steps, positional=positional, can_index=can_index)


def test_unknown_names() -> None:
    batch, _ = lv.sample_batch(5)
    for name in ("nope", "", "T", "ok", "to_dict", "__class__", "fields "):
        with pytest.raises(AttributeError, match=re.escape(f"'{name}'")):
            batch.column(name)
        with pytest.raises(AttributeError):
            RecordBatch().column(name)
    with pytest.raises(TypeError):
        batch.column(1)


def test_empty_batches() -> None:
    for batch in (RecordBatch(), CanStage().finish(), CanStage().feed([])):
        for name in RECORD_ATTRS:
            assert batch.column(name) == [], name


def test_after_iadd() -> None:
    """Columns of a batch grown by += (named batches, a temporary, itself, empty ones) are the
    sources' columns joined."""
    a, want_a = lv.sample_batch(30)
    c, want_c = lv.sample_batch(7)
    a[2]  # a materialized record comes along: the columns still read the Rust records
    acc = RecordBatch()
    acc += RecordBatch()
    acc += a
    acc += c
    acc += acc
    acc += lv.sample_batch(4)[0]
    want = (want_a + want_c) * 2 + lv.sample_batch(4)[1]
    check_record_columns(acc, want, "acc")
    for name in RECORD_ATTRS:
        assert_column(acc.column(name)[:30], a.column(name), name)


def records_in_memory() -> int:
    gc.collect()
    return sum(1 for o in gc.get_objects() if type(o) is Record)


def test_columns_do_not_materialize() -> None:
    """No Record object is made (Records are tracked by the garbage collector, so every live
    one is counted); materializing afterwards still gives one object per index."""
    batch = CanStage().feed(lv.items_of(lv.realistic(500)))
    before = records_in_memory()
    columns = {name: batch.column(name) for name in RECORD_ATTRS}
    assert records_in_memory() == before
    assert batch[7] is batch[7]  # the count sees a materialization
    assert records_in_memory() == before + 1
    assert batch.column("summary") == columns["summary"]


def test_columns_describe_the_records_as_decoded() -> None:
    """As the other bulk methods: an attribute set on a materialized Record is not seen. (The
    ``fields`` dict of a memoised decode is one object, shared by its records' materialized
    objects and by the column, as materialization already shares it.)"""
    batch, want = lv.sample_batch(200)
    batch[3].summary = "changed"
    batch[4].errors.append("x")
    assert batch.column("summary")[3] == want[3].summary
    assert batch.column("errors")[4] == want[4].errors
    fields = batch.column("fields")
    shared = sum(1 for d, r in zip(fields, batch, strict=True) if d is r.fields)
    assert shared > 0


# -- SampleBatch ----------------------------------------------------------------------------------


@pytest.mark.parametrize("samples", [True, False])
def test_live_can_samples(samples: bool) -> None:
    """CanStage + the native Tracker against Decoding + Tracker, batch by batch, on the tracker
    tests' CAN traffic (three buses, many grippers, out-of-range readings, error frames, frames
    without times, requests never answered)."""
    rng = random.Random(5)
    items: list[Item] = list(tt.can_items(5000, 5))
    decoding, live = Decoding(), CanStage()
    py, nat = Tracker(samples=samples), _native.Tracker(samples=samples)
    joined = RecordBatch()
    i = made = 0
    while i < len(items):
        n = rng.choice((1, 10, 300))
        chunk = items[i : i + n]
        i += n
        want_records, batch = decoding.feed_items(chunk), live.feed(chunk)
        joined += batch
        want, got = py.update_many(want_records), nat.update_many(batch)
        check_sample_columns(got, want)
        made += len(got)
    got = nat.update_many(live.finish())
    check_sample_columns(got, py.update_many(decoding.finish()))
    assert (made > 300) if samples else made == 0, made
    # one batch of everything, through a new tracker
    check_sample_columns(_native.Tracker().update_many(joined), Tracker().update_many(list(joined)))


@pytest.mark.parametrize("protocol", [MODBUS_RTU, EG2_SERIAL])
def test_byte_stream_samples(protocol: str) -> None:
    rng = random.Random(2)
    if protocol == MODBUS_RTU:
        frames = list(tt.modbus_frames(1500, seed=2)) + tt.modbus_extra(rng)
    else:
        frames = list(tt.serial_frames(1500, seed=2)) + tt.serial_extra(rng)
    records = tt.byte_records(protocol, frames, 2)
    py, nat = Tracker(), _native.Tracker()
    for part in tt.split(records, rng):
        check_sample_columns(nat._update_records(part), py.update_many(part))


def serial_record(seq: int, device: int, position: Any, bus: str = "s") -> Record:
    """A serial READ_ACTPOS response: the tracker folds ``position`` as the opening, any type."""
    return Record(
        float(seq), bus, EG2_SERIAL, FRAME, 0, b"", direction=RESPONSE, device=device,
        code=Cmd.READ_ACTPOS, fields={"position": position}, seq=seq,
    )  # fmt: skip


def test_values_dicts_share_only_what_cannot_change() -> None:
    """A sample's values are made from its gripper's last ones: a value of the same type and
    bits may be the same object; 0.0 after -0.0, 1 after True, an equal list, are not."""
    positions: list[Any] = [-0.0, 0.0, 0.0, True, 1, 1, 1.0, [1], [1], {"a": 1}, {"a": 1}, "x"]
    positions += ["x", None, None, 2**70 // 2**10, -5]
    records = []
    for k, p in enumerate(positions):
        records.append(serial_record(2 * k, 1, p))
        records.append(serial_record(2 * k + 1, 2, positions[-1 - k], bus="t"))  # interleaved
    got = _native.Tracker()._update_records(records)
    check_sample_columns(got, Tracker().update_many(records))
    values = got.column("values")
    openings = [v["opening"] for v in values[::2]]
    for a, c in itertools.pairwise(openings):
        if isinstance(a, list | dict):
            assert a is not c
    values[0]["opening"] = "changed"  # each dict is the caller's own
    values[2]["frames"] = -1
    check_sample_columns(got, None)
    assert values[4]["frames"] == 3


# generated records: the tracker tests' values, and lists, dicts and signed zeros besides
ODD_VALUES = st.one_of(
    st.sampled_from([0.0, -0.0, 1.0, True, False, 0, 1]),
    st.lists(st.integers(-3, 3), max_size=2),
    st.dictionaries(st.sampled_from(["a", "b"]), st.integers(0, 2), max_size=2),
)


@st.composite
def odd_records(draw: st.DrawFn) -> Record:
    rec: Record = draw(tt.records())
    if draw(st.booleans()):
        value = draw(ODD_VALUES)
        if rec.protocol == EG2_SERIAL:
            rec.fields = {draw(st.sampled_from(tt.SERIAL_KEYS)): value}
        else:
            name = draw(st.sampled_from(["CMD_OPENLEN_ACT", "CMD_FORCE_ACT", "CMD_STATUS"]))
            rec.fields = {"values": {name: value}}
    return rec


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(batches=st.lists(st.lists(odd_records(), max_size=12), max_size=6))
def test_generated_records(batches: list[list[Record]]) -> None:
    py, nat = Tracker(), _native.Tracker()
    for batch in batches:
        check_sample_columns(nat._update_records(batch), py.update_many(batch))


def test_sample_names_and_empty() -> None:
    empty = _native.SampleBatch()
    for name in SAMPLE_ATTRS:
        assert empty.column(name) == [], name
        assert _native.Tracker().update_many(RecordBatch()).column(name) == []
    got = _native.Tracker().update_many(lv.sample_batch(20)[0])
    assert len(got) > 0
    for name in ("nope", "", "Bus", "to_dict", "__class__", "frames", "opening"):
        with pytest.raises(AttributeError, match=re.escape(f"'{name}'")):
            got.column(name)
        with pytest.raises(AttributeError):
            empty.column(name)
    with pytest.raises(TypeError):
        got.column(None)


def test_sample_columns_do_not_materialize() -> None:
    batch = CanStage().feed(lv.items_of(lv.realistic(500)))
    got = _native.Tracker().update_many(batch)

    def samples_in_memory() -> int:
        gc.collect()
        return sum(1 for o in gc.get_objects() if type(o) is StateSample)

    before, records = samples_in_memory(), records_in_memory()
    for name in SAMPLE_ATTRS:
        got.column(name)
    assert samples_in_memory() == before
    assert records_in_memory() == records
    assert got[3] is got[3]
    assert samples_in_memory() == before + 1


def test_the_records_tracked_are_the_columns() -> None:
    """A sample's t, bus, device and seq are its record's (the columns of both batches agree)."""
    batch = CanStage().feed(lv.items_of(lv.realistic(300), ("can0", "can1")))
    got = _native.Tracker().update_many(batch)
    by_seq = dict(zip(batch.column("seq"), range(len(batch)), strict=True))
    rows = [by_seq[s] for s in got.column("seq")]
    for name in ("t", "bus", "device"):
        column = batch.column(name)
        assert got.column(name) == [column[i] for i in rows], name
    assert set(got.column("protocol")) == {EG2_CAN}
    assert REQUEST in batch.column("direction")
