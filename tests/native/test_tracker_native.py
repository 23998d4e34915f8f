"""The native state tracker (``analyzer._native.Tracker``, native/src/session/tracker.rs) against
the Python one (analyzer/session/tracker.py): the same records folded by both must give equal
state samples (dataclass equality, and the same key order in ``changed`` and ``values``),
byte-identical
``messages()`` (``orjson.dumps(sample.to_dict(), default=json_default)``), the same times and
keys, and equal device states, batch after batch.

Records come from the Python decoders (analyzer.session.stage.Decoding) fed realistic traffic
(tests/benchmarks/traffic.py) on several buses, with what real buses add: out-of-range readings,
writes of read-only registers, error frames, frames with no time, requests never answered (the
pairer's ``unanswered`` flag); Modbus and serial traffic too (the Python tracker folds every
protocol; so does the native one); and Hypothesis-made records with odd values. They reach the
native tracker through ``Tracker._update_records`` (Python records converted field by field);
when the core has ``CanStage``, also as the ``RecordBatch`` of ``CanStage.feed``.
Skipped when the extension is not built (or was built without the tracker).
"""

from __future__ import annotations

import random
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import orjson
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from native_core import skip_or_fail, why_not

from analyzer.model import Item, StateSample, json_default
from analyzer.session import engine as native
from analyzer.session.stage import Decoding
from analyzer.session.tracker import VALUE_KEYS, DeviceState, Tracker
from decoders import build as b
from decoders.eg2_serial import Cmd
from decoders.flags import UNANSWERED
from decoders.model import (
    EG2_CAN,
    EG2_SERIAL,
    FRAME,
    GARBAGE,
    MODBUS_RTU,
    REQUEST,
    RESPONSE,
    CanFrame,
    Chunk,
    Record,
)
from decoders.registers import REGISTERS

if why := why_not():
    skip_or_fail(why)
_native: Any = native._native

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests" / "benchmarks"))
from traffic import can_frames, modbus_frames, serial_frames  # noqa: E402

SLOW = settings(max_examples=200, suppress_health_check=[HealthCheck.too_slow])


# -- comparing ------------------------------------------------------------------------------------


def message(sample: StateSample) -> bytes:
    return orjson.dumps(sample.to_dict(), default=json_default)


def assert_same_samples(want: list[StateSample], got: Any) -> None:
    """A native SampleBatch against the Python tracker's samples."""
    assert len(got) == len(want)
    assert got.messages() == [message(s) for s in want]
    assert got.times() == [s.t for s in want]
    assert got.keys() == [(s.bus, s.device) for s in want]
    samples = list(got)
    assert samples == want
    for g, w in zip(samples, want, strict=True):
        assert type(g) is StateSample
        # dict equality ignores order (and 1 == 1.0 == True): the JSON above checks types
        assert list(g.changed) == list(w.changed)
        assert list(g.values) == list(w.values)
        assert g.changed == {k: g.values[k] for k in g.changed}


def assert_same_states(want: Tracker, got: Any) -> None:
    states = got.states
    assert list(states) == list(want.states)
    for key, w in want.states.items():
        g = states[key]
        assert type(g) is DeviceState
        assert (g.bus, g.device, g.protocol, g.t) == (w.bus, w.device, w.protocol, w.t)
        assert list(g.values) == list(w.values) == list(VALUE_KEYS)
        assert orjson.dumps(g.values) == orjson.dumps(w.values, default=json_default)
        assert orjson.dumps(g.to_dict()) == orjson.dumps(w.to_dict(), default=json_default)


def run_both(batches: Sequence[Sequence[Record]], samples: bool = True) -> int:
    """Fold the batches with both trackers, comparing after every batch; the samples made."""
    py, nat = Tracker(samples=samples), _native.Tracker(samples=samples)
    made = 0
    for batch in batches:
        want = py.update_many(list(batch))
        got = nat._update_records(list(batch))
        assert_same_samples(want, got)
        assert_same_states(py, nat)
        made += len(want)
    return made


def split(records: list[Record], rng: random.Random, most: int = 400) -> list[list[Record]]:
    """The records in batches of random sizes (empty ones too), as a live session gets them."""
    out: list[list[Record]] = []
    i = 0
    while i < len(records):
        n = rng.choice((0, 1, 2, 7, 50, most))
        out.append(records[i : i + n])
        i += n
    return out


# -- inputs ---------------------------------------------------------------------------------------


def can_items(n: int, seed: int) -> Iterator[Item]:
    """Realistic polling on three buses, with what real buses carry besides: out-of-range
    readings, writes of read-only registers, error and remote frames, standard and foreign ids,
    frames with no time, answers that never come."""
    rng = random.Random(seed)
    for k, f in enumerate(can_frames(n, seed=seed)):
        bus = ("can0", "can0", "can1", "vcan2")[k % 4 if k % 3 else 0]
        roll = rng.random()
        dev = rng.randint(1, 24)
        if roll < 0.03:
            continue  # lost: its request is never answered (or an answer has no request)
        if roll < 0.05:  # readings outside the documented ranges
            yield Item(bus, b.can_read_request(dev, 1120, 8, t=f.t))
            data = b.u16le(rng.choice((50, 9999)), 1500, -2500, 150)
            yield Item(bus, b.can_read_response(dev, 1120, data, t=f.t))
            yield Item(bus, b.can_read_request(dev, 1128, 4, t=f.t))
            data = b.u16le(rng.choice((0, 7, 0x40)), rng.choice((0, 9, 3)))
            yield Item(bus, b.can_read_response(dev, 1128, data, t=f.t))
        elif roll < 0.06:  # writes of read-only registers, in and out of range
            data = b.u16le(rng.randint(0, 2000), rng.randint(0, 2000))
            yield Item(bus, b.can_write_request(dev, 1120, data, t=f.t))
            yield Item(bus, b.can_write_response(dev, 1120, 4, t=f.t))
        elif roll < 0.07:  # settings, some out of range
            data = b.u16le(rng.randint(0, 1200), rng.randint(0, 1200), rng.randint(0, 1200))
            yield Item(bus, b.can_write_request(dev, 1020, data, t=f.t))
            yield Item(bus, b.can_write_request(dev, 1032, b.u16le(1000, 0), t=f.t))
            yield Item(bus, b.can_write_request(dev, 1010, b.u16le(rng.randint(0, 2)), t=f.t))
        elif roll < 0.073:
            yield Item(bus, CanFrame(f.t, 0x20000080, b"\x00" * 8, is_error=True))
        elif roll < 0.075:  # an EG2 id without data: an error on a device's record
            yield Item(bus, CanFrame(f.t, f.arbitration_id, b""))
        elif roll < 0.08:
            yield Item(bus, CanFrame(f.t, f.arbitration_id, b"", is_remote=True, dlc=2))
        elif roll < 0.085:
            yield Item(bus, CanFrame(f.t, 0x123, b"\x01\x02", is_extended=False))
        elif roll < 0.09:
            yield Item(bus, CanFrame(f.t, 0x1FFFFFFF, b"\x01\x02\x03"))
        elif roll < 0.1:
            yield Item(bus, CanFrame(None, f.arbitration_id, f.data))
            continue
        yield Item(bus, f)


def decode(items: Iterator[Item], rng: random.Random, decoding: Decoding) -> list[Record]:
    """Items through the Python decoding, with ticks (expiring what waits) now and then."""
    records: list[Record] = []
    last_t = 0.0
    for item in items:
        records += decoding.feed(item)
        t = getattr(item.payload, "t", None)
        if t is not None:
            last_t = t
        if rng.random() < 0.01:
            records += decoding.tick(last_t + rng.choice((0.0, 0.05, 5.0)))
    return records + decoding.finish()


def can_records(n: int, seed: int) -> list[Record]:
    return decode(can_items(n, seed), random.Random(seed), Decoding())


def byte_records(protocol: str, frames: list[bytes], seed: int) -> list[Record]:
    """A byte stream on two buses, in chunks, with noise and damaged frames now and then."""
    rng = random.Random(seed)
    items: list[Item] = []
    t = 1_763_700_000.0
    for k, frame in enumerate(frames):
        t += 0.003
        data = bytearray(frame)
        roll = rng.random()
        if roll < 0.02:
            data[rng.randrange(len(data))] ^= 0x10  # a bad checksum
        elif roll < 0.03:
            data = bytearray(rng.randbytes(rng.randint(1, 6))) + data  # noise first
        bus = "rs485a" if k % 5 else "rs485b"
        items.append(Item(bus, Chunk(bytes(data), t if rng.random() > 0.05 else None)))
    return decode(iter(items), rng, Decoding(protocol=protocol))


def modbus_extra(rng: random.Random) -> list[bytes]:
    """Modbus writes the polling traffic lacks: read-only registers, out-of-range values,
    several registers at once, the short numbering."""
    out: list[bytes] = []
    for _ in range(60):
        dev = rng.randint(1, 3)
        reg = rng.choice([r.number for r in REGISTERS])
        value = rng.choice((0, 1, 5, 100, 500, 1000, 1001, 40000))
        out.append(b.modbus_write_single(dev, rng.choice((reg, reg - 1000)), value))
        out.append(b.modbus_write_single(dev, reg, value))
        values = [rng.randint(0, 1200) for _ in range(rng.randint(1, 6))]
        out.append(b.modbus_write_multiple(dev, 1010, values))
        out.append(b.modbus_write_multiple_response(dev, 1010, len(values)))
        out.append(b.modbus_read_request(dev, 1060, 6))
        out.append(b.modbus_read_response(dev, [rng.randint(0, 70000) for _ in range(6)]))
    return out


def serial_extra(rng: random.Random) -> list[bytes]:
    """Serial commands that set the state: catch, release, seek, limits, run state, 0x14."""
    s = b.serial_frame
    out: list[bytes] = []
    for _ in range(60):
        dev = rng.randint(1, 3)
        out += [s(dev, Cmd.MOVE_CATCH2_XG, b.u16le(500, 100)), s(dev, 0x18, b"\x01", True)]
        out += [s(dev, Cmd.SEEKPOS, b.u16le(rng.randint(0, 1500))), s(dev, 0x54, b"\x01", True)]
        out += [s(dev, Cmd.SET_EG_PARA, b.u16le(900, 50)), s(dev, 0x12, b"\x01", True)]
        out += [s(dev, Cmd.READ_EG_PARA), s(dev, 0x13, b.u16le(rng.randint(0, 2000), 5), True)]
        state = bytes((rng.randint(0, 9), rng.choice((0, 1, 0x21)), 40))
        data = state + b.u16le(rng.randint(0, 3000), 100)
        out += [s(dev, Cmd.READ_EG_RUNSTATE), s(dev, 0x41, data, True)]
        out += [s(dev, Cmd.READ_EG_STATE), s(dev, 0x14, rng.randbytes(rng.randint(0, 12)), True)]
        out += [s(dev, Cmd.MOVE_RELEASE, b.u16le(300)), s(dev, 0x11, b"\x01", True)]
    return out


# -- the differential tests -----------------------------------------------------------------------


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("samples", [True, False])
def test_can_traffic(seed: int, samples: bool) -> None:
    records = can_records(6000, seed)
    assert any(UNANSWERED in r.flags for r in records)
    assert any(r.errors and r.device is not None for r in records)
    assert any(r.t is None and r.device is not None for r in records)
    assert len({r.bus for r in records}) == 3
    made = run_both(split(records, random.Random(seed)), samples=samples)
    assert (made > 1000) if samples else made == 0


def test_can_traffic_in_one_batch() -> None:
    records = can_records(20_000, 7)
    assert run_both([records]) > 5000


@pytest.mark.parametrize("seed", [1, 2])
def test_modbus_traffic(seed: int) -> None:
    rng = random.Random(seed)
    frames = list(modbus_frames(2000, seed=seed)) + modbus_extra(rng)
    rng.shuffle(frames)
    records = byte_records(MODBUS_RTU, frames, seed)
    assert {r.protocol for r in records if r.kind == FRAME} == {MODBUS_RTU}
    assert run_both(split(records, rng)) > 500


@pytest.mark.parametrize("seed", [1, 2])
def test_serial_traffic(seed: int) -> None:
    rng = random.Random(seed)
    frames = list(serial_frames(2000, seed=seed)) + serial_extra(rng)
    records = byte_records(EG2_SERIAL, frames, seed)
    assert {r.protocol for r in records if r.kind == FRAME} == {EG2_SERIAL}
    assert run_both(split(records, rng)) > 500


def test_openings_in_millimetres() -> None:
    """``derived``'s millimetres (a table for 0-1000, ``opening_mm`` elsewhere) for every
    opening a 16-bit field can hold, and negative ones: the serial position is folded as it
    comes, so the native rounding must equal Python's ``round(v * 70.0 / 1000.0, 2)``."""
    records = [
        Record(
            float(v),
            "s",
            EG2_SERIAL,
            FRAME,
            0,
            b"",
            direction=RESPONSE,
            device=1,
            code=Cmd.READ_ACTPOS,
            fields={"position": v},
            seq=v,
        )
        for v in range(-3000, 70_000)
    ]
    assert run_both([records[:1], records[1:]]) == len(records)


# -- generated records ----------------------------------------------------------------------------

NAMES = [r.name for r in REGISTERS] + ["REG_1008", "CMD_NOPE"]
ODD = st.one_of(
    st.none(), st.booleans(), st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=4)
)
INTS = st.one_of(
    st.integers(-3, 1100), st.sampled_from([-2001, 2001, 0x20, 65535, 2**40, -(2**62)])
)
VALUE = st.one_of(INTS, INTS, INTS, ODD)
REGISTER_FIELDS = st.one_of(
    st.fixed_dictionaries({"values": st.dictionaries(st.sampled_from(NAMES), VALUE, max_size=6)}),
    st.fixed_dictionaries({"name": st.one_of(st.sampled_from(NAMES), st.none()), "value": VALUE}),
    st.fixed_dictionaries({"values": st.one_of(st.none(), st.lists(INTS, max_size=2))}),
    st.just({}),
)
SERIAL_KEYS = ["speed", "force_g", "position", "max", "min", "state", "fault", "temperature_c",
               "force_setting_g", "other"]  # fmt: skip
SERIAL_FIELDS = st.dictionaries(st.sampled_from(SERIAL_KEYS), VALUE, max_size=5) | st.builds(
    lambda p: {"probable": p},
    st.one_of(
        st.dictionaries(st.sampled_from(["opening", "force", "force_threshold"]), VALUE),
        st.none(),
    ),
)
CODES = st.one_of(st.sampled_from([int(c) for c in Cmd]), st.none(), st.integers(-1, 300))


@st.composite
def records(draw: st.DrawFn) -> Record:
    protocol = draw(st.sampled_from([EG2_CAN, MODBUS_RTU, EG2_SERIAL, "can"]))
    serial = protocol == EG2_SERIAL
    return Record(
        t=draw(st.one_of(st.none(), st.floats(0, 2e9, allow_nan=False))),
        bus=draw(st.sampled_from(["can0", "can1", 'é"bus\n'])),
        protocol=protocol,
        kind=draw(st.sampled_from([FRAME, FRAME, FRAME, GARBAGE])),
        length=1,
        raw=b"\x01",
        direction=draw(st.sampled_from([REQUEST, RESPONSE, None])),
        device=draw(st.one_of(st.integers(0, 3), st.none())),
        code=draw(CODES) if serial else None,
        name=draw(st.one_of(st.none(), st.sampled_from(NAMES), st.just(""))),
        fields=draw(SERIAL_FIELDS if serial else REGISTER_FIELDS),
        errors=draw(st.sampled_from([[], [], [], ["bad checksum"]])),
        summary=draw(st.sampled_from(["", "", "read 8 bytes", "catch é\u0001"])),
        seq=draw(st.integers(-1, 10**12)),
        latency_ms=draw(st.one_of(st.none(), st.floats(0, 1e4, allow_nan=False))),
        flags=draw(st.sampled_from([[], [UNANSWERED], ["out_of_range", UNANSWERED]])),
    )


@SLOW
@given(batches=st.lists(st.lists(records(), max_size=12), max_size=6), samples=st.booleans())
def test_generated_records(batches: list[list[Record]], samples: bool) -> None:
    py, nat = Tracker(samples=samples), _native.Tracker(samples=samples)
    for batch in batches:
        want = py.update_many(batch)
        got = nat._update_records(batch)
        try:
            expected = [message(s) for s in want]
        except TypeError:
            # derived() cannot use a float or text state: the native messages() says so too
            with pytest.raises(TypeError):
                got.messages()
            assert list(got) == want
        else:
            assert got.messages() == expected
            assert_same_samples(want, got)
        assert list(nat.states) == list(py.states)
        for key, w in py.states.items():
            g = nat.states[key]
            assert (g.protocol, g.t, list(g.values.items())) == (
                w.protocol,
                w.t,
                list(w.values.items()),
            )


# -- the RecordBatch of CanStage -------------------------------------------------------------------


@pytest.mark.parametrize("samples", [True, False])
def test_live_can_batches(samples: bool) -> None:
    """Items through Decoding + Tracker against CanStage + the native Tracker, batch by batch
    (with ticks and a gap), as a live session runs them."""
    rng = random.Random(5)
    items = list(can_items(8000, 5))
    decoding, live = Decoding(), _native.CanStage()
    py, nat = Tracker(samples=samples), _native.Tracker(samples=samples)
    i = 0
    now = 0.0
    while i < len(items):
        n = rng.choice((1, 10, 300))
        chunk = items[i : i + n]
        i += n
        now = next((x.payload.t for x in reversed(chunk) if x.payload.t is not None), now)
        steps = [(decoding.feed_items(chunk), live.feed(chunk))]
        if rng.random() < 0.1:
            steps.append((decoding.tick(now + 1.0), live.tick(now + 1.0)))
        if rng.random() < 0.02:
            steps.append((decoding.gap("can1"), live.gap("can1")))
        for want_records, batch in steps:
            assert list(batch) == want_records
            assert_same_samples(py.update_many(want_records), nat.update_many(batch))
            assert_same_states(py, nat)
    want_records, batch = decoding.finish(), live.finish()
    assert_same_samples(py.update_many(want_records), nat.update_many(batch))
    assert_same_states(py, nat)


# -- the API --------------------------------------------------------------------------------------


def test_sample_batch_is_a_sequence() -> None:
    records = can_records(600, 11)
    want = Tracker().update_many(records)
    got = _native.Tracker()._update_records(records)
    n = len(want)
    assert n > 100
    assert got[0] is got[0] and got[-1] is got[n - 1]
    assert got[-1] == want[-1]
    assert got[3:40:5] == want[3:40:5] and got[::-7] == want[::-7] and got[5:2] == []
    assert got[3:40:5][0] is got[3]
    assert [s for s in got] == want  # the iterator
    assert all(a is b for a, b in zip(got, got[:], strict=True))
    it = iter(got)
    assert next(it) is got[0] and iter(it) is it
    for bad in (n, -n - 1):
        with pytest.raises(IndexError):
            got[bad]
    with pytest.raises(TypeError):
        got["x"]
    empty = _native.SampleBatch()
    assert len(empty) == 0 and list(empty) == [] and empty.messages() == []
    assert empty.times() == [] and empty.keys() == [] and empty[:] == []


def test_samples_attribute() -> None:
    nat = _native.Tracker()
    assert nat.samples is True and _native.Tracker(samples=False).samples is False
    records = can_records(400, 12)
    nat.samples = False
    assert len(nat._update_records(records)) == 0
    nat.samples = 1  # any truthy value, as the Python attribute takes
    assert nat.samples is True
    assert len(nat._update_records(records)) > 0
    py = Tracker()
    py.samples = False
    py.update_many(records)
    py.samples = True
    py.update_many(records)
    assert_same_states(py, nat)
    assert nat.states is not nat.states  # fresh objects every time


def test_threads_read_while_the_session_folds() -> None:
    """A listener thread reading states and samples while the session's thread folds: no
    PyO3 "already borrowed" errors, and every thread gets the same sample objects."""
    import threading

    records = can_records(3000, 13)
    batches = split(records, random.Random(13), most=60)
    nat = _native.Tracker()
    made: list[Any] = []
    errors: list[BaseException] = []
    done = threading.Event()

    def read() -> None:
        try:
            while not done.is_set():
                assert all(type(s) is DeviceState for s in nat.states.values())
                for batch in list(made):
                    assert [s for s in batch] == list(batch)  # the iterator
                    batch.messages()
        except BaseException as exc:  # reported below
            errors.append(exc)

    threads = [threading.Thread(target=read) for _ in range(2)]
    for t in threads:
        t.start()
    try:
        for batch in batches:
            made.append(nat._update_records(batch))
            made[-1][:]
    finally:
        done.set()
        for t in threads:
            t.join()
    assert errors == []
    py = Tracker()
    want = [py.update_many(batch) for batch in batches]
    for w, g in zip(want, made, strict=True):
        assert_same_samples(w, g)
    assert_same_states(py, nat)


# -- a frame with a value out of range sets no value at all -----------------------------------


def misread_frames() -> list[tuple[str, Item]]:
    """The manual's CAN reply read big endian (opening 59395 beside force 243), a Modbus read
    reply with the same two values, and a serial run state with position 3000 beside state 1,
    each after a valid reading of the same gripper, as a session hands them to the tracker."""
    can_ok = b.u16le(100, 500, 0, 30)
    can_bad = bytes.fromhex("F3 00 03 E8 00 00 00 22")  # 4.1.1: force 243, opening 59395
    modbus_ok, modbus_bad = [100, 500, 0, 30, 0, 1], [243, 59395, 0, 30, 0, 1]
    run_ok = bytes((1, 0, 40)) + b.u16le(500, 100)
    run_bad = bytes((2, 0, 40)) + b.u16le(3000, 100)
    s = b.serial_frame
    items: list[tuple[str, Item]] = []
    for t, (can_data, regs, run) in enumerate(
        ((can_ok, modbus_ok, run_ok), (can_bad, modbus_bad, run_bad))
    ):
        frames = (
            b.can_read_request(1, 1120, 8, t=float(t)),
            b.can_read_response(1, 1120, can_data, t=t + 0.001),
        )
        items += [(EG2_CAN, Item("can0", f)) for f in frames]
        for k, raw in enumerate(
            (b.modbus_read_request(1, 1060, 6), b.modbus_read_response(1, regs))
        ):
            items.append((MODBUS_RTU, Item("rs485", Chunk(raw, t + 0.002 + k / 1000))))
        for k, raw in enumerate(
            (s(1, Cmd.READ_EG_RUNSTATE), s(1, Cmd.READ_EG_RUNSTATE, run, True))
        ):
            items.append((EG2_SERIAL, Item("rs232", Chunk(raw, t + 0.004 + k / 1000))))
    return items


def test_a_frame_with_a_value_out_of_range_sets_none() -> None:
    """Both trackers fold the valid readings and none of a misread frame's: not the force
    beside the opening 59395, not the state beside the position 3000."""
    items = misread_frames()
    decoding = Decoding(per_bus={"rs485": MODBUS_RTU, "rs232": EG2_SERIAL})
    records = [r for _, item in items for r in decoding.feed(item)] + decoding.finish()
    bad = [r for r in records if "out_of_range" in r.flags]
    assert {r.protocol for r in bad} == {EG2_CAN, MODBUS_RTU, EG2_SERIAL}
    assert run_both([records[:3], records[3:]]) > 0
    py = Tracker()
    samples = py.update_many(records)
    bad_keys = {(r.bus, r.seq) for r in bad}
    noted = [set(x.changed) for x in samples if (x.bus, x.seq) in bad_keys]
    assert noted and all(c <= {"latency_ms", "last_command"} for c in noted)  # no reading
    for bus in ("can0", "rs485"):
        st = py.states[(bus, 1)].values
        assert (st["force"], st["opening"]) == (100, 500), bus
    serial = py.states[("rs232", 1)].values
    assert (serial["state"], serial["opening"]) == (1, 500)
