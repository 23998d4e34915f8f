"""MCAP recording: what McapRecorder (a session listener) writes, read back with the mcap
library and with this project's readers; the recorder inside a real session."""

from __future__ import annotations

import base64
import importlib.util
from pathlib import Path

import orjson
import pytest
from mcap.reader import make_reader
from mcap_checks import assert_time_ordered, mcap_messages

from analyzer import __version__
from analyzer.errors import UsageError
from analyzer.model import ERROR, INFO, WARNING, Item, SourceEvent, StateSample
from analyzer.recording import layout, recovery
from analyzer.recording.reader import (
    McapCaptureReader,
    read_events,
    read_metadata,
    read_records,
    read_states,
)
from analyzer.recording.recorder import McapRecorder
from analyzer.session.batches import RecordSequence, SampleSequence
from analyzer.session.listener import Listener, make_listener
from analyzer.session.session import Session
from analyzer.session.stage import Decoding
from analyzer.session.tracker import Tracker
from analyzer.sources.capture import open_capture
from analyzer.sources.source import CaptureSource
from decoders import build as b
from decoders.model import CanFrame, Chunk, Record

T0 = 1_763_700_000.0
META = {
    "sources": [{"bus": "can0", "interface": "socketcan", "bitrate": 500000}],
    "passive": "yes",
    "note": "bench 3",
}


def sample_items() -> list[Item]:
    """Serial chunks on two streams with directions, CAN frames of every flavour, times in
    order, one chunk without a time."""
    return [
        Item("ttyUSB0", Chunk(b.serial_frame(1, 0x41), T0 + 0.001, "request"), "tx"),
        Item("can0", CanFrame(T0 + 0.002, 0x123, b"\x01\x02", is_extended=False)),
        Item("ttyUSB0", Chunk(b"\x00\xff\xeb", T0 + 0.003, "response"), "rx"),
        Item("can0", CanFrame(T0 + 0.004, 0x1ABCDEF0, bytes(range(8)), is_extended=True)),
        Item("can0", CanFrame(T0 + 0.005, 0x7FF, b"", is_extended=False, is_remote=True, dlc=4)),
        Item("can0", CanFrame(T0 + 0.006, 0x20000080, b"\x00" * 8, is_error=True, channel="0")),
        Item("can1", CanFrame(T0 + 0.007, 0x42, bytes(range(12)), is_fd=True)),
        Item("ttyUSB0", Chunk(b"\x01\x02", T0 + 0.008), ""),
        Item("rs485", Chunk(b"\x10\x20\x30", None), ""),
    ]


def record(seq: int, **kw: object) -> Record:
    base: dict[str, object] = dict(
        t=T0 + seq / 1000,
        bus="can0",
        protocol="eg2-can",
        kind="frame",
        length=4,
        raw=b"\x01\x02\x03\x04",
        index=seq,
        direction="request",
        device=1,
        code=1,
        name="CMD_OPENLEN_SET",
        fields={"address": 0x10, "value": 500},
        summary="set",
        seq=seq,
    )
    base.update(kw)
    return Record(**base)  # type: ignore[arg-type]


def sample_records() -> list[Record]:
    return [
        record(0),
        record(1, direction="response", errors=["bad CRC: expected 1234"], flags=["bad_checksum"]),
        record(2, warnings=["no response within 50 ms"], flags=["unanswered"], device=None),
    ]


def opening_reading(seq: int, t: float, opening: int) -> Record:
    return Record(
        t=t,
        bus="can0",
        protocol="eg2-can",
        kind="frame",
        length=2,
        raw=opening.to_bytes(2, "little"),
        direction="response",
        device=1,
        name="CMD_OPENLEN_ACT",
        fields={"address": 0x46, "values": {"CMD_OPENLEN_ACT": opening}},
        seq=seq,
    )


def sample_states() -> list[StateSample]:
    """Two readings of one gripper, from the real Tracker: one sample each."""
    tracker = Tracker()
    readings = [opening_reading(10, T0 + 0.010, 300), opening_reading(11, T0 + 0.011, 300)]
    samples = tracker.update_many(readings)
    assert len(samples) == 2
    return samples


@pytest.fixture
def recorded(tmp_path: Path) -> Path:
    """One recording made through the listener calls, as a session makes them."""
    path = tmp_path / "run.mcap"
    with McapRecorder(path, META) as rec:
        rec.on_raw(sample_items())
        rec.on_records(RecordSequence(sample_records()))
        rec.on_states(SampleSequence(sample_states()))
        rec.on_event(SourceEvent(T0 + 0.02, "can0", WARNING, "dropped 3 frames", "drops"))
        rec.on_event(SourceEvent(T0 + 0.03, "ttyUSB0", INFO, "port reopened", "reopened", 7))
        rec.write_mark(T0 + 0.04, "gripper slipped", 11)
        rec.tick(T0)  # one batch: sorted by time, the untimed chunk (wall clock) last
    assert_time_ordered(path)
    return path


def test_recorder_is_a_listener_found_by_name(tmp_path: Path) -> None:
    rec = make_listener("mcap", tmp_path / "x.mcap", metadata={"passive": "yes"})
    try:
        assert isinstance(rec, McapRecorder) and isinstance(rec, Listener)
        assert rec.wants_raw and rec.wants_states
    finally:
        rec.close()
    # the per-item writers are gone: a session calls the listener hooks with whole batches
    for dead in ("write_item", "write_items", "write_record", "write_records", "write_state"):
        assert not hasattr(McapRecorder, dead), dead


def test_reader_and_writer_live_side_by_side(recorded: Path) -> None:
    for gone in ("analyzer.sinks.mcap", "analyzer.sources.mcap_reader", "analyzer.recording.mcap"):
        assert importlib.util.find_spec(gone) is None, gone
    with open_capture(recorded) as reader:
        assert type(reader) is McapCaptureReader
    assert McapRecorder.__module__ == "analyzer.recording.recorder"
    assert McapCaptureReader.__module__ == "analyzer.recording.reader"


def test_layout_topics_schemas_encodings(recorded: Path) -> None:
    msgs = mcap_messages(recorded)
    topics = {m[0]: (m[1], m[2], m[3]) for m in msgs}
    assert topics == {
        "/raw/ttyUSB0": ("eg2scope.RawChunk", "jsonschema", "json"),
        "/raw/can0": ("eg2scope.CanFrame", "jsonschema", "json"),
        "/raw/can1": ("eg2scope.CanFrame", "jsonschema", "json"),
        "/raw/rs485": ("eg2scope.RawChunk", "jsonschema", "json"),
        "/decoded/can0": ("eg2scope.Record", "jsonschema", "json"),
        "/state/can0/1": ("eg2scope.DeviceState", "jsonschema", "json"),
        "/events/can0": ("foxglove.Log", "jsonschema", "json"),
        "/events/ttyUSB0": ("foxglove.Log", "jsonschema", "json"),
        "/marks": ("eg2scope.Mark", "jsonschema", "json"),
    }
    with recorded.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    for schema in summary.schemas.values():
        js = orjson.loads(schema.data)
        assert js["type"] == "object" and js["title"] == schema.name
        for name, prop in js["properties"].items():
            assert "type" in prop or "oneOf" in prop, (schema.name, name)
    raw = next(orjson.loads(s.data) for s in summary.schemas.values() if s.name.endswith("Chunk"))
    assert raw["properties"]["data"] == {"type": "string", "contentEncoding": "base64"}
    for ch in summary.channels.values():
        if ch.topic != "/marks":
            assert ch.metadata["bus"] in ch.topic


def test_every_key_written_is_in_its_schema(recorded: Path) -> None:
    """Foxglove reads the schema to offer plot paths: no key may be missing from it."""
    with recorded.open("rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            assert schema is not None
            props = orjson.loads(schema.data)["properties"]
            keys = set(orjson.loads(message.data))
            assert keys <= set(props), (channel.topic, keys - set(props))


def test_raw_messages_match_items(recorded: Path) -> None:
    raw = [m for m in mcap_messages(recorded) if m[0].startswith("/raw/")]
    items = sample_items()
    assert len(raw) == len(items)
    for (topic, _sn, _se, _me, log_time, msg), item in zip(raw, items, strict=True):
        p = item.payload
        assert topic == "/raw/" + item.bus
        assert msg["t"] == p.t
        assert base64.b64decode(msg["data"]) == p.data
        if p.t is not None:
            assert log_time == int(p.t * 1e9)
        if isinstance(p, CanFrame):
            assert (msg["id"], msg["extended"], msg["remote"], msg["error"], msg["fd"]) == (
                p.arbitration_id,
                p.is_extended,
                p.is_remote,
                p.is_error,
                p.is_fd,
            )
            assert msg["dlc"] == p.length and msg["channel"] == p.channel
        else:
            assert (msg["stream"], msg["direction"]) == (item.stream, p.direction)


def test_decoded_state_event_and_mark_messages(recorded: Path) -> None:
    msgs = mcap_messages(recorded)
    decoded = [m[5] for m in msgs if m[0] == "/decoded/can0"]
    assert decoded == [orjson.loads(orjson.dumps(r.to_dict())) for r in sample_records()]
    assert decoded[1]["flags"] == ["bad_checksum"]
    states = [m for m in msgs if m[0] == "/state/can0/1"]
    # one message per sample, each at its own record's time, the sample's whole state
    assert [(log_time, st) for *_, log_time, st in states] == [
        (int(s.t * 1e9), orjson.loads(orjson.dumps(s.to_dict()))) for s in sample_states()
    ]
    for *_, st in states:
        # the Foxglove plot path /state/can0/1.opening_mm: a top-level number
        assert isinstance(st["opening_mm"], float) and st["opening"] == 300
        assert st["changed"] == ["opening"] and st["seq"] in (10, 11)
    logs = [(m[0], m[4], m[5]) for m in msgs if m[0].startswith("/events/")]
    # two records with problems (error, then warning) and the two source events
    assert [(topic, d["level"], d["name"], d["count"]) for topic, _, d in logs] == [
        ("/events/can0", ERROR, "decode", 1),
        ("/events/can0", WARNING, "decode", 1),
        ("/events/can0", WARNING, "drops", 1),
        ("/events/ttyUSB0", INFO, "reopened", 7),
    ]
    for _topic, log_time, d in logs:
        assert set(d) == {"timestamp", "level", "message", "name", "file", "line", "count"}
        ts = d["timestamp"]
        assert set(ts) == {"sec", "nsec"} and 0 <= ts["nsec"] < 1_000_000_000
        assert ts["sec"] * 1_000_000_000 + ts["nsec"] == log_time
        assert isinstance(d["file"], str) and isinstance(d["line"], int)
    assert logs[0][2]["message"] == "ID 1 set: bad CRC: expected 1234"
    assert logs[0][2]["line"] == 1  # the record's seq
    assert logs[2][2]["message"] == "dropped 3 frames"
    marks = [(m[4], m[5]) for m in msgs if m[0] == "/marks"]
    assert marks == [
        (int((T0 + 0.04) * 1e9), {"t": T0 + 0.04, "name": "gripper slipped", "seq": 11})
    ]


def test_metadata_record(recorded: Path) -> None:
    with recorded.open("rb") as f:
        metas = list(make_reader(f).iter_metadata())
    assert [m.name for m in metas] == ["eg2scope"]
    meta = metas[0].metadata
    assert all(isinstance(v, str) for v in meta.values())
    assert meta["tool"] == "eg2scope" and meta["version"] == __version__
    assert meta["passive"] == "yes"
    assert orjson.loads(meta["sources"]) == META["sources"]
    decoded = read_metadata(recorded)
    assert decoded["sources"] == META["sources"] and decoded["passive"] == "yes"


def test_capture_reader_yields_items_and_source_events(
    recorded: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def no_stream(*_a: object) -> None:
        raise AssertionError("an intact file must be read through its index")

    monkeypatch.setattr(recovery.Scan, "_streamed", no_stream)
    items = sample_items()
    events = [
        SourceEvent(T0 + 0.02, "can0", WARNING, "dropped 3 frames", "drops"),
        SourceEvent(T0 + 0.03, "ttyUSB0", INFO, "port reopened", "reopened", 7),
    ]
    # the untimed chunk was stamped with the wall clock: last; the records' problems ("decode")
    # are not source events (decoding the raw input again finds them again)
    expected = [*items[:-1], *events, items[-1]]
    with open_capture(recorded) as reader:
        assert isinstance(reader, McapCaptureReader)
        assert reader.kind == "mixed" and not reader.damaged
        assert reader.metadata["passive"] == "yes"
        got = list(reader)
        assert reader.errors == []
        assert reader.position == reader.size
    assert got == expected
    # one name for several buses would merge them: refused, naming them
    with pytest.raises(UsageError, match=r"recording of 4 buses \(can0, can1, rs485, ttyUSB0\)"):
        McapCaptureReader(recorded, bus="x")


def test_records_events_states_read_back(recorded: Path) -> None:
    errors: list[str] = []
    recs = list(read_records(recorded, errors))
    assert [r.to_dict() for r in recs] == [r.to_dict() for r in sample_records()]
    events = list(read_events(recorded, errors))
    assert [(e.bus, e.level, e.kind, e.count) for e in events] == [
        ("can0", ERROR, "decode", 1),
        ("can0", WARNING, "decode", 1),
        ("can0", WARNING, "drops", 1),
        ("ttyUSB0", INFO, "reopened", 7),
    ]
    assert events[2] == SourceEvent(T0 + 0.02, "can0", WARNING, "dropped 3 frames", "drops")
    states = list(read_states(recorded, errors))
    assert [s["opening"] for s in states] == [300, 300]
    assert errors == []


def test_redecoding_a_recording_gives_the_same_records(tmp_path: Path) -> None:
    serial = b"".join(
        [
            b.serial_frame(1, 0x41),
            b.serial_frame(1, 0x41, b"\x01\x00\x20\x2c\x01\x64\x00", True),
            b"\x55\xaa",
            b.serial_frame(2, 0xD9),
            b.serial_frame(2, 0xD9, b"\x2c\x01", True),
        ]
        * 30
    )
    items = [
        Item("ttyS0", Chunk(serial[i : i + 7], T0 + i * 1e-4)) for i in range(0, len(serial), 7)
    ]
    for k in range(40):
        t = T0 + 0.05 + k * 1e-3
        items.append(Item("can0", b.can_read_request(1, 0x46, 2, t=t)))
        items.append(Item("can0", b.can_read_response(1, 0x46, b"\x2c\x01", t=t + 2e-4)))
    items.sort(key=lambda i: i.payload.t or 0)
    path = tmp_path / "re.mcap"
    with McapRecorder(path, {}) as rec:
        for k in range(0, len(items), 50):  # in batches, as a session gives them
            rec.on_raw(items[k : k + 50])
            rec.tick(0.0)
    assert_time_ordered(path)
    direct = [r.to_dict() for r in Decoding().feed_many(items)]
    with McapCaptureReader(path) as reader:
        again = [r.to_dict() for r in Decoding().feed_many(reader)]  # type: ignore[arg-type]
    assert len(direct) > 100
    assert again == direct


def test_topic_names_for_awkward_bus_names(tmp_path: Path) -> None:
    assert layout.topic_part("/dev/ttyUSB0") == "dev/ttyUSB0"
    assert layout.topic_part("rfc2217://host:4000") == "rfc2217/host_4000"
    assert layout.topic_part("COM3") == "COM3"
    path = tmp_path / "names.mcap"
    with McapRecorder(path, {}, compression="none") as rec:
        rec.on_raw([Item("/dev/ttyUSB0", Chunk(b"\x01", T0))])
        rec.on_raw([Item("rfc2217://host:4000", Chunk(b"\x02", T0 + 1))])
    assert_time_ordered(path)
    assert {m[0] for m in mcap_messages(path)} == {"/raw/dev/ttyUSB0", "/raw/rfc2217/host_4000"}
    with McapCaptureReader(path) as reader:
        assert [i.bus for i in reader] == ["/dev/ttyUSB0", "rfc2217://host:4000"]


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_compressions(tmp_path: Path, compression: str) -> None:
    path = tmp_path / f"{compression}.mcap"
    with McapRecorder(path, {}, compression=compression) as rec:
        assert rec.compression == compression
        rec.on_raw(sample_items())
    assert_time_ordered(path)
    with McapCaptureReader(path) as reader:
        assert len(list(reader)) == len(sample_items())
    assert layout.best_compression() == "zstd"


def test_closed_recorder_refuses_writes(tmp_path: Path) -> None:
    rec = McapRecorder(tmp_path / "c.mcap", {})
    rec.close()
    rec.close()  # twice is fine
    for call in (
        lambda: rec.on_raw(sample_items()),
        lambda: rec.on_records(RecordSequence(sample_records())),
        lambda: rec.on_states(SampleSequence(sample_states())),
        lambda: rec.on_event(SourceEvent(T0, "can0", INFO, "x")),
        lambda: rec.write_mark(T0, "x"),
    ):
        with pytest.raises(ValueError, match="is closed"):
            call()
    with pytest.raises(ValueError):
        McapRecorder(tmp_path / "d.mcap", {}, compression="brotli")


def test_a_detached_recorder_finishes_its_file(tmp_path: Path) -> None:
    """The session tells a listener that failed through on_error: the recording still ends
    with its index, readable as a finished file."""
    path = tmp_path / "detached.mcap"
    rec = McapRecorder(path, {})
    rec.on_raw(sample_items())
    rec.on_error(OSError(28, "No space left on device"))
    with McapCaptureReader(path) as reader:
        assert not reader.damaged and len(list(reader)) == len(sample_items())


# -- in a real session --------------------------------------------------------------------------


def serial_capture() -> bytes:
    """A host polling two grippers on RS232 (run state and position), a catch, noise."""
    s = b.serial_frame
    out = []
    for k in range(60):
        dev = 1 + k % 2
        opening = 1000 - 10 * k
        out.append(s(dev, 0x41))
        out.append(s(dev, 0x41, bytes((4, 0, 35)) + b.u16le(opening, 100), response=True))
        out.append(s(dev, 0xD9))
        out.append(s(dev, 0xD9, b.u16le(opening), response=True))
        if k == 30:
            out.append(s(1, 0x10, b.u16le(500, 100)))
            out.append(b"\x55\xaa\x00")
            out.append(s(1, 0x10, b"\x01", response=True))
    return b"".join(out)


def can_capture() -> bytes:
    """candump -L lines: two grippers polled for force/opening/current/temperature."""
    lines = []
    for k in range(120):
        dev = 1 + k % 2
        t = T0 + k * 0.006
        for frame in (
            b.can_read_request(dev, 1120, 8, t=t),
            b.can_read_response(dev, 1120, b.u16le(100, 1000 - 5 * k, 20, 34), t=t + 0.0005),
        ):
            lines.append(
                f"({frame.t:.6f}) can0 {frame.arbitration_id:08X}#{frame.data.hex().upper()}"
            )
    return ("\n".join(lines) + "\n").encode()


def position_readings(records: list[Record]) -> list[tuple[int, int]]:
    """(seq, opening) of every valid frame that reads a gripper's opening, from the record
    alone (not from the Tracker): serial 0x41/0xD9 answers, CAN/Modbus register values."""
    out = []
    for r in records:
        if r.kind != "frame" or r.errors or r.direction != "response":
            continue
        values = r.fields.get("values")
        if isinstance(values, dict) and "CMD_OPENLEN_ACT" in values:
            out.append((r.seq, values["CMD_OPENLEN_ACT"]))
        elif "position" in r.fields:
            out.append((r.seq, r.fields["position"]))
    return out


@pytest.mark.parametrize(
    ("name", "make"), [("poll.bin", serial_capture), ("poll.log", can_capture)]
)
def test_state_samples_match_the_readings_one_for_one(tmp_path: Path, name: str, make) -> None:
    """A whole session into a recording: every reading is a /state message of its own, at its
    record's time; the recording is in time order."""
    capture = tmp_path / name
    capture.write_bytes(make())
    path = tmp_path / "session.mcap"
    recorder = McapRecorder(path, {"capture": name}, chunk_size=4096)
    with open_capture(capture) as reader:
        counts = Session(CaptureSource(reader), [recorder]).run()
    assert recorder.closed and counts.samples > 0
    assert_time_ordered(path)
    records = list(read_records(path))
    assert len(records) == counts.records
    readings = position_readings(records)
    assert len(readings) >= 100
    states = list(read_states(path))
    assert len(states) == counts.samples
    opening_samples = [(s["seq"], s["opening"]) for s in states if "opening" in s["changed"]]
    assert opening_samples == readings
    by_seq = {r.seq: r for r in records}
    assert all(s["t"] == by_seq[s["seq"]].t for s in states)
