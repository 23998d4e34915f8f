"""A session on CAN input decodes and tracks with the native core
(``analyzer/session/batches.py``): the same listener calls, records, state samples, JSONL and
MCAP messages as with the Python engine (a session on one byte stream: test_byte_session.py).
Each test runs one input through a session twice, ``engine="python"`` and ``engine="native"``."""

from __future__ import annotations

import random
import sys
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from native_core import needs_native

from analyzer.model import ERROR, Item, SourceEvent, StateSample
from analyzer.recording.recorder import McapRecorder
from analyzer.session.batches import NativeByteDecoding, NativeCanDecoding, session_engine
from analyzer.session.listener import Listener
from analyzer.session.session import Session, SessionOptions
from analyzer.session.stage import Decoding
from analyzer.sources.capture import CanLogReader
from analyzer.sources.source import CaptureSource, Source
from decoders.model import CanFrame, Record

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests" / "benchmarks"))
from traffic import can_frames  # noqa: E402

T0 = 1_700_000_000.0  # long past: every tick expires whatever waits, on both engines alike


class Collect(Listener):
    """Every call a session makes, as plain data."""

    wants_states = True
    wants_raw = True

    def __init__(self) -> None:
        self.calls: list[tuple[str, Any]] = []

    def on_records(self, records: Sequence[Record]) -> None:
        self.calls.append(("records", list(records)))

    def on_states(self, samples: Sequence[StateSample]) -> None:
        self.calls.append(("states", list(samples)))

    def on_raw(self, items: list[Item]) -> None:
        self.calls.append(("raw", list(items)))

    def on_event(self, event: SourceEvent) -> None:
        self.calls.append(("event", event))


class Batches(Source):
    """A live source giving fixed batches (items and events), as LiveSource would."""

    live = True
    kind = "can"

    def __init__(self, batches: list[list[Any]]) -> None:
        self._batches = batches

    def batches(self, stop: threading.Event) -> Iterator[list[Any]]:
        yield from self._batches


def traffic(n: int, seed: int = 1, untimed: bool = True) -> list[Item]:
    """Realistic polling on two buses, with the frames real buses also carry: foreign and
    standard ids, error and remote frames, a reply that never came, frames with no time."""
    rng = random.Random(seed)
    items: list[Item] = []
    for k, f in enumerate(can_frames(n, seed=seed, t0=T0)):
        bus = "can0" if k % 7 else "can1"
        roll = rng.random()
        if roll < 0.02:
            continue  # a lost reply: its request goes unanswered
        if roll < 0.04:
            f = CanFrame(
                f.t, rng.getrandbits(11), bytes(rng.getrandbits(8) for _ in range(3)), False
            )
        elif roll < 0.05:
            f = CanFrame(f.t, 0x20000004, bytes(8), is_error=True)
        elif roll < 0.06:
            f = CanFrame(f.t, f.arbitration_id, b"", is_remote=True, dlc=4)
        elif roll < 0.07 and untimed:
            f = CanFrame(None, f.arbitration_id, f.data)
        items.append(Item(bus, f))
    return items


def run(source: Source, engine: str, *listeners: Listener) -> Session:
    session = Session(source, list(listeners), SessionOptions(engine=engine))
    session.run()
    return session


def in_batches(items: list[Any], size: int) -> list[list[Any]]:
    return [items[i : i + size] for i in range(0, len(items), size)]


def mcap_messages(path: Path) -> list[tuple[str, int, bytes]]:
    with path.open("rb") as f:
        return [
            (channel.topic, message.log_time, message.data)
            for _, channel, message in make_reader(f).iter_messages(log_time_order=False)
        ]


@needs_native
def test_auto_uses_the_native_core_for_can_input_and_one_byte_stream() -> None:
    decoding, tracker = session_engine("auto", "can", False)
    assert isinstance(decoding, NativeCanDecoding)
    assert type(tracker).__module__ == "analyzer._native"
    decoding, tracker = session_engine("auto", "bytes", True, "modbus-rtu")  # a raw dump
    assert isinstance(decoding, NativeByteDecoding)
    assert type(tracker).__module__ == "analyzer._native"
    assert isinstance(session_engine("native", "bytes", True)[0], NativeByteDecoding)
    # several byte streams (recordings, live taps), or a line's protocol or byte time named
    for kind, positional, per_bus, byte_time_s in [
        ("bytes", False, None, None),
        ("mixed", False, None, None),
        ("mixed", True, None, None),
        ("bytes", True, {"rs232": "eg2-serial"}, None),
        ("bytes", True, None, {"rs232": 1e-4}),
    ]:
        args = (kind, positional, None, per_bus, byte_time_s)
        assert isinstance(session_engine("auto", *args)[0], Decoding)
        with pytest.raises(ValueError, match="CAN input and single byte streams"):
            session_engine("native", *args)
    assert isinstance(session_engine("python", "can", False)[0], Decoding)
    assert isinstance(session_engine("python", "bytes", True)[0], Decoding)


@needs_native
@pytest.mark.parametrize("size", [1, 37, 600])
def test_live_session_same_calls_on_both_engines(size: int) -> None:
    items = traffic(3000)
    gap = SourceEvent(T0 + 1, "can1", ERROR, "can1 lost", "lost")
    batches_ = [*in_batches(items[:1500], size), [gap], *in_batches(items[1500:], size)]
    python, native = Collect(), Collect()
    p = run(Batches(batches_), "python", python)
    n = run(Batches(batches_), "native", native)
    assert isinstance(n.decoding, NativeCanDecoding)
    assert native.calls == python.calls
    assert n.counts == p.counts
    assert {k: (s.t, s.values) for k, s in n.tracker.states.items()} == {
        k: (s.t, s.values) for k, s in p.tracker.states.items()
    }


@needs_native
def test_recording_is_the_same_on_both_engines(tmp_path: Path) -> None:
    # (frames without a time are logged at the wall clock: not the same in two runs)
    batches_ = in_batches(traffic(4000, seed=2, untimed=False), 500)
    for engine in ("python", "native"):
        run(Batches(batches_), engine, McapRecorder(tmp_path / f"{engine}.mcap"))
    messages = mcap_messages(tmp_path / "native.mcap")
    assert messages == mcap_messages(tmp_path / "python.mcap")
    topics = {topic.split("/")[1] for topic, _, _ in messages}
    assert topics == {"raw", "decoded", "state", "events"}


@needs_native
def test_can_capture_decodes_the_same_on_both_engines(tmp_path: Path) -> None:
    log = tmp_path / "bus.log"
    lines = [
        f"({f.t:.6f}) can0 {f.arbitration_id:08X}#{f.data.hex().upper()}"
        for f in can_frames(5000, seed=5, t0=T0)
    ]
    lines[100] = "(not a line)"
    log.write_text("\n".join(lines) + "\n")
    outputs = []
    for engine in ("python", "native"):
        got = Collect()
        with CanLogReader(log) as reader:
            run(CaptureSource(reader), engine, got)
        outputs.append(got.calls)
    assert outputs[1] == outputs[0]
    assert sum(len(x) for kind, x in outputs[0] if kind == "records") >= 4999
