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
from decoders.eg2_serial import BROADCAST, STATUS_FAILED, STATUS_OK, Cmd, Eg2SerialDecoder
from decoders.model import Chunk

OK, FAILED = bytes((STATUS_OK,)), bytes((STATUS_FAILED,))


def _bad_sum(frame: bytes) -> bytes:
    """frame with its checksum byte damaged."""
    return frame[:-1] + bytes((frame[-1] ^ 0x01,))


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
    host_port.write(serial_frame(1, Cmd.MOVE_CATCH_XG, u16le(500, 100)))  # catch, 500, 100 g
    assert read_exactly(host_port, 7) == serial_frame(1, Cmd.MOVE_CATCH_XG, OK, response=True)
    deadline = time.monotonic() + 3.0
    while server.snapshot(1)["state"] != 6 and time.monotonic() < deadline:
        time.sleep(0.02)
    snap = server.snapshot(1)
    assert (snap["state"], snap["position"], snap["measured_force"]) == (6, 400, 100)
    # the run state now says so
    host_port.write(serial_frame(1, Cmd.READ_EG_RUNSTATE))
    want = serial_frame(
        1, Cmd.READ_EG_RUNSTATE, bytes((6, 0, model.temperature_c)) + u16le(400, 100), True
    )
    assert read_exactly(host_port, len(want)) == want


def test_bad_values_get_failure_status(
    served: tuple[SerialGripperServer, GripperModel], host_port: serial.Serial
) -> None:
    _, model = served
    cases = [
        (Cmd.SET_EG_PARA, u16le(100, 200)),  # max < min
        (Cmd.SET_EG_PARA, u16le(1001, 0)),  # out of 0-1000
        (Cmd.MOVE_CATCH_XG, u16le(5000, 100)),  # speed 5000, as one client sends
        (Cmd.MOVE_RELEASE, u16le(0)),
        (Cmd.PARA_ID_SET, bytes((0,))),  # ID 0
        (Cmd.MOVE_RELEASE, b""),  # no speed at all
    ]
    for cmd, data in cases:
        host_port.write(serial_frame(1, cmd, data))
        want = serial_frame(1, cmd, FAILED, response=True)
        assert read_exactly(host_port, len(want)) == want, f"{cmd!r} {data.hex()}"
    assert (model.max_opening, model.min_opening, model.device_id) == (1000, 0, 1)


def test_two_byte_set_id_is_accepted(
    served: tuple[SerialGripperServer, GripperModel], host_port: serial.Serial
) -> None:
    _, model = served
    host_port.write(serial_frame(1, Cmd.PARA_ID_SET, u16le(7)))  # the LEN 3 form of section 4
    assert read_exactly(host_port, 7) == serial_frame(1, Cmd.PARA_ID_SET, OK, response=True)
    assert model.device_id == 7


def test_faults_show_and_clear(
    served: tuple[SerialGripperServer, GripperModel], host_port: serial.Serial
) -> None:
    server, _ = served
    server.inject_fault(1, "stall")
    host_port.write(serial_frame(1, Cmd.READ_EG_RUNSTATE))
    rec = _response(host_port)
    assert rec.fields["fault"] == FAULT_STALL
    host_port.write(
        serial_frame(1, Cmd.MOVE_CATCH_XG, u16le(500, 100))
    )  # a faulted gripper refuses to move
    assert read_exactly(host_port, 7) == serial_frame(1, Cmd.MOVE_CATCH_XG, FAILED, response=True)
    host_port.write(serial_frame(1, Cmd.ERROR_CLR))
    assert read_exactly(host_port, 7) == serial_frame(1, Cmd.ERROR_CLR, OK, response=True)
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
            host_port.write(serial_frame(i, Cmd.READ_ACTPOS))
            assert read_exactly(host_port, 8) == serial_frame(i, Cmd.READ_ACTPOS, u16le(1000), True)
        host_port.write(serial_frame(4, Cmd.READ_ACTPOS))  # nobody has ID 4
        host_port.write(_bad_sum(serial_frame(1, Cmd.READ_EG_RUNSTATE)))  # bad checksum: ignored
        # broadcast: every gripper closes, none answers
        host_port.write(serial_frame(BROADCAST, Cmd.MOVE_CATCH_XG, u16le(1000, 100)))
        assert read_quiet(host_port, 0.1) == b""
        for i in (1, 2, 3):
            assert server.snapshot(i)["state"] in (2, 4)
        assert server.stats.broadcasts == 1
        assert server.stats.ignored >= 2


def test_the_gripper_is_deaf_during_a_save(line: PtyBus, host_port: serial.Serial) -> None:
    models = {1: GripperModel(1), 2: GripperModel(2)}
    with SerialGripperServer(line.path("gripper"), models):
        host_port.write(serial_frame(1, Cmd.PARA_SAVE))
        time.sleep(0.05)
        host_port.write(serial_frame(1, Cmd.READ_ACTPOS))  # during the pause: no answer, ever
        host_port.write(serial_frame(2, Cmd.READ_ACTPOS))  # the other gripper answers at once
        assert read_exactly(host_port, 8, timeout=0.5) == serial_frame(
            2, Cmd.READ_ACTPOS, u16le(1000), True
        )
        assert read_exactly(host_port, 7, timeout=2.0) == serial_frame(
            1, Cmd.PARA_SAVE, OK, response=True
        )
        assert read_quiet(host_port, 0.05) == b""


def test_noise_knobs(line: PtyBus, host_port: serial.Serial) -> None:
    request = serial_frame(1, Cmd.READ_ACTPOS)
    good = serial_frame(1, Cmd.READ_ACTPOS, u16le(1000), True)
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
        request = serial_frame(1, Cmd.READ_ACTPOS)
        response = serial_frame(1, Cmd.READ_ACTPOS, u16le(1000), response=True)
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
