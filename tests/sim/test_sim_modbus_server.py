"""The simulated EG2-4X2 on a pty, driven by pymodbus's serial client (a Modbus master nobody
here wrote) and by the manual's worked frames."""

from __future__ import annotations

import logging
import struct
import time
from collections.abc import Iterator
from typing import Any

import pytest
import serial
from pymodbus.client import ModbusSerialClient
from sim_helpers import h, read_exactly, read_quiet, vectors

from analyzer.sim.endpoints import ModbusGripperServer
from analyzer.sim.gripper import GripperModel
from analyzer.sim.ptybus import PtyBus
from decoders.build import (
    modbus_exception,
    modbus_read_request,
    modbus_read_response,
    modbus_write_single,
    with_crc,
)

logging.getLogger("pymodbus").setLevel(logging.CRITICAL)  # it logs every exception response


@pytest.fixture
def gripper(line: PtyBus) -> Iterator[tuple[ModbusGripperServer, GripperModel]]:
    model = GripperModel(1, now=time.monotonic())
    with ModbusGripperServer(line.path("gripper"), {1: model}) as server:
        yield server, model


@pytest.fixture
def client(line: PtyBus) -> Iterator[ModbusSerialClient]:
    c = ModbusSerialClient(line.path("host"), baudrate=115200, timeout=0.5, retries=1)
    assert c.connect()
    yield c
    c.close()


def test_read_the_measurements(
    gripper: tuple[ModbusGripperServer, GripperModel], client: ModbusSerialClient
) -> None:
    rr = client.read_holding_registers(1061, count=5, device_id=1)
    assert not rr.isError(), rr
    opening, current, temperature, fault, state = rr.registers
    assert (opening, temperature, fault, state) == (1000, 35, 0, 1)
    assert current == 0xFFFE  # -2: signed
    rr = client.read_holding_registers(1060, count=1, device_id=1)
    assert rr.registers == [0]


def test_write_target_and_settings(
    gripper: tuple[ModbusGripperServer, GripperModel], client: ModbusSerialClient
) -> None:
    server, model = gripper
    server.place_object(1, 300)
    rr = client.write_registers(1010, [0, 1000, 1000], device_id=1)
    assert not rr.isError(), rr
    with server.lock:
        assert (model.speed, model.force, model.target) == (1000, 1000, 0)
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline:
        rr = client.read_holding_registers(1060, count=6, device_id=1)
        assert not rr.isError(), rr
        if rr.registers[5] == 6:
            break
        time.sleep(0.02)
    force, opening, _, _, fault, state = rr.registers
    assert (force, opening, fault, state) == (1000, 300, 0, 6)
    # open again with a single write
    rr = client.write_register(1010, 1000, device_id=1)
    assert not rr.isError(), rr
    assert server.snapshot(1)["state"] == 5


def test_short_register_numbers_are_the_same_registers(
    gripper: tuple[ModbusGripperServer, GripperModel], client: ModbusSerialClient
) -> None:
    server, model = gripper
    rr = client.write_register(11, 864, device_id=1)  # xArm style: 11 for 1011
    assert not rr.isError(), rr
    rr = client.write_register(10, 500, device_id=1)  # 10 for 1010
    assert not rr.isError(), rr
    with server.lock:
        assert (model.speed, model.target) == (864, 500)
    rr = client.read_holding_registers(11, count=2, device_id=1)
    assert rr.registers == [864, 100]
    rr = client.read_holding_registers(1011, count=2, device_id=1)
    assert rr.registers == [864, 100]


@pytest.mark.parametrize(
    ("call", "code"),
    [
        (lambda c: c.read_holding_registers(1013, count=1, device_id=1), 2),  # undocumented
        (lambda c: c.read_holding_registers(1060, count=7, device_id=1), 2),  # runs past 1065
        (lambda c: c.read_holding_registers(2000, count=1, device_id=1), 2),  # outside the map
        (lambda c: c.write_register(1061, 5, device_id=1), 2),  # read-only
        (lambda c: c.write_register(1010, 1001, device_id=1), 3),  # out of range
        (lambda c: c.write_register(1011, 5000, device_id=1), 3),  # a client's speed 5000
        (lambda c: c.write_registers(1016, [100, 200], device_id=1), 3),  # max < min
        (lambda c: c.read_input_registers(1061, count=1, device_id=1), 1),  # function 04
        (lambda c: c.write_coil(1, True, device_id=1), 1),  # function 05
    ],
    ids=["1013", "1060+7", "2000", "ro 1061", "1010=1001", "speed 5000", "max<min", "fc04", "fc05"],
)
def test_exceptions(
    gripper: tuple[ModbusGripperServer, GripperModel],
    client: ModbusSerialClient,
    call: Any,
    code: int,
) -> None:
    server, model = gripper
    rr = call(client)
    assert rr.isError()
    assert rr.exception_code == code
    with server.lock:  # nothing changed
        assert (model.target, model.speed, model.max_opening, model.min_opening) == (
            1000,
            500,
            1000,
            0,
        )
    assert server.stats.exceptions == 1


def test_broadcast_is_executed_not_answered(line: PtyBus, client: ModbusSerialClient) -> None:
    models = {1: GripperModel(1), 2: GripperModel(2)}
    with ModbusGripperServer(line.path("gripper"), models) as server:
        client.write_register(1011, 700, device_id=0, no_response_expected=True)
        deadline = time.monotonic() + 1.0
        while server.stats.broadcasts == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert server.stats.responses == 0
        with server.lock:
            assert models[1].speed == models[2].speed == 700
        assert client.read_holding_registers(1011, count=1, device_id=2).registers == [700]


def test_worked_frames_byte_identical(line: PtyBus, host_port: serial.Serial) -> None:
    entries = [p.values[0] for p in vectors("modbus_rtu")]
    read_req, read_resp, write_single, write_multi, write_multi_resp = (
        h(e["wire"]) for e in entries
    )
    # the reference's situation: opening 0, current -2, 37 °C, no fault
    model = GripperModel(1, opening=0, ambient_c=37.0)
    with ModbusGripperServer(line.path("gripper"), [model]):
        for request, response in [
            (read_req, read_resp),
            (write_single, write_single),  # the response echoes the request
            (write_multi, write_multi_resp),
        ]:
            host_port.write(request)
            assert read_exactly(host_port, len(response)).hex(" ") == response.hex(" ")
    assert (model.target, model.speed, model.force) == (0, 1000, 1000)


def test_the_manuals_swapped_crc_is_ignored_unless_asked(
    line: PtyBus, host_port: serial.Serial
) -> None:
    swapped = with_crc(modbus_write_single(1, 1010, 0)[:-2], swapped=True)  # as the manual prints
    with ModbusGripperServer(line.path("gripper"), [GripperModel(1)]) as server:
        host_port.write(swapped)
        assert read_quiet(host_port, 0.1) == b""
        assert server.stats.ignored == 1
    with ModbusGripperServer(line.path("gripper"), [GripperModel(1)], accept_swapped_crc=True):
        host_port.write(swapped)
        assert read_exactly(host_port, 8) == swapped  # the echo


def test_save_pause_over_the_wire(line: PtyBus, host_port: serial.Serial) -> None:
    model = GripperModel(1)
    with ModbusGripperServer(line.path("gripper"), [model]):
        save = modbus_write_single(1, 1001, 1)
        start = time.monotonic()
        host_port.write(save)
        time.sleep(0.05)
        host_port.write(modbus_read_request(1, 1065, 1))  # ignored during the pause
        assert read_exactly(host_port, 8, timeout=2.0) == save
        assert time.monotonic() - start > 0.8
        assert read_quiet(host_port, 0.05) == b""
        assert model.saves == 1
        host_port.write(modbus_read_request(1, 1003, 1))
        assert read_exactly(host_port, 7) == modbus_read_response(1, [1])  # ID 1
        read_input_registers = with_crc(struct.pack(">BBHH", 1, 4, 1061, 1))  # not the gripper's
        host_port.write(read_input_registers)
        assert read_exactly(host_port, 5) == modbus_exception(1, 4, 1)
