"""The virtual multi-drop serial line: real ptys opened with pyserial."""

from __future__ import annotations

import os
import random
import threading
import time
from pathlib import Path

import pytest
import serial
from sim_helpers import read_exactly, read_quiet

from analyzer.sim.ptybus import PtyBus
from decoders.build import modbus_read_request, serial_frame
from decoders.eg2_serial import Cmd


def _reader(port: serial.Serial, n: int, out: list[bytes]) -> threading.Thread:
    def run() -> None:
        out.append(read_exactly(port, n, timeout=10.0))

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def test_bytes_reach_every_other_drop_unchanged_and_not_the_writer() -> None:
    data = random.Random(7).randbytes(64 * 1024)  # far more than a pty buffer holds
    with PtyBus(["a", "b", "c"]) as bus:
        ports = {n: serial.Serial(bus.path(n), 115200, timeout=0.5) for n in "abc"}
        try:
            got_b: list[bytes] = []
            got_c: list[bytes] = []
            readers = [_reader(ports["b"], len(data), got_b), _reader(ports["c"], len(data), got_c)]
            for i in range(0, len(data), 1000):  # in pieces, as a program writes
                ports["a"].write(data[i : i + 1000])
            for t in readers:
                t.join(10.0)
            assert got_b == [data]
            assert got_c == [data]
            assert read_quiet(ports["a"], 0.05) == b""  # no echo to the writer
            # and the other way round, from another drop
            request = modbus_read_request(1, 1061, 4)
            ports["c"].write(request)
            assert read_exactly(ports["a"], 8) == request
            assert read_exactly(ports["b"], 8) == request
            assert read_quiet(ports["c"], 0.05) == b""
        finally:
            for p in ports.values():
                p.close()


def test_writes_from_two_drops_keep_each_writers_order() -> None:
    with PtyBus(["a", "b", "tap"]) as bus:
        a = serial.Serial(bus.path("a"), 115200)
        b = serial.Serial(bus.path("b"), 115200)
        tap = serial.Serial(bus.path("tap"), 115200)
        try:
            seq_a = bytes(range(0, 100))
            seq_b = bytes(range(100, 200))
            for i in range(100):
                a.write(seq_a[i : i + 1])
                b.write(seq_b[i : i + 1])
            got = read_exactly(tap, 200)
            assert sorted(got) == list(range(200))
            assert bytes(x for x in got if x < 100) == seq_a
            assert bytes(x for x in got if x >= 100) == seq_b
        finally:
            for p in (a, b, tap):
                p.close()


def test_on_bytes_sees_every_chunk_with_its_writer() -> None:
    seen: list[tuple[str, bytes]] = []
    with PtyBus(["host", "gripper"], on_bytes=lambda n, d, t: seen.append((n, d))) as bus:
        host = serial.Serial(bus.path("host"), 115200)
        gripper = serial.Serial(bus.path("gripper"), 115200)
        request = serial_frame(1, Cmd.READ_EG_RUNSTATE)
        host.write(request)
        assert read_exactly(gripper, 6) == request
        bus.send("gripper", b"\xee\x16")  # injected as if the gripper had sent it
        assert read_exactly(host, 2) == b"\xee\x16"
        host.close()
        gripper.close()
    assert b"".join(d for n, d in seen if n == "host") == request
    assert b"".join(d for n, d in seen if n == "gripper") == b"\xee\x16"


def test_unplug_and_replug_through_the_stable_symlink(tmp_path: Path) -> None:
    relayed = threading.Event()

    def on_bytes(name: str, data: bytes, t: float) -> None:
        if data.endswith(b"lost"):
            relayed.set()

    with PtyBus(link_dir=str(tmp_path), on_bytes=on_bytes) as bus:
        bus.add_endpoint("gripper")
        first = bus.add_endpoint("adapter")
        link = tmp_path / "adapter"
        assert os.readlink(link) == first
        gripper = serial.Serial(bus.path("gripper"), 115200)
        adapter = serial.Serial(str(link), 115200, timeout=0.2)
        gripper.write(b"before")
        assert read_exactly(adapter, 6) == b"before"

        bus.unplug("adapter")
        assert not link.exists()
        assert not bus.plugged("adapter")
        with pytest.raises((serial.SerialException, OSError)):
            adapter.read(1)  # EIO / hang-up: the device is gone
        adapter.close()
        with pytest.raises(serial.SerialException):
            serial.Serial(str(link), 115200)
        gripper.write(b"lost")  # nobody listens on the unplugged drop: dropped
        assert relayed.wait(2.0)

        second = bus.replug("adapter")
        assert os.readlink(link) == second
        adapter = serial.Serial(str(link), 115200, timeout=0.2)
        gripper.write(b"after")
        assert read_exactly(adapter, 5) == b"after"
        adapter.write(b"back")
        assert read_exactly(gripper, 4) == b"back"
        adapter.close()
        gripper.close()
    assert not link.exists()  # close() removes the links it made


def test_close_is_quick_and_idempotent() -> None:
    bus = PtyBus(["a", "b"])
    a = serial.Serial(bus.path("a"), 115200)
    start = time.monotonic()
    bus.close()
    bus.close()
    assert time.monotonic() - start < 0.5
    with pytest.raises((serial.SerialException, OSError)):
        a.read(1)
    a.close()
    with pytest.raises(RuntimeError):
        bus.add_endpoint("c")
