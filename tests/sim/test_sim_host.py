"""The scripted host against each simulated gripper: a pick-and-place completes with the object
detected (state 6), and a tap on the line decodes every frame of it cleanly."""

from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Iterator
from typing import Any

import can
import pytest

from analyzer.sim.endpoints import CanGripperServer, ModbusGripperServer, SerialGripperServer
from analyzer.sim.gripper import GripperModel
from analyzer.sim.host import HostQuirks, HostResult, run_host_cycle
from analyzer.sim.ptybus import PtyBus
from analyzer.sources.can_message import message_to_frame
from decoders.eg2_can import Eg2CanDecoder
from decoders.eg2_serial import Cmd, Eg2SerialDecoder
from decoders.modbus_rtu import ModbusRtuDecoder
from decoders.model import GARBAGE, REQUEST, RESPONSE, Chunk, Record

# a generous response time-out: a loaded CI machine must not turn a late answer into a miss
FAST: dict[str, Any] = {"speed": 1000, "dwell_s": 0.03, "timeout_s": 0.25}


class Tap:
    """Everything written on a pty line, in order (the analyzer's view)."""

    def __init__(self) -> None:
        self.data = bytearray()
        self.lock = threading.Lock()

    def __call__(self, name: str, data: bytes, t: float) -> None:
        with self.lock:
            self.data += data


@pytest.fixture
def tapped_line() -> Iterator[tuple[PtyBus, Tap]]:
    tap = Tap()
    with PtyBus(["gripper", "host"], on_bytes=tap) as bus:
        yield bus, tap


def _decoded(decoder: Eg2SerialDecoder | ModbusRtuDecoder, data: bytearray) -> list[Record]:
    return decoder.feed(Chunk(bytes(data))) + decoder.finish()


def _response_values(records: list[Record]) -> list[dict[str, int]]:
    return [r.fields["values"] for r in records if r.direction == RESPONSE and "values" in r.fields]


def _check_grips(result: HostResult, ids: list[int], cycles: int) -> None:
    assert result.cycles == cycles
    for device in ids:
        assert result.grips[device] == cycles, result
        assert {4, 5, 6} <= result.states_seen[device]
        assert result.last[device].state == 1
    assert result.responses > 0


@pytest.mark.parametrize("continuous", [False, True])
def test_serial_pick_and_place(tapped_line: tuple[PtyBus, Tap], continuous: bool) -> None:
    bus, tap = tapped_line
    models = {1: GripperModel(1, object_width=800), 2: GripperModel(2, object_width=700)}
    with SerialGripperServer(bus.path("gripper"), models):
        quirks = HostQuirks(continuous=continuous, id_scan=3)
        result = run_host_cycle("serial", bus.path("host"), [1, 2], 1, quirks=quirks, **FAST)
    _check_grips(result, [1, 2], 1)
    assert result.found == [1, 2]
    records = _decoded(Eg2SerialDecoder(), tap.data)
    assert all(r.ok for r in records), [r for r in records if not r.ok][:3]
    catch = Cmd.MOVE_CATCH2_XG if continuous else Cmd.MOVE_CATCH_XG
    assert {r.code for r in records} >= {Cmd.READ_EG_RUNSTATE, Cmd.MOVE_RELEASE, catch}
    held = [r for r in records if r.direction == RESPONSE and r.fields.get("state") == 6]
    assert {r.device for r in held} == {1, 2}
    # the ID scan probed 3 and got nothing back: more requests than responses
    requests = [r for r in records if r.direction == REQUEST]
    responses = [r for r in records if r.direction == RESPONSE]
    assert len(requests) == len(responses) + result.timeouts


@pytest.mark.parametrize("short", [False, True])
def test_modbus_pick_and_place(tapped_line: tuple[PtyBus, Tap], short: bool) -> None:
    bus, tap = tapped_line
    with ModbusGripperServer(bus.path("gripper"), [GripperModel(1, object_width=800)]):
        quirks = HostQuirks(short_registers=short)
        result = run_host_cycle("modbus", bus.path("host"), [1], 1, quirks=quirks, **FAST)
    _check_grips(result, [1], 1)
    assert result.timeouts == 0 and result.failures == 0
    records = _decoded(ModbusRtuDecoder(), tap.data)
    assert all(r.ok for r in records), [r for r in records if not r.ok][:3]
    writes = [r for r in records if r.code == 6 and r.direction == REQUEST]
    assert {r.fields["register"] for r in writes} >= {1005, 1010}
    assert all((r.fields.get("numbering") == "short") == short for r in writes)
    states = [v["CMD_STATUS"] for v in _response_values(records) if "CMD_STATUS" in v]
    assert 6 in states


def test_can_pick_and_place() -> None:
    channel = f"eg2scope-host-{uuid.uuid4().hex[:8]}"
    tap = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    try:
        models = [GripperModel(1, object_width=850), GripperModel(7, object_width=750)]
        with CanGripperServer(models, channel=channel):
            quirks = HostQuirks(padded_reads=True, continuous=True)
            result = run_host_cycle("can", channel, [1, 7], 2, quirks=quirks, **FAST)
        _check_grips(result, [1, 7], 2)
        dec = Eg2CanDecoder()
        records: list[Record] = []
        while (msg := tap.recv(0)) is not None:
            records.append(dec.decode(message_to_frame(msg), len(records)))
    finally:
        tap.shutdown()
    assert records and all(r.ok for r in records)
    assert any(r.fields.get("padded") for r in records)
    states = {
        (r.device, r.fields["values"]["CMD_STATUS"])
        for r in records
        if r.direction == RESPONSE and "CMD_STATUS" in r.fields.get("values", {})
    }
    assert {(1, 6), (7, 6)} <= states


def test_noisy_line_still_completes(tapped_line: tuple[PtyBus, Tap]) -> None:
    bus, tap = tapped_line
    noise: dict[str, Any] = {"corrupt": 0.2, "garbage": 0.2, "drop": 0.2, "seed": 5}
    with ModbusGripperServer(bus.path("gripper"), [GripperModel(1, object_width=800)], **noise):
        # dropped answers are the point here: a short time-out keeps the polling dense
        fast_retry = {**FAST, "timeout_s": 0.03}
        result = run_host_cycle("modbus", bus.path("host"), [1], 1, retries=8, **fast_retry)
    _check_grips(result, [1], 1)
    assert result.retries > 0
    records = _decoded(ModbusRtuDecoder(), tap.data)
    assert any(r.kind == GARBAGE or r.errors for r in records)  # the analyzer sees the noise


def test_save_quirk_waits_over_a_second(tapped_line: tuple[PtyBus, Tap]) -> None:
    bus, tap = tapped_line
    model = GripperModel(1)
    with SerialGripperServer(bus.path("gripper"), [model]):
        start = time.monotonic()
        quirks = HostQuirks(save_first=True)
        result = run_host_cycle("serial", bus.path("host"), [1], 0, quirks=quirks, **FAST)
    assert model.saves == 1
    assert result.timeouts == 0
    assert time.monotonic() - start > 0.85 + 1.0
    records = _decoded(Eg2SerialDecoder(), tap.data)
    save = next(
        i for i, r in enumerate(records) if r.code == Cmd.PARA_SAVE and r.direction == REQUEST
    )
    assert records[save + 1].code == Cmd.PARA_SAVE and records[save + 1].direction == RESPONSE


def test_stop_event_ends_an_endless_run(tapped_line: tuple[PtyBus, Tap]) -> None:
    bus, _ = tapped_line
    stop = threading.Event()
    result = HostResult()
    with SerialGripperServer(bus.path("gripper"), [GripperModel(1, object_width=800)]):
        thread = threading.Thread(
            target=run_host_cycle,
            args=("serial", bus.path("host"), [1], None, stop),
            kwargs={"result": result, **FAST},
        )
        thread.start()
        deadline = time.monotonic() + 5.0
        while result.grips.get(1, 0) < 1 and time.monotonic() < deadline:
            time.sleep(0.02)
        stop.set()
        start = time.monotonic()
        thread.join(2.0)
        assert not thread.is_alive()
        assert time.monotonic() - start < 0.5
    assert result.grips[1] >= 1


def test_unknown_protocol_is_refused() -> None:
    with pytest.raises(ValueError):
        run_host_cycle("profibus", "/dev/null")
