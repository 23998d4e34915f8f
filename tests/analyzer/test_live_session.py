"""Live sessions end to end: a real tap on a real pty or virtual CAN bus, decoded live, recorded
to MCAP, and the recording decoded again to the same records."""

from __future__ import annotations

import io
import os
import threading
import time
import tty
from pathlib import Path

import can

from analyzer.model import Item
from analyzer.recording.reader import read_events, read_records
from analyzer.recording.recorder import McapRecorder
from analyzer.session.session import Session, live_session
from analyzer.session.stage import Decoding
from analyzer.sinks.text import TextListener
from analyzer.sources.can_tap import CanTap
from analyzer.sources.capture import open_capture
from analyzer.sources.live import Tap, TapQueue
from analyzer.sources.serial_tap import SerialTap
from decoders import build as b
from decoders.model import Chunk, Record


def key(r: Record) -> tuple:
    return (r.protocol, r.kind, r.direction, r.device, r.name, r.raw, tuple(r.errors))


def decode_all(items: list[Item]) -> list[Record]:
    dec = Decoding()
    return list(dec.feed_many(items))


def run_in_thread(session: Session) -> threading.Thread:
    thread = threading.Thread(target=session.run, daemon=True)
    thread.start()
    time.sleep(0.3)  # taps open their ports
    return thread


def serial_traffic() -> bytes:
    s = b.serial_frame
    return b"".join(
        [
            s(1, 0x10, b.u16le(500, 100)),
            s(1, 0x10, b"\x01", response=True),
            s(1, 0xD9),
            s(1, 0xD9, b.u16le(497), response=True),
            b"\x00\x01\x02",
            s(2, 0x41),
            s(2, 0x41, bytes((6, 0, 40)) + b.u16le(300, 100), response=True),
        ]
    )


def test_serial_tap_decodes_live_and_records(tmp_path: Path) -> None:
    master, slave = os.openpty()
    tty.setraw(slave)
    port = os.ttyname(slave)
    out = io.StringIO()
    mcap_path = tmp_path / "run.mcap"
    recorder = McapRecorder(mcap_path, metadata={"test": True})
    session = live_session([SerialTap("rs232", port)], [TextListener(out, colour=False), recorder])
    thread = run_in_thread(session)
    data = serial_traffic()
    for i in range(0, len(data), 5):  # in bursts, as a USB adapter delivers them
        os.write(master, data[i : i + 5])
        time.sleep(0.002)
    time.sleep(0.5)
    session.stop()
    thread.join(5)
    assert not thread.is_alive()
    os.close(master)
    os.close(slave)
    text = out.getvalue()
    assert "CMD_MC_MOVE_CATCH_XG" in text and "catch speed=500 force=100 g" in text
    assert "-> ok" in text and "GARBAGE" in text
    assert "passive" in text  # the tap said whether it is passive
    live = list(read_records(mcap_path))
    expected = decode_all([Item("rs232", Chunk(data))])
    assert [key(r) for r in live] == [key(r) for r in expected]
    assert any(r.pair is not None and r.latency_ms is not None for r in live)
    with open_capture(mcap_path) as reader:
        replayed = list(Decoding().feed_many(reader))
        assert not reader.errors
    assert [key(r) for r in replayed] == [key(r) for r in expected]
    assert any("passive" in e.message for e in read_events(mcap_path))


def test_can_tap_on_virtual_bus_records_and_replays(tmp_path: Path) -> None:
    channel = f"eg2-live-{os.getpid()}-{time.monotonic_ns()}"
    mcap_path = tmp_path / "can.mcap"
    recorder = McapRecorder(mcap_path, metadata={})
    session = live_session([CanTap("can0", "virtual", channel)], [recorder])
    thread = run_in_thread(session)
    frames = [
        b.can_write_request(1, 1020, b.u16le(0, 500, 500)),
        b.can_write_response(1, 1020, 6),
        b.can_read_request(1, 1120, 8),
        b.can_read_response(1, 1120, b.u16le(243, 1000, 0, 34)),
    ]
    with can.Bus(interface="virtual", channel=channel) as sender:
        for f in frames:
            sender.send(
                can.Message(arbitration_id=f.arbitration_id, data=f.data, is_extended_id=True)
            )
            time.sleep(0.006)
    time.sleep(0.3)
    session.stop()
    thread.join(5)
    records = list(read_records(mcap_path))
    assert [(r.direction, r.name) for r in records] == [
        ("request", "CMD_OPENLEN_SET..CMD_FORCE_SET"),
        ("response", "CMD_OPENLEN_SET..CMD_FORCE_SET"),
        ("request", "CMD_FORCE_ACT..CMD_TEMP"),
        ("response", "CMD_FORCE_ACT..CMD_TEMP"),
    ]
    assert records[3].fields["values"]["CMD_OPENLEN_ACT"] == 1000
    assert records[1].pair == records[0].seq and records[1].latency_ms > 0
    with open_capture(mcap_path) as reader:
        replayed = list(Decoding().feed_many(reader))
    assert [key(r) for r in replayed] == [key(r) for r in records]
    assert session.tracker.states[("can0", 1)].opening == 1000


def test_drops_are_counted_and_reported() -> None:
    class Flood(Tap):
        def start(self, out: TapQueue) -> None:
            for _ in range(500):
                out.put(Item("flood", Chunk(b"\x00", time.time())))

        def stop(self) -> None:
            pass

    out = io.StringIO()
    session = live_session(
        [Flood("flood", "yes")],
        [TextListener(out, colour=False)],
        queue_size=10,
        duration=0.3,
    )
    counts = session.run()
    assert counts.dropped == 490
    assert "dropped 490 items" in out.getvalue()
