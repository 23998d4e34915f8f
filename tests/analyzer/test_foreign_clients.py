"""Clients nobody here wrote, tapped by eg2scope.

- pymodbus's serial client talks to the simulated gripper over a pty line while eg2scope's
  passive tap listens on another drop of the same line: every frame decoded, paired, named.
- python-can's own player (``can.player``'s entry point, in this process: the virtual bus does
  not cross processes) replays a candump log onto a virtual bus while eg2scope records it: the
  recording decodes to the same records as decoding the log directly.
"""

from __future__ import annotations

import logging
import os
import sys
import threading
import time
from pathlib import Path

import can.player
import pytest
from pymodbus.client import ModbusSerialClient

from analyzer.recording.reader import read_records
from analyzer.recording.recorder import McapRecorder
from analyzer.session.session import Session, live_session
from analyzer.session.stage import Decoding
from analyzer.sim.endpoints import ModbusGripperServer
from analyzer.sim.gripper import GripperModel
from analyzer.sim.ptybus import PtyBus
from analyzer.sources.can_tap import CanTap
from analyzer.sources.capture import open_capture
from analyzer.sources.live import wait_open
from analyzer.sources.serial_tap import SerialTap
from decoders.model import Record

ROOT = Path(__file__).resolve().parents[2]
logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def start(session: Session) -> threading.Thread:
    thread = threading.Thread(target=session.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 5
    while not session.source.taps[0].running and time.monotonic() < deadline:
        time.sleep(0.01)
    assert wait_open(session.source.taps, 5.0), "tap did not open"
    return thread


def test_pymodbus_client_traffic_is_decoded_paired_and_named(tmp_path: Path) -> None:
    with PtyBus(["gripper", "host", "tap"]) as line:
        model = GripperModel(1, now=time.monotonic(), object_width=300.0)
        server = ModbusGripperServer(line.path("gripper"), {1: model})
        recorder = McapRecorder(tmp_path / "modbus.mcap", metadata={})
        session = live_session(
            [SerialTap("rs485", line.path("tap"))], [recorder], protocol="modbus-rtu"
        )
        with server:
            thread = start(session)
            client = ModbusSerialClient(line.path("host"), baudrate=115200, timeout=0.5)
            assert client.connect()
            try:
                assert not client.read_holding_registers(1061, count=5, device_id=1).isError()
                assert not client.write_registers(1010, [0, 1000, 1000], device_id=1).isError()
                time.sleep(0.01)
                assert not client.write_register(1011, 800, device_id=1).isError()
                time.sleep(0.01)
                assert not client.write_register(10, 500, device_id=1).isError()  # short number
                time.sleep(0.01)
                assert client.read_holding_registers(1040, count=1, device_id=1).isError()
            finally:
                client.close()
            time.sleep(0.3)
            session.stop()
            thread.join(5)
    records = [r for r in read_records(tmp_path / "modbus.mcap")]
    frames = [r for r in records if r.kind == "frame"]
    assert all(not r.errors for r in records), [r.errors for r in records]
    assert [(r.direction, r.name) for r in frames] == [
        ("request", "CMD_OPENLEN_ACT..CMD_STATUS"),
        ("response", "CMD_OPENLEN_ACT..CMD_STATUS"),
        ("request", "CMD_OPENLEN_SET..CMD_FORCE_SET"),
        ("response", "CMD_OPENLEN_SET..CMD_FORCE_SET"),
        ("request", "CMD_SPEED_SET"),
        ("response", "CMD_SPEED_SET"),
        ("request", "CMD_OPENLEN_SET"),
        ("response", "CMD_OPENLEN_SET"),
        ("request", "REG_1040"),
        ("response", "EXCEPTION"),
    ]
    by_seq = {r.seq: r for r in frames}
    for resp in (r for r in frames if r.direction == "response"):
        req = by_seq[resp.pair]
        assert req.direction == "request" and req.pair == resp.seq
        assert resp.latency_ms is not None and 0 < resp.latency_ms < 100
    assert frames[1].fields["values"]["CMD_OPENLEN_ACT"] == 1000
    assert frames[1].fields["values"]["CMD_CURRENT"] == -2
    assert frames[6].fields["numbering"] == "short"
    assert frames[9].fields["exception_code"] == 2


def key(r: Record) -> tuple:
    if r.errors and r.errors[0].startswith("CAN error frame"):
        # python-can's candump reader keeps only "an error frame" (no class, no data), so
        # after its player an error frame can only be compared as one
        return ("can", "error frame")
    return (
        r.protocol,
        r.kind,
        r.direction,
        r.device,
        r.code,
        r.name,
        r.raw,
        tuple(r.errors),
        r.fields.get("address"),
    )


def test_python_can_player_replay_is_recorded_like_the_log(tmp_path: Path, monkeypatch) -> None:
    log = ROOT / "captures" / "can_pick_place.log"
    channel = f"eg2-player-{os.getpid()}-{time.monotonic_ns()}"
    recorder = McapRecorder(tmp_path / "player.mcap", metadata={})
    session = live_session([CanTap("can0", "virtual", channel)], [recorder])
    thread = start(session)
    monkeypatch.setattr(
        sys, "argv", ["can.player", "-i", "virtual", "-c", channel, "--error-frames", str(log)]
    )
    can.player.main()  # python-can's own player, with the log's timing
    time.sleep(0.3)
    session.stop()
    thread.join(5)
    recorded = list(read_records(tmp_path / "player.mcap"))
    with open_capture(log) as reader:
        direct = list(Decoding().feed_many(reader))
    assert len(recorded) == len(direct) > 80
    assert [key(r) for r in recorded] == [key(r) for r in direct]
    # pairing holds too (latencies differ: the player re-times the frames)
    assert [(r.seq, r.pair) for r in recorded] == [(r.seq, r.pair) for r in direct]


@pytest.mark.parametrize("signal_name", ["SIGKILL"])
def test_killed_recorder_leaves_a_recoverable_file(tmp_path: Path, signal_name: str) -> None:
    import signal
    import subprocess

    out = tmp_path / "demo.mcap"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "analyzer", "record", "--demo", "--buses", "can", "-o", str(out)],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        time.sleep(4.0)
    finally:
        proc.send_signal(getattr(signal, signal_name))
        proc.wait(10)
    with open_capture(out) as reader:
        records = list(Decoding().feed_many(reader))
        errors = list(reader.errors)
    assert any("recovered a damaged recording" in e for e in errors), errors
    frames = [r for r in records if r.kind == "frame" and r.protocol == "eg2-can"]
    assert len(frames) > 100  # ~3 s of polling two grippers survived the kill
    assert sum(1 for r in frames if r.pair is not None) > 50
