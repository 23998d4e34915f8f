"""MCAP recording: what McapRecorder writes, read back with the mcap library and with
McapCaptureReader; damaged and truncated files."""

from __future__ import annotations

import base64
import shutil
from pathlib import Path

import orjson
import pytest
from mcap.reader import make_reader

from analyzer import __version__
from analyzer.pipeline import Decoding, Item
from analyzer.sinks import mcap as sink
from analyzer.sinks.mcap import McapRecorder, topic_part
from analyzer.sources import mcap_reader
from analyzer.sources.capture import open_capture
from analyzer.sources.live import ERROR, INFO, WARNING, SourceEvent
from analyzer.sources.mcap_reader import (
    McapCaptureReader,
    read_events,
    read_metadata,
    read_records,
    read_states,
)
from analyzer.tracker import Tracker
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


def mcap_messages(path: Path) -> list[tuple[str, str, str, str, int, dict]]:
    """(topic, schema name, schema encoding, message encoding, log time, message) of every
    message, through the mcap library's own reader."""
    with path.open("rb") as f:
        reader = make_reader(f)
        return [
            (ch.topic, sc.name, sc.encoding, ch.message_encoding, m.log_time, orjson.loads(m.data))
            for sc, ch, m in reader.iter_messages(log_time_order=False)
        ]


@pytest.fixture
def recording(tmp_path: Path) -> Path:
    path = tmp_path / "run.mcap"
    tracker = Tracker()
    with McapRecorder(path, META) as rec:
        for item in sample_items():
            rec.write_item(item)
        rec.write_record(record(0))
        rec.write_record(record(1, direction="response", errors=["bad CRC: expected 1234"]))
        rec.write_record(record(2, warnings=["no response within 50 ms"], device=None))
        ok = Record(
            t=T0 + 0.01,
            bus="can0",
            protocol="eg2-can",
            kind="frame",
            length=2,
            raw=b"\x2c\x01",
            direction="response",
            device=1,
            name="CMD_OPENLEN_ACT",
            fields={"address": 0x46, "values": {"CMD_OPENLEN_ACT": 300}},
        )
        state = tracker.update(ok)
        assert state is not None
        rec.write_state(state)
        rec.write_state(state.to_dict())
        rec.write_event(SourceEvent(T0 + 0.02, "can0", WARNING, "dropped 3 frames", "drops"))
        rec.write_event(SourceEvent(T0 + 0.03, "ttyUSB0", INFO, "port reopened", "reopened"))
    return path


def test_layout_topics_schemas_encodings(recording: Path) -> None:
    msgs = mcap_messages(recording)
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
    }
    with recording.open("rb") as f:
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
        assert ch.metadata["bus"] in ch.topic


def test_raw_messages_match_items(recording: Path) -> None:
    raw = [m for m in mcap_messages(recording) if m[0].startswith("/raw/")]
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


def test_decoded_state_and_event_messages(recording: Path) -> None:
    msgs = mcap_messages(recording)
    decoded = [m[5] for m in msgs if m[0] == "/decoded/can0"]
    assert decoded == [
        orjson.loads(orjson.dumps(r.to_dict()))
        for r in (
            record(0),
            record(1, direction="response", errors=["bad CRC: expected 1234"]),
            record(2, warnings=["no response within 50 ms"], device=None),
        )
    ]
    states = [m for m in msgs if m[0] == "/state/can0/1"]
    assert len(states) == 2
    for *_, log_time, st in states:
        # the Foxglove plot path /state/can0/1.opening_mm: a top-level number
        assert isinstance(st["opening_mm"], float) and st["opening"] == 300
        assert (st["bus"], st["device"]) == ("can0", 1)
        assert log_time == int((T0 + 0.01) * 1e9)
    logs = [(m[0], m[4], m[5]) for m in msgs if m[0].startswith("/events/")]
    # two records with problems (error, then warning) and the two source events
    assert [(topic, d["level"], d["name"]) for topic, _, d in logs] == [
        ("/events/can0", ERROR, "decode"),
        ("/events/can0", WARNING, "decode"),
        ("/events/can0", WARNING, "drops"),
        ("/events/ttyUSB0", INFO, "reopened"),
    ]
    for _topic, log_time, d in logs:
        assert set(d) == {"timestamp", "level", "message", "name", "file", "line"}
        ts = d["timestamp"]
        assert set(ts) == {"sec", "nsec"} and 0 <= ts["nsec"] < 1_000_000_000
        assert ts["sec"] * 1_000_000_000 + ts["nsec"] == log_time
        assert isinstance(d["file"], str) and isinstance(d["line"], int)
    assert logs[0][2]["message"] == "ID 1 set: bad CRC: expected 1234"
    assert logs[0][2]["line"] == 1  # the record's seq
    assert logs[2][2]["message"] == "dropped 3 frames"


def test_metadata_record(recording: Path) -> None:
    with recording.open("rb") as f:
        metas = list(make_reader(f).iter_metadata())
    assert [m.name for m in metas] == ["eg2scope"]
    meta = metas[0].metadata
    assert all(isinstance(v, str) for v in meta.values())
    assert meta["tool"] == "eg2scope" and meta["version"] == __version__
    assert meta["passive"] == "yes"
    assert orjson.loads(meta["sources"]) == META["sources"]
    decoded = read_metadata(recording)
    assert decoded["sources"] == META["sources"] and decoded["passive"] == "yes"


def test_capture_reader_yields_the_items(recording: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def no_stream(*_a: object) -> None:
        raise AssertionError("an intact file must be read through its index")

    monkeypatch.setattr(mcap_reader._Scan, "_streamed", no_stream)
    items = sample_items()
    expected = sorted(items, key=lambda i: (i.payload.t is None, i.payload.t or 0))
    with open_capture(recording) as reader:
        assert isinstance(reader, McapCaptureReader)
        assert reader.kind == "mixed" and not reader.damaged
        assert reader.metadata["passive"] == "yes"
        got = list(reader)
        assert reader.errors == []
        assert reader.position == reader.size
    assert got == expected
    # the bus override puts everything on one bus
    with McapCaptureReader(recording, bus="x") as reader:
        assert {i.bus for i in reader} == {"x"}


def test_records_events_states_read_back(recording: Path) -> None:
    errors: list[str] = []
    recs = list(read_records(recording, errors))
    assert [r.to_dict() for r in recs] == [
        record(0).to_dict(),
        record(1, direction="response", errors=["bad CRC: expected 1234"]).to_dict(),
        record(2, warnings=["no response within 50 ms"], device=None).to_dict(),
    ]
    events = list(read_events(recording, errors))
    assert [(e.bus, e.level, e.kind) for e in events] == [
        ("can0", ERROR, "decode"),
        ("can0", WARNING, "decode"),
        ("can0", WARNING, "drops"),
        ("ttyUSB0", INFO, "reopened"),
    ]
    assert events[2] == SourceEvent(T0 + 0.02, "can0", WARNING, "dropped 3 frames", "drops")
    states = list(read_states(recording, errors))
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
        for item in items:
            rec.write_item(item)
    direct = [r.to_dict() for r in Decoding().feed_many(items)]
    with McapCaptureReader(path) as reader:
        again = [r.to_dict() for r in Decoding().feed_many(reader)]
    assert len(direct) > 100
    assert again == direct


def test_topic_names_for_awkward_bus_names(tmp_path: Path) -> None:
    assert topic_part("/dev/ttyUSB0") == "dev/ttyUSB0"
    assert topic_part("rfc2217://host:4000") == "rfc2217/host_4000"
    assert topic_part("COM3") == "COM3"
    path = tmp_path / "names.mcap"
    with McapRecorder(path, {}, compression="none") as rec:
        rec.write_item(Item("/dev/ttyUSB0", Chunk(b"\x01", T0)))
        rec.write_item(Item("rfc2217://host:4000", Chunk(b"\x02", T0 + 1)))
    assert {m[0] for m in mcap_messages(path)} == {"/raw/dev/ttyUSB0", "/raw/rfc2217/host_4000"}
    assert [i.bus for i in McapCaptureReader(path)] == ["/dev/ttyUSB0", "rfc2217://host:4000"]


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_compressions(tmp_path: Path, compression: str) -> None:
    path = tmp_path / f"{compression}.mcap"
    with McapRecorder(path, {}, compression=compression) as rec:
        assert rec.compression == compression
        for item in sample_items():
            rec.write_item(item)
    assert len(list(McapCaptureReader(path))) == len(sample_items())


def test_log_time_never_goes_back_within_a_topic(tmp_path: Path) -> None:
    """A stream whose clock steps back keeps its order on replay; the exact t survives."""
    items = [Item("s", Chunk(bytes([i]), t)) for i, t in enumerate([T0 + 2, T0 + 1, T0 + 3])]
    path = tmp_path / "back.mcap"
    with McapRecorder(path, {}) as rec:
        for item in items:
            rec.write_item(item)
    log_times = [m[4] for m in mcap_messages(path)]
    assert log_times == sorted(log_times)
    assert list(McapCaptureReader(path)) == items


def test_closed_recorder_refuses_writes(tmp_path: Path) -> None:
    rec = McapRecorder(tmp_path / "c.mcap", {})
    rec.close()
    rec.close()  # twice is fine
    with pytest.raises(ValueError):
        rec.write_item(sample_items()[0])
    with pytest.raises(ValueError):
        McapRecorder(tmp_path / "d.mcap", {}, compression="brotli")


# -- damage -------------------------------------------------------------------------------------


def many_items(n: int) -> list[Item]:
    out = []
    for i in range(n):
        t = T0 + i * 1e-3
        if i % 3:
            out.append(Item("can0", CanFrame(t, 0x100 + i % 7, i.to_bytes(4, "little"))))
        else:
            out.append(Item("ttyUSB0", Chunk(i.to_bytes(4, "little"), t, "request"), "tx"))
    return out


def test_open_recording_copied_mid_session_is_recovered(tmp_path: Path) -> None:
    """What a SIGKILL leaves: the file as it is while the recorder is still open, after a
    flush period; everything written before the flush is there, with a clear message."""
    items = many_items(300)
    path, copy = tmp_path / "live.mcap", tmp_path / "copy.mcap"
    rec = McapRecorder(path, META, flush_interval_s=3600)
    for item in items[:200]:
        rec.write_item(item)
    rec.flush_interval_s = 0.0
    rec.tick()  # what the live loop does when idle
    rec.flush_interval_s = 3600
    for item in items[200:]:
        rec.write_item(item)  # in the chunk in progress: not on disk yet
    shutil.copyfile(path, copy)
    rec.close()
    with McapCaptureReader(copy) as reader:
        assert reader.damaged
        assert reader.metadata["passive"] == "yes"
        assert reader.kind == "mixed"
        got = list(reader)
        assert got == items[:200]
        assert len(reader.errors) == 1
        msg = reader.errors[0]
        assert msg.startswith("recovered a damaged recording: read 200 raw messages up to byte ")
        assert f" of {copy.stat().st_size}; the rest is lost" in msg
    assert list(McapCaptureReader(path)) == items  # the finished file has it all


def test_truncated_at_any_offset_never_raises(tmp_path: Path) -> None:
    items = many_items(240)
    path = tmp_path / "whole.mcap"
    with McapRecorder(path, META, chunk_size=1500) as rec:
        for i, item in enumerate(items):
            rec.write_item(item)
            if i % 40 == 0:
                rec.write_record(record(i, t=item.payload.t))
                rec.write_event(SourceEvent(item.payload.t or 0, "can0", INFO, f"e{i}", "info"))
    data = path.read_bytes()
    size = len(data)
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and len(summary.chunk_indexes) > 5
    data_end = max(c.chunk_start_offset + c.chunk_length for c in summary.chunk_indexes)
    offsets = sorted(
        {0, 1, 7, 8, 9, 20, 60, size - 1, size - 8, size - 9, size - 30}
        | set(range(0, size, max(1, size // 37)))
        | {c.chunk_start_offset + d for c in summary.chunk_indexes[:4] for d in (0, 1, 30)}
    )
    cut = tmp_path / "cut.mcap"
    previous = -1
    for off in offsets:
        cut.write_bytes(data[:off])
        with McapCaptureReader(cut) as reader:
            got = list(reader)
            errors = reader.errors
        assert got == items[: len(got)], off  # a prefix, in order
        assert errors, f"no message for a file cut at {off} of {size}"
        assert len(got) >= previous, off  # more bytes never give fewer items
        previous = len(got)
        if off > data_end + 64:  # only the summary/footer is cut: nothing lost
            assert len(got) == len(items), off
        recs_errors: list[str] = []
        recs = list(read_records(cut, recs_errors))
        evs = list(read_events(cut, recs_errors))
        assert [r.seq for r in recs] == list(range(0, 40 * len(recs), 40))
        assert [e.message for e in evs] == [f"e{40 * k}" for k in range(len(evs))]
        assert recs_errors
    cut.write_bytes(b"not an mcap file at all, just some bytes " * 3)
    with McapCaptureReader(cut) as reader:
        assert list(reader) == []
        assert reader.errors and "not a readable MCAP" in reader.errors[0]


def test_sink_module_exports() -> None:
    assert sink.FOXGLOVE_LOG == "foxglove.Log"
    assert sink.best_compression() == "zstd"


def test_log_time_order_matches_the_mcap_library(tmp_path: Path) -> None:
    """Two buses stamped by different threads interleave with jitter across chunk boundaries:
    the reader's order is the mcap library's log-time order, intact or recovered."""
    import random

    rng = random.Random(5)
    items = []
    for i in range(600):
        bus = "can0" if i % 2 else "ttyUSB0"
        t = T0 + i * 1e-3 + rng.uniform(-0.004, 0.004)  # up to 8 positions out of order
        p = (
            CanFrame(t, 0x100, i.to_bytes(2, "little"))
            if i % 2
            else Chunk(i.to_bytes(2, "little"), t)
        )
        items.append(Item(bus, p))
    path = tmp_path / "jitter.mcap"
    with McapRecorder(path, {}, chunk_size=400) as rec:
        for item in items:
            rec.write_item(item)
    with path.open("rb") as f:
        reader = make_reader(f)
        assert len(reader.get_summary().chunk_indexes) > 20  # type: ignore[union-attr]
        library = [
            (ch.topic, orjson.loads(m.data)["data"])
            for _s, ch, m in reader.iter_messages(log_time_order=True)
        ]
    ours = [
        ("/raw/" + i.bus, base64.b64encode(i.payload.data).decode())
        for i in McapCaptureReader(path)
    ]
    assert ours == library
    assert ours != [("/raw/" + i.bus, base64.b64encode(i.payload.data).decode()) for i in items]
    # recovered from a damaged copy: the same order, for what is left
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size * 2 // 3])
    rd = McapCaptureReader(cut)
    recovered = [("/raw/" + i.bus, base64.b64encode(i.payload.data).decode()) for i in rd]
    assert rd.errors and len(recovered) > 300
    assert recovered == [m for m in library if m in set(recovered)]
