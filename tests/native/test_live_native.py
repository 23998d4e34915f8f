"""The native live CAN path (``analyzer._native.CanStage``, ``RecordBatch``,
``can_raw_messages``) against the Python one it stands in for.

The same Items, ticks, gaps and end go through ``analyzer.session.stage.Decoding`` and through
``CanStage``; after every step both must give the same records: the materialized objects compare
== to the Python's (and have the same types, down to the JSON of their fields), and the batch's
bulk methods (``messages``, ``times``, ``buses``, ``error_count``, ``problems``) say what the
Python records say, the JSON byte for byte (``orjson.dumps(rec.to_dict(),
default=json_default)``, as the MCAP recorder writes it). ``can_raw_messages`` must give the
recorder's ``/raw`` messages of the same frames byte for byte.

Inputs: the benchmark's realistic traffic, several buses interleaved, frames without times,
error, remote, FD, standard and foreign frames, saves, retransmissions, requests never answered
(expired by ``tick``), gaps mid-stream, positional seq on and off, the hostile CAN frames of the
other tests (native_corpus), and Hypothesis-generated frames and steps. Skipped when the
extension is not built or has no live path.
"""

from __future__ import annotations

import dataclasses
import random
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import orjson
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from native_core import skip_or_fail, why_not

from analyzer.model import Item, json_default
from analyzer.session.stage import Decoding
from decoders import build as b
from decoders.model import CanFrame, Chunk, Record

if why := why_not():
    skip_or_fail(why)

import native_corpus as corpus  # after the check (tests/native is on sys.path)
from analyzer._native import CanStage, RecordBatch, can_raw_messages

from analyzer.recording.layout import raw_message
from analyzer.session.batches import json_message

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from traffic import can_frames

T0 = 1_763_700_000.0

# a step of a session: ("feed", items), ("tick", now), ("gap", bus) or ("finish",)
Step = tuple[Any, ...]


# -- running both -----------------------------------------------------------------------------


def dumps(rec: Record) -> bytes:
    """What the MCAP recorder writes for a record."""
    return orjson.dumps(rec.to_dict(), default=json_default)


def typed(rec: Record) -> list[tuple[type, Any]]:
    """Every attribute with its type (== alone takes 1 for 1.0 and True)."""
    return [(type(getattr(rec, f.name)), getattr(rec, f.name)) for f in dataclasses.fields(rec)]


def python_step(dec: Decoding, step: Step) -> list[Record]:
    op = step[0]
    if op == "feed":
        out: list[Record] = []
        for item in step[1]:
            out += dec.feed(item)
        return out
    if op == "tick":
        return dec.tick(step[1])
    if op in ("gap", "cut_off"):
        return getattr(dec, op)(step[1])
    return dec.stop() if op == "stop" else dec.finish()


def native_step(live: Any, step: Step) -> RecordBatch:
    op = step[0]
    if op == "feed":
        return live.feed(step[1])
    if op == "tick":
        return live.tick(step[1])
    if op in ("gap", "cut_off"):
        return getattr(live, op)(step[1])
    return live.stop() if op == "stop" else live.finish()


def check_batch(batch: RecordBatch, want: list[Record], where: str) -> None:
    """``batch`` holds the records ``want``, by every means of looking at it."""
    assert len(batch) == len(want), where
    # the bulk methods read the Rust records: before anything is materialized
    assert batch.messages() == [dumps(r) for r in want], where
    assert batch.times() == [r.t for r in want], where
    assert [type(t) for t in batch.times()] == [type(r.t) for r in want], where
    assert batch.buses() == [r.bus for r in want], where
    assert batch.error_count() == sum(1 for r in want if r.errors), where
    assert batch.problems() == [i for i, r in enumerate(want) if r.errors or r.warnings], where
    got = list(batch)
    assert got == want, where
    for g, w in zip(got, want, strict=True):
        assert type(g) is Record
        assert typed(g) == typed(w), where
        assert dumps(g) == dumps(w), where
    assert all(batch[i] is g for i, g in enumerate(got)), where


def run_both(
    steps: list[Step], positional: bool = False, can_index: int = 0
) -> tuple[list[Record], RecordBatch]:
    """Every step through both; the records of each step compared; all of them returned
    (Python's list, and the native batches joined with +=)."""
    dec = Decoding(positional_seq=positional, can_index=can_index)
    live = CanStage(positional, can_index)
    assert live.can_index == can_index
    everything: list[Record] = []
    joined = RecordBatch()
    for n, step in enumerate(steps):
        want = python_step(dec, step)
        batch = native_step(live, step)
        check_batch(batch, want, f"step {n} {step[0]}")
        assert live.can_index == dec.can_index
        everything += want
        joined += batch
    return everything, joined


def batches(items: list[Item], rng: random.Random, ticks: bool = True) -> list[Step]:
    """``items`` in feeds of random sizes (1 to 600: under and over the size where the GIL is
    released), with ticks between them at the time of the last frame, or later."""
    steps: list[Step] = []
    i = 0
    last_t = T0
    while i < len(items):
        n = rng.choice([1, 2, 3, 17, 100, 300, 600])
        chunk = items[i : i + n]
        i += n
        steps.append(("feed", chunk))
        ts = [it.payload.t for it in chunk if it.payload.t is not None]
        if ts:
            last_t = max(ts)
        if ticks and rng.random() < 0.5:
            steps.append(("tick", last_t + rng.choice([0.0, 0.001, 0.3, 0.6, 2.5])))
    return steps


def realistic(n: int, seed: int = 3) -> list[CanFrame]:
    return list(can_frames(n, seed=seed))


# -- odd frames ------------------------------------------------------------------------------


def odd_frames(t: float) -> list[CanFrame]:
    """Everything on a bus that is not an answered EG2 exchange."""
    return [
        CanFrame(t, 0x123, b"\x01\x02\x03", is_extended=False),  # standard id
        CanFrame(t, 0x7FF, b"", is_extended=False, is_remote=True, dlc=4),  # remote
        CanFrame(t, 0x04FF0001, b"", is_remote=True, dlc=6),
        CanFrame(t, 0x20000080 & 0x1FFFFFFF, bytes(8), is_error=True, channel="0"),  # error
        CanFrame(t, 0, b"", is_error=True),
        CanFrame(t, 0x1FF, bytes(8), is_error=True),
        CanFrame(t, 0x42, bytes(range(12)), is_fd=True),  # FD
        CanFrame(t, 0x123, b"\xaa" * 64, is_extended=False, is_fd=True),
        CanFrame(t, 0x04FF0001, b"\x00\x00\xf4\x01\xf4\x01", is_fd=True),
        CanFrame(t, 0x18FF50E5, bytes(range(8))),  # J1939: reserved bit set
        CanFrame(t, 0x1FFFFFFF, b"\xff"),
        CanFrame(t, 0x01180001, bytes(8), dlc=12),  # DLC beyond 8
        CanFrame(t, 0x01180001, bytes(3), dlc=5),  # DLC and data disagree
        CanFrame(t, 0x800, b"", is_extended=False),  # beyond 11 bits
        CanFrame(t, b.can_id(2, 1020, 1), b"\x01\x02"),  # positioning move
        CanFrame(t, b.can_id(3, 1020, 1), b""),  # servo follow, empty
        CanFrame(t, b.can_id(0, 1120, 1), b""),  # read without data
        CanFrame(t, b.can_id(1, 1120, 1), b""),  # write without data
        CanFrame(t, b.can_id(0, 1120, 0), b"\x08"),  # device 0
        CanFrame(t, b.can_id(0, 1120, 0x3FFF), b"\x08"),  # broadcast read
        CanFrame(t, b.can_id(1, 1020, 0x3FFF), b.u16le(100)),  # broadcast write
        CanFrame(t, b.can_id(0, 1121, 5), b"\x03"),  # odd address
        CanFrame(t, b.can_id(0, 1121, 5), b"\x01\x02\x03"),
        CanFrame(t, b.can_id(0, 4000, 5), b"\x02"),  # outside the register map
        CanFrame(t, b.can_id(1, 1120, 5), b.u16le(7)),  # write to a read-only register
        CanFrame(t, b.can_id(0, 1120, 6), b"\x08" + bytes(7)),  # padded read
        CanFrame(t, b.can_id(1, 1020, 6), b"\x06" + bytes(7)),  # padded write response
    ]


def exchanges(t: float, dev: int) -> list[CanFrame]:
    """Answered, unanswered, retransmitted, mismatched and saving exchanges on one device."""
    step = 0.001
    frames = [
        b.can_read_request(dev, 1120, 8, t=t),
        b.can_read_request(dev, 1120, 8, t=t + step),  # retransmission
        b.can_read_response(dev, 1120, b.u16le(1, 2, 3, 4), t=t + 2 * step),
        b.can_read_response(dev, 1120, b.u16le(1, 2, 3, 4), t=t + 3 * step),
        b.can_read_request(dev, 1128, 4, t=t + 4 * step),
        b.can_read_response(dev, 1128, b.u16le(0), t=t + 5 * step),  # shorter: mismatch
        b.can_write_request(dev, 1002, b.u16le(1), t=t + 6 * step),  # save
        b.can_write_response(dev, 1002, 2, t=t + 0.9),
        b.can_write_request(dev, 1020, b.u16le(300, 500, 500), t=t + 0.95),  # during save
        b.can_write_response(dev, 1020, 6, t=t + 0.951),
        b.can_read_response(dev, 1140, b.u16le(9), t=t + 0.96),  # orphan response
        b.can_read_request(dev, 1140, 2, t=t + 0.97),  # never answered
        b.can_read_request(dev, 1128, 4, t=t + 0.971),  # closer than 5 ms
        b.can_write_request(dev, 1001, b"\x01\x00\x00", t=t + 0.98),  # odd start and end
    ]
    return frames


def items_of(frames: list[CanFrame], buses: Sequence[str] = ("can0",), seed: int = 1) -> list[Item]:
    rng = random.Random(seed)
    return [Item(rng.choice(buses), f) for f in frames]


# -- the decodings ---------------------------------------------------------------------------


@pytest.mark.parametrize("positional", [False, True])
def test_realistic_traffic(positional: bool) -> None:
    rng = random.Random(7)
    items = items_of(realistic(6000))
    steps = [*batches(items, rng), ("finish",)]
    everything, joined = run_both(steps, positional=positional, can_index=5 if positional else 0)
    assert len(everything) == 6000
    assert sum(1 for r in everything if r.pair is not None) > 5000
    assert joined.messages() == [dumps(r) for r in everything]
    assert list(joined) == everything


def test_buses_interleaved() -> None:
    """Frames spread at random over three buses: answers land on other buses than their
    requests (orphans, time-outs), and each bus has its own decoder and pairing."""
    rng = random.Random(11)
    frames = realistic(3000, seed=5)
    items = items_of(frames, ("can0", "can1", "vcan2"), seed=2)
    steps = [*batches(items, rng), ("gap", "can1"), ("tick", T0 + 100), ("finish",)]
    everything, _ = run_both(steps)
    assert {r.bus for r in everything} == {"can0", "can1", "vcan2"}
    assert sum(1 for r in everything if "orphan_response" in r.flags) > 100


def test_bus_names_by_value() -> None:
    """A source that makes a new str per item for one bus (not the same object) decodes as one
    bus."""
    frames = realistic(400)
    items = [Item("".join(["ca", "n0"]), f) for f in frames]
    assert items[0].bus is not items[1].bus
    run_both([("feed", items), ("finish",)])


@pytest.mark.parametrize("positional", [False, True])
def test_odd_frames_and_exchanges(positional: bool) -> None:
    frames: list[CanFrame] = []
    t = T0
    for k in range(6):
        frames += odd_frames(t)
        frames += exchanges(t + 0.01, dev=1 + k % 3)
        t += 1.5
    steps: list[Step] = [("feed", items_of(frames[:40], ("can0", "can1")))]
    steps += [("tick", T0 + 0.5), ("feed", items_of(frames[40:], ("can0", "can1")))]
    steps += [("tick", t + 10), ("finish",)]
    everything, _ = run_both(steps, positional=positional)
    flags = {f for r in everything for f in r.flags}
    for want in (
        "foreign",
        "can_error_frame",
        "malformed",
        "unanswered",
        "orphan_response",
        "retransmission",
        "length_mismatch",
        "during_save",
        "closer_than_5ms",
        "odd_span",
        "undocumented",
        "read_only_write",
        "invalid_id",
        "ambiguous_direction",
    ):
        assert want in flags, want


def test_no_timestamps() -> None:
    """Frames without times: nothing expires by time, the pairing window and the end decide."""
    frames = realistic(2000)
    for i, f in enumerate(frames):
        if i % 3:
            f.t = None
    frames += [b.can_read_request(1, 1120, 8) for _ in range(30)]
    rng = random.Random(3)
    items = items_of(frames, ("can0", "can1"))
    run_both([*batches(items, rng), ("tick", T0 + 1e6), ("finish",)])


def test_pairing_window() -> None:
    """Without times a request never answered holds everything behind it until the pairing
    window's bounds (10 000 records, 64 KiB) give up on it."""
    frames = [b.can_read_request(1, 1140, 2), *realistic(24_000, seed=8)]
    for f in frames:
        f.t = None
    items = items_of(frames)
    everything, _ = run_both([*batches(items, random.Random(5)), ("finish",)])
    assert len(everything) == len(items)
    assert "no response within the pairing window" in everything[0].warnings


def test_odd_times() -> None:
    """Times that print in exponent form, are negative, zero, huge or go backwards."""
    times = [0.0, 1e-7, 5e-324, -1.5, 1e16, 123456789012345678.0, 2.5e-5, 1e-5, 9.99e15, -0.0]
    frames = []
    for i, t in enumerate(times * 3):
        frames += [
            b.can_read_request(1 + i % 2, 1120, 8, t=t),
            b.can_read_response(1 + i % 2, 1120, bytes(8), t=t + 1e-4),
        ]
    run_both([("feed", items_of(frames)), ("tick", 1e17), ("finish",)])
    items = items_of(frames)
    assert can_raw_messages(items) == [dumps_raw(it) for it in items]


def test_unanswered_expire_on_tick() -> None:
    requests = [b.can_read_request(d, 1120, 8, t=T0 + d * 0.01) for d in range(1, 40)]
    saves = [b.can_write_request(50, 1002, b.u16le(1), t=T0)]
    items = items_of(requests + saves)
    steps: list[Step] = [("feed", items)]
    steps += [("tick", T0 + x) for x in (0.1, 0.505, 0.52, 0.6, 1.0, 2.0, 2.1, 3.0)]
    everything, _ = run_both([*steps, ("finish",)])
    assert sum(1 for r in everything if r.warnings == ["no response within 500 ms"]) == 39
    assert any("no response within 2000 ms" in r.warnings for r in everything)


def test_gap_mid_stream() -> None:
    frames = realistic(1000)
    items = items_of(frames, ("can0", "can1"), seed=9)
    steps: list[Step] = [("feed", items[:301]), ("gap", "can0"), ("gap", "nowhere")]
    steps += [("feed", items[301:700]), ("gap", "can1"), ("gap", "can0")]
    steps += [("feed", items[700:]), ("finish",), ("tick", T0 + 1e4), ("finish",)]
    everything, _ = run_both(steps)
    assert any("no response before the source was lost" in r.warnings for r in everything)


def test_a_stop_cuts_off_what_waits() -> None:
    """At a user's stop (a bus's tap closed, then the session's end) the requests waiting are
    cut off by the stop, flagged ``cut_off`` and not ``unanswered``, the same in both engines;
    a source lost before keeps its wording."""
    frames = realistic(1000)
    items = items_of(frames, ("can0", "can1"), seed=4)
    steps: list[Step] = [("feed", items[:401]), ("gap", "can1"), ("feed", items[401:800])]
    steps += [("cut_off", "can0"), ("feed", items[800:]), ("cut_off", "nowhere")]
    steps += [("stop",), ("stop",)]  # the second: nothing is left
    everything, _ = run_both(steps)
    assert len(everything) == len(items)  # every frame came out
    cut = [r for r in everything if "cut_off" in r.flags]
    assert cut
    for r in cut:
        assert r.direction == "request" and "unanswered" not in r.flags
        assert r.warnings[-1] == "no response before the capture was stopped"
    assert any("no response before the source was lost" in r.warnings for r in everything)


def test_corpus_frames() -> None:
    """The hostile CAN frames of the other tests' tables, several times over (so memoised
    decodes are reused), with times and without."""
    _, mined, _ = corpus.mined()
    frames = [f for f in mined if 0 <= f.arbitration_id < 1 << 32 and isinstance(f.t, float | None)]
    assert len(frames) > 20
    out: list[CanFrame] = []
    for rep in range(3):
        for i, f in enumerate(frames):
            t = None if rep == 2 else T0 + rep + i * 0.002
            out.append(dataclasses.replace(f, t=t))
    run_both([("feed", items_of(out, ("can0", "can1"))), ("finish",)])


def test_data_as_any_buffer() -> None:
    """bytearray and memoryview data are read as bytes (the Python decoder does bytes(data))."""
    frames = realistic(200)
    for i, f in enumerate(frames):
        if i % 3 == 1:
            f.data = bytearray(f.data)
        elif i % 3 == 2:
            f.data = memoryview(bytes(f.data))
    items = items_of(frames)
    want = [dumps_raw(i) for i in items]
    run_both([("feed", items), ("finish",)])
    assert can_raw_messages(items) == want


# -- Hypothesis ------------------------------------------------------------------------------

EG2_ADDRESSES = [1000, 1001, 1002, 1003, 1020, 1021, 1120, 1121, 1128, 1130, 1140, 4000, 0]
DEVICES = [0, 1, 2, 3, 0x3FFF]


@st.composite
def frames_st(draw: st.DrawFn) -> CanFrame:
    kind = draw(st.sampled_from(["eg2"] * 6 + ["any29", "std", "remote", "error", "fd"]))
    if kind == "eg2":
        op = draw(st.sampled_from([0, 0, 1, 1, 2, 3]))
        aid = b.can_id(op, draw(st.sampled_from(EG2_ADDRESSES)), draw(st.sampled_from(DEVICES)))
        shape = draw(st.sampled_from(["count", "padded", "values", "empty"]))
        if shape == "count":
            data = bytes([draw(st.integers(0, 9))])
        elif shape == "padded":
            data = bytes([draw(st.integers(0, 9))]) + bytes(7)
        elif shape == "values":
            data = draw(st.binary(min_size=1, max_size=8))
        else:
            data = b""
        dlc = draw(st.sampled_from([None] * 8 + [len(data), 8, 15]))
        return CanFrame(None, aid, data, dlc=dlc)
    if kind == "any29":
        return CanFrame(None, draw(st.integers(0, 0x1FFFFFFF)), draw(st.binary(max_size=8)))
    if kind == "std":
        aid = draw(st.integers(0, 0x900))
        return CanFrame(None, aid, draw(st.binary(max_size=8)), is_extended=False)
    if kind == "remote":
        ext = draw(st.booleans())
        aid = draw(st.integers(0, 0x1FFFFFFF if ext else 0x7FF))
        return CanFrame(
            None, aid, b"", is_extended=ext, is_remote=True, dlc=draw(st.integers(0, 15))
        )
    if kind == "error":
        return CanFrame(
            None, draw(st.integers(0, 0x1FF)), draw(st.binary(max_size=8)), is_error=True
        )
    return CanFrame(
        None, draw(st.integers(0, 0x1FFFFFFF)), draw(st.binary(max_size=64)), is_fd=True
    )


@st.composite
def sessions(draw: st.DrawFn) -> tuple[list[Step], bool, int]:
    """A session: feeds of generated frames (times rising by small and large steps, or none)
    on one to three buses, with ticks, gaps and an end."""
    buses = ["can0", "can1", "x"][: draw(st.integers(1, 3))]
    timed = draw(st.sampled_from(["all", "none", "some"]))
    t = T0
    steps: list[Step] = []
    for _ in range(draw(st.integers(1, 8))):
        op = draw(st.sampled_from(["feed"] * 4 + ["tick", "gap"]))
        if op == "feed":
            items = []
            for frame in draw(st.lists(frames_st(), max_size=40)):
                t += draw(st.sampled_from([0.0, 0.0001, 0.003, 0.006, 0.3, 0.7, 1.2, 2.5]))
                if timed == "all" or (timed == "some" and draw(st.booleans())):
                    frame.t = t
                items.append(Item(draw(st.sampled_from(buses)), frame))
            steps.append(("feed", items))
        elif op == "tick":
            steps.append(("tick", t + draw(st.sampled_from([0.0, 0.4, 0.6, 2.1, 5.0]))))
        else:
            steps.append(("gap", draw(st.sampled_from(buses))))
    if draw(st.booleans()):
        steps.append(("finish",))
    return steps, draw(st.booleans()), draw(st.sampled_from([0, 1, 1000]))


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(sessions())
def test_generated_sessions(session: tuple[list[Step], bool, int]) -> None:
    steps, positional, can_index = session
    everything, joined = run_both(steps, positional=positional, can_index=can_index)
    assert joined.messages() == [dumps(r) for r in everything]
    items = [it for s in steps if s[0] == "feed" for it in s[1]]
    assert can_raw_messages(items) == [dumps_raw(it) for it in items]


# -- can_raw_messages ------------------------------------------------------------------------


def dumps_raw(item: Item) -> bytes:
    """The recorder's ``/raw`` message of an item, as the Python recorder makes it."""
    return json_message(raw_message(item))


def test_raw_messages() -> None:
    frames = realistic(300) + odd_frames(T0) + odd_frames(None) + exchanges(T0, 3)  # type: ignore[arg-type]
    for i, f in enumerate(frames):
        f.channel = [None, "can0", "0", 'we"ird\\\n\u00e9', "\U0001f600"][i % 5]
    items = items_of(frames, ("can0", "can1"))
    assert can_raw_messages(items) == [dumps_raw(it) for it in items]
    assert can_raw_messages(tuple(items)) == can_raw_messages(iter(items))
    assert can_raw_messages([]) == []


# -- what is refused -------------------------------------------------------------------------


def test_refused_items_decode_nothing() -> None:
    live = CanStage()
    good = items_of(realistic(10))
    bad: list[Any] = [
        Item("serial", Chunk(b"\x01\x02", T0)),
        Item("can0", CanFrame(1, 0x123, b"")),  # an int time: the Python would keep the int
        Item("can0", CanFrame(T0, 0x123, b"", is_extended=1)),  # type: ignore[arg-type]
        Item("can0", CanFrame(T0, -1, b"")),
        Item("can0", CanFrame(T0, 1 << 40, b"")),
        Item("can0", CanFrame(T0, True, b"")),  # type: ignore[arg-type]
        Item("can0", CanFrame(T0, 5, b"", dlc=-1)),
        Item("can0", CanFrame(T0, 5, b"", dlc=2.0)),  # type: ignore[arg-type]
        "not an item",
    ]
    for x in bad:
        with pytest.raises((TypeError, OverflowError)):
            live.feed([*good, x])
        assert live.can_index == 0
    with pytest.raises(TypeError, match="Chunk"):
        live.feed([Item("serial", Chunk(b"\x01", T0))])
    with pytest.raises(TypeError, match="Chunk"):
        can_raw_messages([Item("serial", Chunk(b"\x01", T0))])
    assert len(live.finish()) == 0
    assert len(live.feed(good)) + len(live.finish()) == 10


# -- RecordBatch as a list -------------------------------------------------------------------


def sample_batch(n: int = 40) -> tuple[RecordBatch, list[Record]]:
    frames = realistic(n)
    live, dec = CanStage(), Decoding()
    items = items_of(frames)
    batch = live.feed(items)
    batch += live.finish()
    want = [r for it in items for r in dec.feed(it)] + dec.finish()
    return batch, want


def test_batch_behaves_as_a_list() -> None:
    batch, want = sample_batch()
    assert isinstance(batch, Sequence)
    assert len(batch) == len(want) == 40
    assert bool(batch) and not RecordBatch()
    assert batch[0] == want[0] and batch[-1] == want[-1] and batch[-40] == want[0]
    for bad in (40, -41, 1 << 70):
        with pytest.raises(IndexError):
            batch[bad]
    with pytest.raises(TypeError):
        batch["0"]  # type: ignore[index]
    for sl in (
        slice(None),
        slice(3, 9),
        slice(-5, None),
        slice(None, None, -1),
        slice(30, 2, -3),
        slice(100, 200),
        slice(None, None, 7),
    ):
        assert batch[sl] == want[sl], sl
    assert batch[5:10][0] is batch[5]
    assert list(reversed(batch)) == want[::-1]
    assert want[3] in batch
    it = iter(batch)
    assert next(it) is batch[0]
    assert list(it) == want[1:]
    assert list(it) == []
    assert [r.seq for r in batch] == list(range(40))


def test_batch_iadd() -> None:
    batch, want = sample_batch()
    first = batch[0]
    other, other_want = sample_batch(10)
    other_first = other[0]
    acc = RecordBatch()
    acc += RecordBatch()
    assert len(acc) == 0
    acc += batch  # a named batch: copied, left as it was
    assert len(batch) == 40 and batch[0] is first
    assert acc[0] is first  # its objects come along
    acc += other
    assert acc[40] is other_first
    assert list(acc) == want + other_want
    acc += acc  # itself
    assert list(acc) == (want + other_want) * 2
    assert acc[50] is acc[0]
    n = len(acc)
    acc += sample_batch(6)[0]  # a temporary: moved
    assert len(acc) == n + 6
    assert acc.messages() == [dumps(r) for r in (want + other_want) * 2 + sample_batch(6)[1]]
    with pytest.raises(TypeError):
        acc += [first]  # type: ignore[arg-type]
    # the batch keeps working after being used as a source
    assert list(batch) == want


def test_batch_objects_are_kept() -> None:
    """A materialized record is the same object each time; changing it changes that object
    only (the bulk methods describe the records as decoded)."""
    batch, want = sample_batch(10)
    r = batch[3]
    assert batch[3] is r and batch[-7] is r and list(batch)[3] is r
    r.summary = "changed"
    assert batch[3].summary == "changed"
    assert batch.messages()[3] == dumps(want[3])
