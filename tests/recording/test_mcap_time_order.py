"""One clock for the whole recording: log times never decrease in file order across all
channels (``mcap doctor --strict-message-order``), the exact ``t`` stays in every message, and
a byte stream is never reordered."""

from __future__ import annotations

import base64
import math
import random
from pathlib import Path

import orjson
from mcap.reader import make_reader
from mcap_checks import assert_time_ordered, mcap_messages

from analyzer.model import INFO, WARNING, Item, SourceEvent
from analyzer.recording.reader import McapCaptureReader, read_records
from analyzer.recording.recorder import McapRecorder
from analyzer.session.batches import PythonDecoding, PythonTracker, RecordSequence
from decoders import build as b
from decoders.model import CanFrame, Chunk

T0 = 1_763_700_000.0


def jittered_traffic(n: int, seed: int = 5) -> list[Item]:
    """Two buses stamped by different threads: their times interleave with up to 4 ms of
    jitter, so arrival order is not time order."""
    rng = random.Random(seed)
    items = []
    for i in range(n):
        t = T0 + i * 1e-3 + rng.uniform(-0.004, 0.004)
        if i % 4 == 1:
            items.append(Item("can0", b.can_read_request(1 + i % 3, 1120, 8, t=t)))
        elif i % 4 == 3:
            data = b.u16le(100, 500 + i % 400, 20, 34)
            items.append(Item("can0", b.can_read_response(1 + i % 3, 1120, data, t=t)))
        else:
            items.append(Item("ttyUSB0", Chunk(b.serial_frame(1, 0xD9), t, "request"), "tx"))
    return items


def record_session(path: Path, items: list[Item], batch: int = 40, **kw: object) -> None:
    """What a session does: per batch, raw input, records, state samples, events, a tick."""
    decoding, tracker = PythonDecoding(), PythonTracker()
    with McapRecorder(path, {}, **kw) as rec:  # type: ignore[arg-type]
        for k in range(0, len(items), batch):
            part = items[k : k + batch]
            rec.on_raw(part)
            records = RecordSequence(r for item in part for r in decoding.feed(item))
            rec.on_records(records)
            rec.on_states(tracker.update_many(records))
            if k % (5 * batch) == 0:
                t = part[0].payload.t or 0
                rec.on_event(SourceEvent(t - 0.01, "ttyUSB0", INFO, f"event {k}", "info"))
            rec.tick(0.0)
        records = decoding.finish()
        rec.on_records(records)
        rec.on_states(tracker.update_many(records))


def test_log_times_never_decrease_in_file_order(tmp_path: Path) -> None:
    path = tmp_path / "jitter.mcap"
    items = jittered_traffic(2000)
    record_session(path, items, chunk_size=2000)
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and len(summary.chunk_indexes) > 20
    topics = {ch.topic for ch in summary.channels.values()}
    assert {"/raw/can0", "/raw/ttyUSB0", "/decoded/can0", "/events/ttyUSB0"} <= topics
    assert any(t.startswith("/state/can0/") for t in topics)
    count = assert_time_ordered(path)
    assert count == sum(summary.statistics.channel_message_counts.values())  # type: ignore[union-attr]
    # the mcap library's own log-time order is the file order
    with path.open("rb") as f:
        by_time = [m.data for _s, _c, m in make_reader(f).iter_messages(log_time_order=True)]
    with path.open("rb") as f:
        by_file = [m.data for _s, _c, m in make_reader(f).iter_messages(log_time_order=False)]
    assert by_time == by_file


def test_exact_times_stay_in_the_messages(tmp_path: Path) -> None:
    path = tmp_path / "exact.mcap"
    items = jittered_traffic(400)
    record_session(path, items)
    raw = [m for m in mcap_messages(path) if m[0].startswith("/raw/")]
    # in arrival order, each with its own t, whatever its log time had to be
    assert [m[5]["t"] for m in raw] == [i.payload.t for i in items]
    assert [base64.b64decode(m[5]["data"]) for m in raw] == [i.payload.data for i in items]
    moved = [m for m in raw if m[4] != int(m[5]["t"] * 1e9)]
    assert moved, "jittered input must have needed some log times raised"
    assert all(m[4] > int(m[5]["t"] * 1e9) for m in moved)  # only ever later, never earlier


def test_a_batch_is_sorted_by_time_across_topics(tmp_path: Path) -> None:
    """Within a batch, each frame's /decoded record and /state sample come right after its
    /raw frame (same time), not after the whole batch's raw input."""
    path = tmp_path / "sorted.mcap"
    frames = []
    for k in range(50):
        t = T0 + k * 0.01
        frames.append(Item("can0", b.can_read_request(1, 1120, 8, t=t)))
        frames.append(Item("can0", b.can_read_response(1, 1120, b.u16le(0, k, 0, 30), t=t + 5e-4)))
    record_session(path, frames, batch=len(frames))
    topics = [m[0] for m in mcap_messages(path) if not m[0].startswith("/events/")]
    # each frame, then its record, then the state sample it made, frame after frame
    assert topics == ["/raw/can0", "/decoded/can0", "/state/can0/1"] * len(frames)
    # every raw frame is at its exact time: nothing had to be moved
    for topic, *_rest, log_time, msg in mcap_messages(path):
        if topic.startswith(("/raw/", "/decoded/", "/state/")):
            assert log_time == int(msg["t"] * 1e9), topic


def test_a_clock_stepping_back_never_reorders_a_stream(tmp_path: Path) -> None:
    """A serial stream whose wall clock steps back (NTP) mid-capture keeps its byte order: the
    recording replays exactly what arrived."""
    times = [T0 + 2, T0 + 1, T0 + 3, T0 + 0.5, T0 + 4]
    items = [Item("s", Chunk(bytes([i]) * 3, t)) for i, t in enumerate(times)]
    path = tmp_path / "back.mcap"
    with McapRecorder(path, {}) as rec:
        rec.on_raw(items[:3])
        rec.on_event(SourceEvent(T0 + 1.5, "s", WARNING, "clock stepped", "info"))
        rec.tick(0.0)
        rec.on_raw(items[3:])
    assert_time_ordered(path)
    with McapCaptureReader(path) as reader:
        got = [x for x in reader if isinstance(x, Item)]
        assert reader.errors == []
    assert got == items
    log_times = [m[4] for m in mcap_messages(path)]
    assert log_times == sorted(log_times)


def test_late_records_keep_their_time_in_the_message(tmp_path: Path) -> None:
    """A record decided later (a request found unanswered when the capture ends) is written
    after newer messages; its log time is raised, its t is the request's."""
    path = tmp_path / "late.mcap"
    request = Item("can0", b.can_read_request(1, 1120, 8, t=T0))
    later = [Item("can0", b.can_read_request(2, 1120, 8, t=T0 + 1 + k * 0.01)) for k in range(3)]
    decoding = PythonDecoding()
    with McapRecorder(path, {}) as rec:
        rec.on_raw([request])
        rec.on_records(RecordSequence(decoding.feed(request)))
        rec.tick(0.0)
        rec.on_raw(later)
        rec.on_records(RecordSequence(r for item in later for r in decoding.feed(item)))
        rec.tick(0.0)
        rec.on_records(decoding.finish())
    assert_time_ordered(path)
    records = list(read_records(path))
    assert sorted(r.t for r in records if r.t is not None)[0] == T0
    first = next(r for r in records if r.device == 1)
    assert first.t == T0 and any("no response" in w for w in first.warnings + first.errors)


def test_untimed_input_gets_the_wall_clock_in_order(tmp_path: Path) -> None:
    path = tmp_path / "untimed.mcap"
    with McapRecorder(path, {}) as rec:
        rec.on_raw([Item("s", Chunk(bytes([i]))) for i in range(5)])
        rec.tick(0.0)
        rec.on_raw([Item("c", CanFrame(None, 0x10, b"\x01"))])
    assert_time_ordered(path)
    msgs = mcap_messages(path)
    assert [orjson.loads(orjson.dumps(m[5]))["t"] for m in msgs] == [None] * 6
    assert msgs[0][4] > 1_700_000_000 * 10**9  # now, in nanoseconds


def test_nonsense_times_never_fail_the_recording(tmp_path: Path) -> None:
    """Times a capture may carry (negative, NaN, infinite, far future): the message keeps
    what JSON can say, the log time is pinned into MCAP's range, the file stays in order."""
    times = [T0, -5.0, float("nan"), T0 + 1, float("inf"), 1e30, 0.0, T0 + 2]
    items = [Item("s", Chunk(bytes([i]), t)) for i, t in enumerate(times)]
    path = tmp_path / "nonsense.mcap"
    with McapRecorder(path, {}) as rec:
        rec.on_raw(items)
        rec.on_event(SourceEvent(float("inf"), "s", INFO, "far away", "info"))
    assert_time_ordered(path)
    with McapCaptureReader(path) as reader:
        got = [x for x in reader if isinstance(x, Item)]
        assert reader.errors == []
    assert [i.payload.data for i in got] == [i.payload.data for i in items]  # order kept
    expected = [t if math.isfinite(t) else None for t in times]  # JSON has only null for those
    assert [i.payload.t for i in got] == expected
