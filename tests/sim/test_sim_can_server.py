"""The simulated EG2-4X0 on python-can's virtual bus (a unique channel per test)."""

from __future__ import annotations

import struct
import time
import uuid
from collections.abc import Iterator
from typing import Any

import can
import pytest
from sim_helpers import h, vectors

from analyzer.sim.endpoints import CanGripperServer
from analyzer.sim.gripper import GripperModel
from analyzer.sources.can_message import frame_to_message
from decoders.build import can_id, can_read_request, can_write_request, u16le
from decoders.eg2_can import BROADCAST, OP_READ, RESERVED_BIT
from decoders.model import CanFrame


@pytest.fixture
def channel() -> str:
    return f"eg2scope-test-{uuid.uuid4().hex[:8]}"


@pytest.fixture
def host(channel: str) -> Iterator[can.BusABC]:
    bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    yield bus
    bus.shutdown()


def send(bus: can.BusABC, frame: CanFrame) -> None:
    bus.send(frame_to_message(frame))


def vector_frame(entry: dict[str, Any], data: str) -> CanFrame:
    return CanFrame(None, int(entry["id"], 16), h(data))


def answers(bus: can.BusABC, quiet: float = 0.05, first: float = 1.0) -> list[can.Message]:
    """Every frame until the bus is quiet (waiting up to `first` for the first one)."""
    out: list[can.Message] = []
    msg = bus.recv(first)
    while msg is not None:
        out.append(msg)
        msg = bus.recv(quiet)
    return out


def one(bus: can.BusABC, timeout: float = 1.0) -> can.Message:
    got = answers(bus, first=timeout)
    assert len(got) == 1, got
    return got[0]


@pytest.fixture
def gripper(channel: str) -> Iterator[tuple[CanGripperServer, GripperModel]]:
    model = GripperModel(1, now=time.monotonic())
    with CanGripperServer({1: model}, channel=channel) as server:
        yield server, model


def test_worked_write_frame(
    gripper: tuple[CanGripperServer, GripperModel], host: can.BusABC
) -> None:
    server, model = gripper
    vector = next(p.values[0] for p in vectors("eg2_can"))
    send(host, vector_frame(vector, vector["data"]))
    msg = one(host)
    assert msg.arbitration_id == int(vector["response"]["id"], 16)
    assert msg.is_extended_id
    assert bytes(msg.data) == h(vector["response"]["data"])
    with server.lock:
        assert (model.target, model.speed, model.force) == (0, 500, 500)


@pytest.mark.parametrize("padded", [False, True])
def test_worked_read_frames(
    gripper: tuple[CanGripperServer, GripperModel], host: can.BusABC, padded: bool
) -> None:
    entries = [p.values[0] for p in vectors("eg2_can")]
    read_1120, read_1128 = entries[1], entries[2]
    # fault and state: the vector's bytes exactly (no fault, state 1)
    data = read_1128["data"] + (" 00" * 7 if padded else "")
    send(host, vector_frame(read_1128, data))
    msg = one(host)
    assert msg.arbitration_id == 0x011A0001
    assert bytes(msg.data) == h(read_1128["response"]["data"])
    # force, opening, current, temperature: DLC 8, little endian (the manual's own example
    # mixes byte orders; the simulator follows the protocol's definition)
    request = read_1120["alt_data_padded"] if padded else read_1120["data"]
    send(host, vector_frame(read_1120, request))
    msg = one(host)
    assert msg.arbitration_id == 0x01180001 and msg.dlc == 8
    assert struct.unpack("<HHhH", bytes(msg.data)) == (0, 1000, -2, 35)


def test_odd_spans_and_undocumented_registers(
    gripper: tuple[CanGripperServer, GripperModel], host: can.BusABC
) -> None:
    server, model = gripper
    req = can_read_request(1, 1123, 1)  # the high byte of the opening (1000 = 0x03E8)
    send(host, req)
    assert bytes(one(host).data) == b"\x03"
    req = can_read_request(1, 1026, 2)  # register 1013: undocumented, reads 0
    send(host, req)
    assert bytes(one(host).data) == b"\x00\x00"
    # a 1-byte write at 1022 changes the low byte of the speed only: 500 = 0x01F4 -> 0x0120
    req = can_write_request(1, 1022, b"\x20")
    send(host, req)
    assert bytes(one(host).data) == b"\x01"
    with server.lock:
        assert model.speed == 0x0120


@pytest.mark.parametrize(
    ("address", "data"),
    [
        (1020, u16le(1001)),  # target out of range
        (1022, u16le(5)),  # speed below 10
        (1122, u16le(5)),  # read-only
        (1026, u16le(5)),  # undocumented
        (2000, u16le(5)),  # outside the map
    ],
)
def test_refused_writes_get_no_answer(
    gripper: tuple[CanGripperServer, GripperModel], host: can.BusABC, address: int, data: bytes
) -> None:
    server, model = gripper
    req = can_write_request(1, address, data)
    send(host, req)
    assert answers(host, first=0.1) == []
    with server.lock:
        assert (model.target, model.speed) == (1000, 500)


def test_broadcast_and_several_ids(channel: str, host: can.BusABC) -> None:
    models = [GripperModel(1), GripperModel(2), GripperModel(1000)]
    with CanGripperServer(models, channel=channel) as server:
        for device in (1, 2, 1000):
            req = can_read_request(device, 1130, 2)
            send(host, req)
            msg = one(host)
            assert msg.arbitration_id == can_id(OP_READ, 1130, device)
            assert bytes(msg.data) == b"\x01\x00"
        req = can_read_request(3, 1130, 2)  # nobody has ID 3
        send(host, req)
        req = can_write_request(BROADCAST, 1022, u16le(800))
        send(host, req)
        assert answers(host, first=0.1) == []
        assert server.stats.broadcasts == 1
        with server.lock:
            assert [m.speed for m in models] == [800, 800, 800]


def test_set_id_beyond_254_and_save_pause(
    gripper: tuple[CanGripperServer, GripperModel], host: can.BusABC
) -> None:
    server, model = gripper
    req = can_write_request(1, 1006, u16le(3000))
    send(host, req)
    assert bytes(one(host).data) == b"\x02"  # answered under the old ID
    assert server.models.keys() == {3000}
    req = can_write_request(3000, 1002, u16le(1))  # save
    start = time.monotonic()
    send(host, req)
    poll = can_read_request(3000, 1130, 2)
    send(host, poll)  # during the pause: never answered
    msg = one(host, timeout=2.0)
    assert time.monotonic() - start > 0.8
    assert msg.arbitration_id == req.arbitration_id and bytes(msg.data) == b"\x02"
    assert model.saves == 1


def test_noise(channel: str, host: can.BusABC) -> None:
    req = can_read_request(1, 1130, 2)
    with CanGripperServer([GripperModel(1)], channel=channel, drop=1.0) as server:
        send(host, req)
        assert answers(host, first=0.1) == []
        assert server.stats.dropped == 1
    with CanGripperServer([GripperModel(1)], channel=channel, corrupt=1.0, garbage=1.0):
        send(host, req)
        got: list[Any] = answers(host)
        kinds = [
            "error" if m.is_error_frame else "std" if not m.is_extended_id else "eg2" for m in got
        ]
        assert kinds == ["std", "error", "eg2"]
        assert bytes(got[-1].data) == b"\x01\x00"


def test_stop_is_quick(channel: str) -> None:
    server = CanGripperServer([GripperModel(1)], channel=channel)
    server.start()
    start = time.monotonic()
    server.stop()
    assert time.monotonic() - start < 0.5


def test_padded_write_responses(channel: str, host: can.BusABC) -> None:
    with CanGripperServer([GripperModel(1)], channel=channel, pad_responses=True):
        send(host, can_write_request(1, 1022, u16le(800)))
        assert bytes(one(host).data) == b"\x02" + bytes(7)


def test_frames_with_the_reserved_bit_are_not_for_the_gripper(
    gripper: tuple[CanGripperServer, GripperModel], host: can.BusABC
) -> None:
    """A J1939 identifier with bit 28 set that reads as "write 1020 on device 1" below it."""
    server, model = gripper
    write = can_write_request(1, 1020, u16le(0, 500, 500))
    send(host, CanFrame(None, write.arbitration_id | RESERVED_BIT, write.data))
    assert answers(host, first=0.1) == []
    with server.lock:
        assert model.target == 1000
    assert server.stats.ignored == 1
