"""The native decoding of one byte stream (``analyzer._native.ByteStage``, a session on a raw
serial or Modbus dump) against the Python ``analyzer.session.stage.Decoding`` it stands in for;
and ``_native.detect_protocol`` against ``decoders.registry.detect_protocol``.

The same chunks, ticks, gaps, cut-offs and end go through both; after every step both must give
the same records, by every means of looking at a ``RecordBatch`` (test_live_native.py's
``check_batch``: materialized records ==, types and JSON byte for byte, the bulk methods).

Inputs: realistic polling on RS232 and RS485 with garbage, bad checksums and CRCs, frames cut
short and retransmissions mixed in, fed whole, in random chunks and one byte at a time; the
protocol fixed, named for the bus, or detected (from the first 4096 bytes, or at the end of a
shorter stream, or by a tick once a frame shows); chunks with times and directions; the end by
``finish``, ``stop`` (a frame begun cut off, requests cut off), ``cut_off(bus)`` and
``gap(bus)``; and Hypothesis-generated streams and sessions. Skipped when the extension is not
built.
"""

from __future__ import annotations

import random
import sys
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from native_core import skip_or_fail, why_not

from analyzer.model import Item
from analyzer.session.stage import DETECT_BYTES, Decoding
from decoders import build as b
from decoders.model import EG2_SERIAL, MODBUS_RTU, CanFrame, Chunk, Record
from decoders.registry import detect_protocol

if why := why_not():
    skip_or_fail(why)

import test_live_native as lv  # after the check (tests/native is on sys.path)
import test_native_differential as diff
from analyzer._native import ByteStage, RecordBatch
from analyzer._native import detect_protocol as native_detect_protocol

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from traffic import modbus_frames, serial_frames

T0 = 1_763_700_000.0
BUS = {EG2_SERIAL: "serial", MODBUS_RTU: "rs485"}
Step = tuple[Any, ...]  # test_live_native's steps, and ("set_protocol", bus, protocol)


# -- running both -----------------------------------------------------------------------------


def run_both(
    steps: list[Step], protocol: str | None = None, positional: bool = True
) -> tuple[list[Record], RecordBatch]:
    """Every step through both; the records of each step compared; all of them returned
    (Python's list, and the native batches joined with +=)."""
    dec = Decoding(protocol, positional_seq=positional)
    stage = ByteStage(protocol, positional)
    everything: list[Record] = []
    joined = RecordBatch()
    for n, step in enumerate(steps):
        if step[0] == "set_protocol":
            dec.set_protocol(*step[1:])
            stage.set_protocol(*step[1:])
            continue
        want = lv.python_step(dec, step)
        batch = lv.native_step(stage, step)
        lv.check_batch(batch, want, f"step {n} {step[0]}")
        everything += want
        joined += batch
    assert joined.messages() == [lv.dumps(r) for r in everything]
    return everything, joined


def traffic(protocol: str, n: int, seed: int = 1) -> list[bytes]:
    """n frames of realistic polling."""
    frames = serial_frames if protocol == EG2_SERIAL else modbus_frames
    return list(frames(n, seed=seed))


def damaged(frames: list[bytes], seed: int = 1, tail: bool = True) -> bytes:
    """The frames with garbage, bad checksums or CRCs, frames cut short, retransmissions and
    lone header bytes among them; a frame cut short at the end (``tail``)."""
    rng = random.Random(seed)
    parts: list[bytes] = []
    for f in frames:
        roll = rng.random()
        if roll < 0.03:
            parts.append(rng.randbytes(rng.randint(1, 24)))  # noise
        elif roll < 0.06:
            f = f[:-1] + bytes([f[-1] ^ 0x5A])  # a bad checksum or CRC
        elif roll < 0.08:
            f = f[: rng.randint(1, len(f) - 1)]  # cut short
        elif roll < 0.09:
            parts.append(f)  # a retransmission
        elif roll < 0.10:
            parts.append(rng.choice([b"\xeb", b"\xeb\x90", b"\xee\x16", b"\x01\x03", b"\x00"]))
        parts.append(f)
    if tail:
        parts.append(frames[0][:3])
    return b"".join(parts)


def pieces(data: bytes, how: str, seed: int = 1) -> list[bytes]:
    """``data`` whole, in random chunks, or one byte at a time."""
    if how == "whole":
        return [data]
    if how == "bytes":
        return [data[i : i + 1] for i in range(len(data))]
    rng = random.Random(seed)
    out, i = [], 0
    while i < len(data):
        n = rng.choice([1, 2, 3, 5, 17, 64, 500, 1500, 4095, 4097])
        out.append(data[i : i + n])
        i += n
    return out


def chunks(
    data: bytes,
    how: str,
    bus: str = "serial",
    t0: float | None = None,
    step: float = 0.002,
    direction: str | None = None,
) -> list[Item]:
    """Items of ``data`` in pieces; timed from ``t0`` (None: no times), ``step`` apart."""
    out = []
    for i, piece in enumerate(pieces(data, how)):
        t = None if t0 is None else t0 + i * step
        out.append(Item(bus, Chunk(piece, t, direction)))
    return out


def feeds(items: list[Item], size: int = 50) -> list[Step]:
    """``items`` in feeds of ``size`` items."""
    return [("feed", items[i : i + size]) for i in range(0, len(items), size)]


def flags(records: list[Record]) -> set[str]:
    return {f for r in records for f in r.flags}


# -- whole streams ---------------------------------------------------------------------------


@pytest.mark.parametrize("how", ["whole", "random", "bytes"])
@pytest.mark.parametrize("fixed", [False, True], ids=["detected", "fixed"])
@pytest.mark.parametrize("protocol", [EG2_SERIAL, MODBUS_RTU])
def test_damaged_traffic_in_any_chunking(protocol: str, fixed: bool, how: str) -> None:
    data = damaged(traffic(protocol, 600 if how == "bytes" else 2000), seed=len(how))
    assert len(data) > DETECT_BYTES
    items = chunks(data, how, BUS[protocol])
    everything, _ = run_both([*feeds(items), ("finish",)], protocol if fixed else None)
    assert sum(len(r.raw) for r in everything) == len(data)  # every byte, once
    assert {r.protocol for r in everything} == {protocol}
    assert sum(1 for r in everything if r.pair is not None) > 100
    assert {"truncated", "garbage"} <= flags(everything)
    assert flags(everything) & {"bad_checksum", "bad_crc"}


@pytest.mark.parametrize("positional", [False, True])
def test_positional_seq(positional: bool) -> None:
    data = damaged(traffic(EG2_SERIAL, 600), seed=4)
    everything, _ = run_both([*feeds(chunks(data, "random")), ("finish",)], None, positional)
    offsets = [r.offset for r in everything]
    assert ([r.seq for r in everything] == offsets) is positional


def test_the_other_protocol_fixed() -> None:
    """Modbus bytes decoded as serial and the reverse: garbage and stray frames, the same."""
    for protocol, wrong in ((EG2_SERIAL, MODBUS_RTU), (MODBUS_RTU, EG2_SERIAL)):
        data = damaged(traffic(protocol, 300))
        run_both([*feeds(chunks(data, "random")), ("finish",)], wrong)


def test_garbage_only() -> None:
    """No protocol shows: the regular serial protocol is chosen, past 4096 bytes and at the
    end alike."""
    rng = random.Random(5)
    noise = bytes(rng.choice(b"\x00\x11\x22\x33\xff") for _ in range(9000))
    assert detect_protocol(noise) is None
    everything, _ = run_both([*feeds(chunks(noise, "random")), ("finish",)])
    assert {r.protocol for r in everything} == {EG2_SERIAL}
    short, _ = run_both([("feed", chunks(noise[:100], "whole")), ("finish",)])
    assert {r.kind for r in short} == {"garbage"}


@pytest.mark.parametrize("end", ["finish", "stop"])
@pytest.mark.parametrize("protocol", [EG2_SERIAL, MODBUS_RTU])
def test_short_stream_decided_at_the_end(protocol: str, end: str) -> None:
    """Fewer than 4096 bytes: held until the end, then detected and decoded."""
    data = damaged(traffic(protocol, 30))
    assert len(data) < DETECT_BYTES
    steps: list[Step] = feeds(chunks(data, "random"), 3)
    everything, _ = run_both([*steps, ("gap", "serial"), (end,)])
    assert {r.protocol for r in everything} == {protocol}
    # the stream was held until the end: nothing came out before it
    stage = ByteStage()
    assert sum(len(stage.feed(s[1])) for s in steps) == 0


def test_detection_at_the_threshold() -> None:
    """The chunk that brings the held bytes to 4096 decides; every chunk held is replayed."""
    data = damaged(traffic(MODBUS_RTU, 1000), tail=False)
    for cut in (DETECT_BYTES - 1, DETECT_BYTES, DETECT_BYTES + 1):
        items = [Item("rs485", Chunk(data[:cut])), Item("rs485", Chunk(data[cut : cut + 9]))]
        run_both([("feed", items[:1]), ("feed", items[1:]), ("finish",)])


def test_empty_chunks_and_no_input() -> None:
    run_both([("finish",)])
    run_both([("stop",)])
    run_both([("tick", T0), ("gap", "serial"), ("cut_off", "serial"), ("finish",)])
    empty = [Item("serial", Chunk(b"")), Item("serial", Chunk(b"", T0))]
    run_both([("feed", empty), ("tick", T0 + 1), ("finish",)])
    frame = b.serial_frame(1, 0x41)
    run_both([("feed", [*empty, Item("serial", Chunk(frame, T0)), *empty]), ("stop",)], EG2_SERIAL)


# -- the ends: finish, stop, cut_off, gap ----------------------------------------------------


def begun(protocol: str) -> tuple[bytes, bytes]:
    """A request never answered, and the first bytes of a frame."""
    if protocol == EG2_SERIAL:
        return b.serial_frame(1, 0x41), b.serial_frame(2, 0xD9)[:4]
    return b.modbus_read_request(1, 1061, 5), b.modbus_read_request(2, 1061, 5)[:5]


@pytest.mark.parametrize("detected", [False, True])
@pytest.mark.parametrize("protocol", [EG2_SERIAL, MODBUS_RTU])
def test_a_stop_cuts_off_the_frame_begun_and_the_request(protocol: str, detected: bool) -> None:
    lead = damaged(traffic(protocol, 600), tail=False)
    request, head = begun(protocol)
    bus = BUS[protocol]
    items = chunks(lead + request + head, "random", bus)
    everything, _ = run_both([*feeds(items), ("stop",), ("stop",)], None if detected else protocol)
    cut = everything[-1]
    assert cut.kind == "cut_off" and cut.raw == head and not cut.errors
    assert cut.flags == ["cut_off"]
    waiting = [r for r in everything if r.raw == request]
    assert waiting[-1].flags[-1] == "cut_off" and "unanswered" not in waiting[-1].flags
    # the same stream ended instead: the frame begun is truncated, the request unanswered
    ended, _ = run_both([*feeds(items), ("finish",)], protocol)
    assert ended[-1].kind == "truncated" and ended[-1].errors
    assert "unanswered" in [r for r in ended if r.raw == request][-1].flags


@pytest.mark.parametrize("protocol", [EG2_SERIAL, MODBUS_RTU])
def test_cut_off_and_gap_of_a_bus(protocol: str) -> None:
    """``cut_off`` and ``gap`` of the stream's bus decide what it holds (cut off, or damage);
    of another bus they do nothing; the stream goes on after them."""
    bus = BUS[protocol]
    request, head = begun(protocol)
    lead = damaged(traffic(protocol, 800), tail=False)
    more = damaged(traffic(protocol, 200, seed=3), tail=False)
    steps: list[Step] = [("feed", chunks(lead + request + head, "random", bus))]
    steps += [("cut_off", "other"), ("gap", "other"), ("cut_off", bus)]
    steps += [("feed", chunks(more + request + head, "random", bus)), ("gap", bus)]
    steps += [("feed", chunks(more + request + head, "random", bus)), ("cut_off", bus)]
    steps += [("feed", chunks(request + head, "whole", bus)), ("finish",), ("finish",)]
    everything, _ = run_both(steps)
    kinds = [r.kind for r in everything if r.raw == head and r.kind != "garbage"]
    assert kinds == ["cut_off", "truncated", "cut_off", "truncated"]
    assert any("no response before the source was lost" in r.warnings for r in everything)


@pytest.mark.parametrize("end", ["cut_off", "gap", "stop"])
def test_undetected_stream_at_a_cut_off_or_gap(end: str) -> None:
    """A stream still undetected: a cut-off or stop of its bus decides it; a gap leaves it
    held (as the Python does), and the end decides it."""
    request, head = begun(MODBUS_RTU)
    data = damaged(traffic(MODBUS_RTU, 20), tail=False) + request + head
    step: Step = (end,) if end == "stop" else (end, "rs485")
    run_both([("feed", chunks(data, "random", "rs485")), step, ("finish",)])


# -- times: ticks ----------------------------------------------------------------------------


@pytest.mark.parametrize("protocol", [EG2_SERIAL, MODBUS_RTU])
def test_ticks_decide_quiet_bytes_and_time_out_requests(protocol: str) -> None:
    """Timed chunks: a tick 0.1 s after the last read decides the bytes held (a frame begun is
    truncated), requests unanswered time out at 0.5 s."""
    bus = BUS[protocol]
    request, head = begun(protocol)
    lead = damaged(traffic(protocol, 1500), tail=False)
    items = chunks(lead, "random", bus, t0=T0)
    t = items[-1].payload.t
    assert t is not None
    steps: list[Step] = [*feeds(items), ("feed", [Item(bus, Chunk(request + head, t + 0.01))])]
    steps += [("tick", t + x) for x in (0.02, 0.05, 0.111, 0.2, 0.4, 0.52, 0.6, 3.0)]
    steps += [("feed", chunks(lead[:2000], "random", bus, t0=t + 4)), ("tick", t + 10)]
    steps += [("finish",)]
    everything, _ = run_both(steps, protocol)
    assert any(r.kind == "truncated" and r.raw == head for r in everything)
    assert any("no response within 500 ms" in r.warnings for r in everything)


def test_a_tick_detects_a_short_stream_once_a_frame_shows() -> None:
    """A live line slow to fill the detection sample is decided by a tick once it shows a
    frame; before that the tick holds it."""
    noise = b"\x00\x11\x22"
    request, head = begun(MODBUS_RTU)
    steps: list[Step] = [("feed", [Item("rs485", Chunk(noise, T0))]), ("tick", T0 + 1)]
    steps += [("feed", [Item("rs485", Chunk(request, T0 + 1.1))]), ("tick", T0 + 1.15)]
    steps += [("feed", [Item("rs485", Chunk(head, T0 + 1.2))]), ("tick", T0 + 1.4)]
    steps += [("tick", T0 + 2.0), ("finish",)]
    everything, _ = run_both(steps)
    assert {r.protocol for r in everything} == {MODBUS_RTU}


def test_times_that_go_back_or_are_missing() -> None:
    data = damaged(traffic(EG2_SERIAL, 1500))
    items = chunks(data, "random", t0=T0, step=0.05)
    rng = random.Random(8)
    for it in items:
        roll = rng.random()
        if roll < 0.2:
            it.payload.t = None
        elif roll < 0.3:
            it.payload.t = T0 - rng.random()  # back in time
    run_both([*feeds(items, 7), ("tick", T0 + 1e4), ("finish",)])


# -- directions and set_protocol -------------------------------------------------------------


def test_chunks_with_directions() -> None:
    """Each chunk says which wire it came from (a host's and a gripper's port)."""
    frames = traffic(EG2_SERIAL, 1200)
    items = [
        Item("serial", Chunk(f, T0 + i * 0.003, "request" if i % 2 == 0 else "response"))
        for i, f in enumerate(frames)
    ]
    items[7].payload.direction = "response"  # a request said to be an answer
    items[8].payload.direction = None
    run_both([*feeds(items, 33), ("finish",)])
    items = [Item("rs485", Chunk(f, None, "request")) for f in traffic(MODBUS_RTU, 300)]
    run_both([*feeds(items), ("finish",)], MODBUS_RTU)


def test_set_protocol() -> None:
    """A bus named after its protocol decodes with it, detected or not; naming another bus, or
    naming it after its bytes began, changes nothing until the stream would start over."""
    data = damaged(traffic(MODBUS_RTU, 800))
    items = chunks(data, "random", "rs485")
    run_both([("set_protocol", "rs485", EG2_SERIAL), *feeds(items), ("finish",)])
    run_both([("set_protocol", "other", EG2_SERIAL), *feeds(items), ("finish",)])
    run_both([("set_protocol", "rs485", EG2_SERIAL), *feeds(items), ("finish",)], MODBUS_RTU)
    run_both([*feeds(items[:1]), ("set_protocol", "rs485", EG2_SERIAL), *feeds(items[1:])])
    short = chunks(data[:300], "random", "rs485")
    steps: list[Step] = [*feeds(short[:2]), ("set_protocol", "rs485", EG2_SERIAL)]
    run_both([*steps, *feeds(short[2:]), ("finish",)])
    run_both([*steps, ("tick", T0), ("finish",)])


# -- what is refused -------------------------------------------------------------------------


def test_a_second_stream_is_refused() -> None:
    stage, dec = ByteStage(), Decoding(positional_seq=True)
    data = b.serial_frame(1, 0x41)
    first = [Item("serial", Chunk(data))]
    lv.check_batch(stage.feed(first), dec.feed_items(first), "first")
    for other in (Item("rs485", Chunk(data)), Item("serial", Chunk(data), stream="tx")):
        with pytest.raises(ValueError, match="one byte stream"):
            stage.feed([Item("serial", Chunk(data)), other])
    # nothing of a refused call was decoded: the stream goes on as if it had not been made
    run = [Item("serial", Chunk(data * 2000))]
    lv.check_batch(stage.feed(run), dec.feed_items(run), "after")
    lv.check_batch(stage.finish(), dec.finish(), "finish")


def test_refused_items_decode_nothing() -> None:
    good = [Item("serial", Chunk(b.serial_frame(1, 0x41) * 300))]
    bad: list[tuple[type[Exception], Any]] = [
        (TypeError, Item("serial", CanFrame(T0, 0x123, b"\x01"))),
        (TypeError, "not an item"),
        (TypeError, Item("serial", Chunk("text"))),  # type: ignore[arg-type]
        (TypeError, Item("serial", Chunk(b"\x01", 5))),  # an int time: the Python keeps the int
        (TypeError, Item(1, Chunk(b"\x01"))),  # type: ignore[arg-type]
        (ValueError, Item("serial", Chunk(b"\x01", T0, "sideways"))),
    ]
    for error, x in bad:
        stage = ByteStage(EG2_SERIAL)
        with pytest.raises(error):
            stage.feed([*good, x])
        assert len(stage.finish()) == 0, x
    with pytest.raises(TypeError, match="Chunk"):
        ByteStage().feed([Item("can0", CanFrame(T0, 0x123, b""))])


def test_data_as_any_buffer() -> None:
    """bytearray and memoryview data are read as bytes (the Python decoders take any buffer)."""
    frames = traffic(EG2_SERIAL, 200)
    items = []
    for i, f in enumerate(frames):
        data: Any = f if i % 3 == 0 else bytearray(f) if i % 3 == 1 else memoryview(f)
        items.append(Item("serial", Chunk(data, T0 + i)))
    run_both([("feed", items), ("finish",)], EG2_SERIAL)


def test_protocols_refused() -> None:
    with pytest.raises(Exception, match="not a byte-stream protocol"):
        ByteStage("eg2-can")
    with pytest.raises(Exception, match="not a byte-stream protocol"):
        ByteStage().set_protocol("serial", "nonsense")


# -- detect_protocol -------------------------------------------------------------------------


def samples(seed: int) -> list[bytes]:
    """Heads of lines: either protocol, both, damaged, noise, cut anywhere."""
    rng = random.Random(seed)
    serial, modbus = traffic(EG2_SERIAL, 300, seed), traffic(MODBUS_RTU, 300, seed)
    out = [b"", b"\xeb\x90", rng.randbytes(64), rng.randbytes(5000)]
    for _ in range(12):
        mix = [*rng.sample(serial, 20), *rng.sample(modbus, rng.randint(0, 30))]
        rng.shuffle(mix)
        data = damaged(mix, rng.randint(0, 1000))
        out += [data, data[rng.randint(0, len(data)) :], data[: rng.randint(0, len(data))]]
    return out


@pytest.mark.parametrize("seed", range(5))
def test_detect_protocol(seed: int) -> None:
    for sample in samples(seed):
        assert native_detect_protocol(sample) == detect_protocol(sample), sample.hex()


@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(diff.byte_stream(), st.binary(max_size=300)))
def test_generated_detect_protocol(sample: bytes) -> None:
    assert native_detect_protocol(sample) == detect_protocol(sample)


# -- Hypothesis ------------------------------------------------------------------------------


@st.composite
def sessions(draw: st.DrawFn) -> tuple[list[Step], str | None, bool]:
    """A session on one stream: generated bytes (after realistic traffic past the detection
    sample, or not) cut into chunks with times (all, none, some) and directions, with ticks,
    gaps, cut-offs and a bus named after its protocol among the feeds, and an end."""
    protocol = draw(st.sampled_from([None, None, EG2_SERIAL, MODBUS_RTU]))
    data = draw(diff.byte_stream())
    if draw(st.booleans()):
        kind = draw(st.sampled_from([EG2_SERIAL, MODBUS_RTU]))
        data = damaged(traffic(kind, 500, seed=draw(st.integers(0, 9)))) + data
    bus = draw(st.sampled_from(["serial", "rs485"]))
    timed = draw(st.sampled_from(["all", "none", "some"]))
    steps: list[Step] = []
    if draw(st.booleans()):
        steps.append(("set_protocol", bus, draw(st.sampled_from([EG2_SERIAL, MODBUS_RTU]))))
    t, i = T0, 0
    while i < len(data):
        op = draw(st.sampled_from(["feed"] * 6 + ["tick", "gap", "cut_off", "set_protocol"]))
        if op == "feed":
            items = []
            for _ in range(draw(st.integers(1, 5))):
                n = draw(st.sampled_from([1, 2, 3, 8, 40, 700, 5000]))
                t += draw(st.sampled_from([0.0, 0.0005, 0.002, 0.05, 0.15, 0.6, 2.5]))
                when = t if timed == "all" or (timed == "some" and draw(st.booleans())) else None
                way = draw(st.sampled_from([None, None, "request", "response"]))
                items.append(Item(bus, Chunk(data[i : i + n], when, way)))
                i += n
            steps.append(("feed", items))
        elif op == "tick":
            steps.append(("tick", t + draw(st.sampled_from([0.0, 0.05, 0.11, 0.6, 2.1]))))
        elif op == "set_protocol":
            steps.append(("set_protocol", bus, draw(st.sampled_from([EG2_SERIAL, MODBUS_RTU]))))
        else:
            steps.append((op, draw(st.sampled_from([bus, "other"]))))
    steps.append((draw(st.sampled_from(["finish", "stop", "tick"])), t + 5))
    return steps, protocol, draw(st.booleans())


@settings(max_examples=200, suppress_health_check=[HealthCheck.too_slow])
@given(sessions())
def test_generated_sessions(session: tuple[list[Step], str | None, bool]) -> None:
    steps, protocol, positional = session
    run_both(steps, protocol, positional)
