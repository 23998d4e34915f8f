"""The session core: one path for captures and live taps, guarded listeners, one state sample per
reading, and the recording's /state samples matching the decoded readings one for one."""

from __future__ import annotations

import gc
import io
import os
import threading
import time
import tty
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import orjson
import pytest
from recording.mcap_checks import assert_time_ordered

from analyzer.model import SourceEvent
from analyzer.recording.reader import read_events, read_records, read_states
from analyzer.recording.recorder import McapRecorder
from analyzer.session.capture import CaptureOptions, run_capture
from analyzer.session.listener import Listener, listener_class, make_listener
from analyzer.session.session import Session, SessionOptions, live_session
from analyzer.sinks.jsonl import JsonlListener
from analyzer.sinks.stats import StatsListener
from analyzer.sources.capture import open_capture
from analyzer.sources.serial_tap import SerialTap
from analyzer.sources.source import CaptureSource
from decoders import build as b
from decoders.model import Record
from decoders.registers import opening_mm

CAPTURES = Path(__file__).resolve().parents[2] / "captures"
SAMPLES = sorted(p.name for p in CAPTURES.iterdir() if p.suffix in (".bin", ".log"))


class Boom(Listener):
    """Fails on its third batch of records."""

    wants_states = True

    def __init__(self) -> None:
        self.batches = 0
        self.errors: list[BaseException] = []
        self.closed = 0

    def on_records(self, records: list[Record]) -> None:
        self.batches += 1
        if self.batches == 3:
            raise RuntimeError("listener bug")

    def on_error(self, exc: BaseException) -> None:
        self.errors.append(exc)

    def close(self) -> None:
        self.closed += 1


class Collect(Listener):
    wants_states = True

    def __init__(self) -> None:
        self.records: list[Record] = []
        self.samples: list = []
        self.events: list[SourceEvent] = []

    def on_records(self, records: list[Record]) -> None:
        self.records += records

    def on_states(self, samples: list) -> None:
        self.samples += samples

    def on_event(self, event: SourceEvent) -> None:
        self.events.append(event)


def opening_readings(records: list[Record]) -> list[tuple[int, int]]:
    """(seq, opening) of every valid record that reads the opening, in any protocol."""
    out = []
    for r in records:
        if not r.ok or r.direction != "response":
            continue
        values = r.fields.get("values") or {}
        if "CMD_OPENLEN_ACT" in values and 0 <= values["CMD_OPENLEN_ACT"] <= 1000:
            out.append((r.seq, values["CMD_OPENLEN_ACT"]))
        elif r.protocol == "eg2-serial" and "position" in r.fields:
            out.append((r.seq, r.fields["position"]))
        elif r.protocol == "eg2-serial" and (r.fields.get("probable") or {}).get("opening"):
            out.append((r.seq, r.fields["probable"]["opening"]))  # 0x14's likely layout
    return out


def test_a_failing_listener_is_detached_and_the_recording_completes(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    boom, collect = Boom(), Collect()
    recorder = McapRecorder(path, metadata={})
    opts = CaptureOptions(str(CAPTURES / "can_pick_place.log"), progress=False)
    with open_capture(opts.path) as reader:
        session = Session(CaptureSource(reader), [boom, recorder, collect])
        # small batches, so the failure comes in the middle of the capture
        session.source.batches = _small_batches(reader)  # type: ignore[method-assign]
        session.run()
    assert [type(e) for e in boom.errors] == [RuntimeError]
    assert boom.closed == 1 and boom not in session.listeners
    assert len(session.detached) == 1
    # reported once, as an event, to the listeners that stay
    failed = [e for e in collect.events if e.kind == "listener_failed"]
    assert len(failed) == 1 and "listener bug" in failed[0].message
    # the recording is complete: every record and the failure event
    assert len(list(read_records(path))) == len(collect.records) == 91
    assert any("listener bug" in e.message for e in read_events(path))
    assert_time_ordered(path)


def _small_batches(reader):  # type: ignore[no-untyped-def]
    def batches(stop: threading.Event):  # type: ignore[no-untyped-def]
        batch: list = []
        for x in reader:
            batch.append(x)
            if len(batch) == 10:
                yield batch
                batch = []
        yield batch

    return batches


@pytest.mark.parametrize("name", SAMPLES)
def test_one_state_sample_per_reading_reaches_the_recording(tmp_path: Path, name: str) -> None:
    path = tmp_path / f"{name}.mcap"
    collect = Collect()
    session, _ = run_capture(
        CaptureOptions(str(CAPTURES / name), progress=False),
        [collect, McapRecorder(path, metadata={})],
    )
    readings = opening_readings(collect.records)
    assert readings, "the sample capture reads the opening"
    samples = [(s.seq, s.changed["opening"]) for s in collect.samples if "opening" in s.changed]
    assert samples == readings
    states = list(read_states(path))
    recorded = [(d["seq"], d["opening"]) for d in states if "opening" in d["changed"]]
    assert recorded == readings  # one for one, each with its own record's time
    by_seq = {r.seq: r.t for r in collect.records}
    assert all(d["t"] == by_seq[d["seq"]] for d in states)
    assert session.counts.samples == len(states)
    assert_time_ordered(path)


def test_samples_are_snapshots_with_the_fields_each_record_set() -> None:
    collect = Collect()
    run_capture(CaptureOptions(str(CAPTURES / "can_pick_place.log"), progress=False), [collect])
    openings = [s for s in collect.samples if "opening" in s.changed]
    assert len({s.values["opening"] for s in openings}) > 1  # not all the last state
    for s in openings:
        assert s.values["opening"] == s.changed["opening"]
        d = s.to_dict()
        assert d["opening_mm"] == opening_mm(s.changed["opening"])
        assert "opening" in d["changed"] and d["device"] == s.device


def test_decode_and_stats_share_the_session_and_the_tracker_runs() -> None:
    out = io.BytesIO()
    stats = StatsListener()
    session, _ = run_capture(
        CaptureOptions(str(CAPTURES / "serial_session.bin"), progress=False),
        [JsonlListener(out), stats],
    )
    lines = out.getvalue().splitlines()
    assert len(lines) == stats.stats.records == session.counts.records
    assert session.tracker.states  # the Tracker ran although nobody read samples
    assert all("flags" in orjson.loads(line) for line in lines)


def test_listeners_are_found_by_name() -> None:
    assert listener_class("jsonl") is JsonlListener
    assert isinstance(make_listener("stats"), StatsListener)
    with pytest.raises(ValueError, match=r"unknown output 'nope'.*jsonl"):
        listener_class("nope")


def test_live_session_on_a_pty_gives_frames_their_own_times(tmp_path: Path) -> None:
    """Two frames that arrive in one read get times a byte-time apart, marked estimated."""
    master, slave = os.openpty()
    tty.setraw(slave)
    collect = Collect()
    session = live_session(
        [SerialTap("rs232", os.ttyname(slave), baudrate=9600)],
        [collect],
        byte_time_s={"rs232": 10 / 9600},
    )
    thread = threading.Thread(target=session.run, daemon=True)
    thread.start()
    time.sleep(0.4)
    request = b.serial_frame(1, 0xD9)
    response = b.serial_frame(1, 0xD9, b.u16le(500), response=True)
    os.write(master, request + response)  # one write: most likely one read on the tap side
    time.sleep(0.5)
    session.stop()
    thread.join(5)
    os.close(master)
    os.close(slave)
    frames = [r for r in collect.records if r.kind == "frame"]
    assert [r.direction for r in frames] == ["request", "response"]
    assert frames[1].latency_ms is not None and frames[1].latency_ms > 0
    assert frames[1].t is not None and frames[0].t is not None and frames[1].t > frames[0].t


def test_session_options_are_typed() -> None:
    options = SessionOptions(protocol="eg2-serial", duration=1.0)
    with pytest.raises(AttributeError):
        options.protocol = "x"  # type: ignore[misc]


def test_a_gap_decides_the_bytes_held_before_it_and_shows_in_place() -> None:
    """A port lost mid-frame: the frame before the gap is complete, the cut one is truncated,
    and the event comes after them and before what follows, as the replay of a recording shows."""
    from analyzer.model import WARNING, Item
    from analyzer.sources.source import Source
    from decoders.model import Chunk

    frame = b.serial_frame(1, 0xD9)
    batch = [
        Item("rs232", Chunk(frame + frame[:3], 1.0)),
        SourceEvent(1.1, "rs232", WARNING, "lost /dev/ttyUSB0", "lost"),
        Item("rs232", Chunk(frame, 2.0)),
    ]

    class Replay(Source):
        def batches(self, stop: threading.Event):  # type: ignore[no-untyped-def]
            yield batch

    out = io.BytesIO()
    Session(Replay(), [JsonlListener(out)], SessionOptions(protocol="eg2-serial")).run()
    kinds = [(d["kind"], d.get("offset")) for d in map(orjson.loads, out.getvalue().splitlines())]
    assert kinds == [("frame", 0), ("truncated", 6), ("event", None), ("frame", 9)]


def test_sessions_collect_garbage_rarely_and_restore_the_thresholds() -> None:
    """While any session runs the cyclic collector runs rarely (session.rare_gc). Sessions
    overlap (a TUI and a test, two threads): the first one to end must not put the thresholds
    back under the other; the last one does."""
    before = gc.get_threshold()
    a_in, b_in = threading.Event(), threading.Event()
    seen: list[tuple[int, int, int]] = []

    class Watch(Listener):
        def __init__(self, on_first: Any) -> None:
            self.on_first = on_first

        def on_records(self, records: Sequence[Record]) -> None:
            if self.on_first is not None:
                self.on_first()
                self.on_first = None
            seen.append(gc.get_threshold())

    def capture(on_first: Any) -> None:
        reader = open_capture(str(CAPTURES / "serial_session.bin"))
        with reader:
            Session(CaptureSource(reader), [Watch(on_first)]).run()

    def a_first() -> None:  # A waits until B runs, then ends
        a_in.set()
        assert b_in.wait(10)

    def b_first() -> None:  # B waits until A has ended, then reads the thresholds
        b_in.set()
        a.join(10)

    a = threading.Thread(target=capture, args=(a_first,))
    a.start()
    assert a_in.wait(10)
    capture(b_first)
    assert not a.is_alive()
    assert seen and all(x[0] == 100_000 for x in seen), seen
    assert gc.get_threshold() == before
