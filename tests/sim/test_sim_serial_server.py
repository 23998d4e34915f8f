"""The simulated EG2-4X1 on a pty, driven from a test-side pyserial port with the manual's
frames: responses must be byte-identical to the worked frames of the reference."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import serial
from sim_helpers import h, read_exactly, read_quiet, vectors

from analyzer.sim.endpoints import SerialGripperServer
from analyzer.sim.gripper import FAULT_STALL, SAVE_PAUSE_S, GripperModel
from analyzer.sim.ptybus import PtyBus
from decoders.build import serial_frame, u16le
from decoders.eg2_serial import Eg2SerialDecoder
from decoders.model import Chunk


def _position_497(m: GripperModel, now: float) -> None:
    assert m.seek(497, now)
    m.step(now + 1.0)


def _limits_1000_112(m: GripperModel, now: float) -> None:
    assert m.set_limits(1000, 112, now)


# the situation each state-dependent vector describes
SETUP: dict[str, Callable[[GripperModel, float], None]] = {
    "read current opening": _position_497,
    "read opening limits": _limits_1000_112,
}


@pytest.fixture
def served(line: PtyBus) -> Iterator[tuple[SerialGripperServer, GripperModel]]:
    model = GripperModel(1)
    with SerialGripperServer(line.path("gripper"), {1: model}) as server:
        yield server, model


@pytest.mark.parametrize("vector", vectors("eg2_serial"))
def test_every_worked_frame_gets_the_manuals_response(
    vector: dict[str, Any], line: PtyBus, host_port: serial.Serial
) -> None:
    # a fresh gripper in the situation the vector's values describe: fully open and idle,
    # no fault, 35 °C, force setting 100 g (the run state frame), or as SETUP says
    model = GripperModel(1, now=time.monotonic())
    setup = SETUP.get(vector["meaning"])
    if setup is not None:
        setup(model, time.monotonic())
        model.step(time.monotonic())
    with SerialGripperServer(line.path("gripper"), [model]) as server:
        expected = h(vector["response"])
        start = time.monotonic()
        host_port.write(h(vector["request"]))
        got = read_exactly(host_port, len(expected), timeout=2.0)
        elapsed = time.monotonic() - start
        assert got.hex(" ") == expected.hex(" ")
        assert read_quiet(host_port, 0.02) == b""  # one response, nothing else
        assert server.stats.responses == 1
    if vector["meaning"].startswith("save"):
        assert elapsed >= SAVE_PAUSE_S - 0.01  # the save response comes after the pause
        assert model.saves == 1
    else:
        assert elapsed < 0.2
    if vector["meaning"].startswith("set ID"):
        assert model.device_id == 3


def test_requests_change_the_model(
    served: tuple[SerialGripperServer, GripperModel], host_port: serial.Serial
) -> None:
    server, model = served
    server.place_object(1, 400)
    host_port.write(h("EB 90 01 05 10 F4 01 64 00 6F"))  # catch, 500, 100 g
    assert read_exactly(host_port, 7) == h("EE 16 01 02 10 01 14")
    deadline = time.monotonic() + 3.0
    while server.snapshot(1)["state"] != 6 and time.monotonic() < deadline:
        time.sleep(0.02)
    snap = server.snapshot(1)
    assert (snap["state"], snap["position"], snap["measured_force"]) == (6, 400, 100)
    # the run state now says so
    host_port.write(h("EB 90 01 01 41 43"))
    want = serial_frame(1, 0x41, bytes((6, 0, model.temperature_c)) + u16le(400, 100), True)
    assert read_exactly(host_port, len(want)) == want


def test_bad_values_get_failure_status(
    served: tuple[SerialGripperServer, GripperModel], host_port: serial.Serial
) -> None:
    _, model = served
    cases = [
        (0x12, u16le(100, 200)),  # max < min
        (0x12, u16le(1001, 0)),  # out of 0-1000
        (0x10, u16le(5000, 100)),  # speed 5000, as one client sends
        (0x11, u16le(0)),
        (0x04, bytes((0,))),  # ID 0
        (0x11, b""),  # no speed at all
    ]
    for cmd, data in cases:
        host_port.write(serial_frame(1, cmd, data))
        want = serial_frame(1, cmd, b"\x55", response=True)
        assert read_exactly(host_port, len(want)) == want, f"CMD 0x{cmd:02X} {data.hex()}"
    assert (model.max_opening, model.min_opening, model.device_id) == (1000, 0, 1)


def test_two_byte_set_id_is_accepted(
    served: tuple[SerialGripperServer, GripperModel], host_port: serial.Serial
) -> None:
    _, model = served
    host_port.write(serial_frame(1, 0x04, u16le(7)))  # the LEN 3 form of section 4
    assert read_exactly(host_port, 7) == serial_frame(1, 0x04, b"\x01", response=True)
    assert model.device_id == 7


def test_faults_show_and_clear(
    served: tuple[SerialGripperServer, GripperModel], host_port: serial.Serial
) -> None:
    server, _ = served
    server.inject_fault(1, "stall")
    host_port.write(h("EB 90 01 01 41 43"))
    rec = _response(host_port)
    assert rec.fields["fault"] == FAULT_STALL
    host_port.write(h("EB 90 01 05 10 F4 01 64 00 6F"))  # a faulted gripper refuses to move
    assert read_exactly(host_port, 7) == serial_frame(1, 0x10, b"\x55", response=True)
    host_port.write(h("EB 90 01 01 17 19"))
    assert read_exactly(host_port, 7) == h("EE 16 01 02 17 01 1B")
    assert server.snapshot(1)["fault"] == 0


def _response(port: serial.Serial) -> Any:
    dec = Eg2SerialDecoder()
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline:
        port.timeout = 0.05
        for rec in dec.feed(Chunk(port.read(64))):
            if rec.direction == "response":
                return rec
    raise AssertionError("no response")


def test_several_grippers_one_line_broadcast_and_bad_checksum(
    line: PtyBus, host_port: serial.Serial
) -> None:
    models = {i: GripperModel(i) for i in (1, 2, 3)}
    with SerialGripperServer(line.path("gripper"), models) as server:
        for i in (1, 2, 3):
            host_port.write(serial_frame(i, 0xD9))
            assert read_exactly(host_port, 8) == serial_frame(i, 0xD9, u16le(1000), True)
        host_port.write(serial_frame(4, 0xD9))  # nobody has ID 4
        host_port.write(h("EB 90 01 01 41 44"))  # bad checksum: ignored
        # broadcast: every gripper closes, none answers
        host_port.write(serial_frame(255, 0x10, u16le(1000, 100)))
        assert read_quiet(host_port, 0.1) == b""
        for i in (1, 2, 3):
            assert server.snapshot(i)["state"] in (2, 4)
        assert server.stats.broadcasts == 1
        assert server.stats.ignored >= 2


def test_the_gripper_is_deaf_during_a_save(line: PtyBus, host_port: serial.Serial) -> None:
    models = {1: GripperModel(1), 2: GripperModel(2)}
    with SerialGripperServer(line.path("gripper"), models):
        host_port.write(serial_frame(1, 0x01))
        time.sleep(0.05)
        host_port.write(serial_frame(1, 0xD9))  # during the pause: no answer, ever
        host_port.write(serial_frame(2, 0xD9))  # the other gripper answers at once
        assert read_exactly(host_port, 8, timeout=0.5) == serial_frame(2, 0xD9, u16le(1000), True)
        assert read_exactly(host_port, 7, timeout=2.0) == h("EE 16 01 02 01 01 05")
        assert read_quiet(host_port, 0.05) == b""


def test_noise_knobs(line: PtyBus, host_port: serial.Serial) -> None:
    request = h("EB 90 01 01 D9 DB")
    good = serial_frame(1, 0xD9, u16le(1000), True)
    with SerialGripperServer(line.path("gripper"), [GripperModel(1)], corrupt=1.0) as server:
        host_port.write(request)
        bad = read_exactly(host_port, len(good))
        assert bad[:-1] == good[:-1] and bad[-1] != good[-1]  # the checksum is wrong
        assert server.stats.corrupted == 1
    with SerialGripperServer(line.path("gripper"), [GripperModel(1)], drop=1.0) as server:
        host_port.write(request)
        assert read_quiet(host_port, 0.1) == b""
        assert server.stats.dropped == 1
    with SerialGripperServer(line.path("gripper"), [GripperModel(1)], garbage=1.0) as server:
        host_port.write(request)
        got = read_quiet(host_port, 0.1)
        assert got.endswith(good) and len(got) > len(good)


def test_stop_is_quick(line: PtyBus) -> None:
    server = SerialGripperServer(line.path("gripper"), [GripperModel(1)])
    server.start()
    start = time.monotonic()
    server.stop()
    assert time.monotonic() - start < 0.5
    assert not server.running


def test_the_server_comes_back_after_its_adapter_is_replugged(tmp_path: Path) -> None:
    with PtyBus(link_dir=str(tmp_path)) as bus:
        bus.add_endpoint("gripper")
        host = serial.Serial(bus.add_endpoint("host"), 115200, timeout=1.0)
        request = serial_frame(1, 0xD9)
        response = serial_frame(1, 0xD9, u16le(1000), response=True)
        with SerialGripperServer(str(tmp_path / "gripper"), [GripperModel(1)]) as server:
            host.write(request)
            assert read_exactly(host, len(response)) == response
            bus.unplug("gripper")
            host.write(request)  # nobody there
            assert read_quiet(host, 0.1) == b""
            bus.replug("gripper")
            deadline = time.monotonic() + 3.0
            got = b""
            while got != response and time.monotonic() < deadline:
                host.write(request)
                got = read_quiet(host, 0.1)
            assert got == response
            assert server.running
        host.close()
