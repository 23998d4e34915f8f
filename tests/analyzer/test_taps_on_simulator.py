"""Taps against the simulated gripper, as a user would wire them.

- The inline bridge between a host program and a simulated gripper on two separate pty lines:
  the host completes its pick-and-place through eg2scope, every byte crosses unchanged both ways,
  and both directions decode, paired.
- The passive CAN tap on the simulated gripper's virtual bus while a host drives it.
"""

from __future__ import annotations

import threading
import time

from analyzer.session.listener import Listener
from analyzer.session.session import Session, live_session
from analyzer.sim.endpoints import CanGripperServer, SerialGripperServer
from analyzer.sim.gripper import GripperModel
from analyzer.sim.host import HostQuirks, run_host_cycle
from analyzer.sim.ptybus import PtyBus
from analyzer.sources.can_tap import CanTap
from analyzer.sources.live import wait_open
from analyzer.sources.serial_tap import SerialBridge
from decoders.model import REQUEST, RESPONSE, Record


class Collect(Listener):
    wants_raw = True

    def __init__(self) -> None:
        self.got: list[Record] = []
        self.raw: dict[str, bytearray] = {"request": bytearray(), "response": bytearray()}

    def on_records(self, records: list[Record]) -> None:
        self.got += records

    def on_raw(self, items: list) -> None:
        for item in items:
            direction = getattr(item.payload, "direction", None)  # chunks of the bridge only
            if direction is not None:
                self.raw[direction] += item.payload.data


def run_session(session: Session) -> threading.Thread:
    thread = threading.Thread(target=session.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 5
    while not all(t.running for t in session.source.taps) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert wait_open(session.source.taps, 5.0)
    return thread


def test_bridge_between_host_and_simulated_gripper() -> None:
    seen_at_gripper = bytearray()
    seen_at_host = bytearray()

    def at_device_line(name: str, data: bytes, t: float) -> None:
        if name == "bridge":  # what the bridge put on the gripper's line
            seen_at_gripper.extend(data)

    def at_host_line(name: str, data: bytes, t: float) -> None:
        if name == "bridge":
            seen_at_host.extend(data)

    with (
        PtyBus(["host", "bridge"], on_bytes=at_host_line) as host_line,
        PtyBus(["bridge", "gripper"], on_bytes=at_device_line) as device_line,
    ):
        model = GripperModel(1, now=time.monotonic(), object_width=500.0)
        out = Collect()
        bridge = SerialBridge("rs232", host_line.path("bridge"), device_line.path("bridge"))
        session = live_session([bridge], [out], protocol="eg2-serial")
        with SerialGripperServer(device_line.path("gripper"), {1: model}):
            thread = run_session(session)
            result = run_host_cycle("serial", host_line.path("host"), [1], 1,
                                    speed=1000, timeout_s=0.25)  # fmt: skip
            time.sleep(0.2)
            session.stop()
            thread.join(5)
    assert result.cycles == 1 and result.grips[1] == 1 and result.failures == 0
    # every byte relayed unchanged, in order, both ways
    assert bytes(seen_at_gripper) == bytes(out.raw["request"])
    assert bytes(seen_at_host) == bytes(out.raw["response"])
    frames = [r for r in out.got if r.kind == "frame"]
    assert frames and all(r.ok for r in frames)
    requests = [r for r in frames if r.direction == REQUEST]
    responses = [r for r in frames if r.direction == RESPONSE]
    # what the host sent and got is what the tap saw (a late answer the host gave up on is
    # still on the line, so the tap may see more responses than the host counted)
    assert len(requests) == result.commands
    assert result.responses <= len(responses) <= result.responses + result.timeouts
    assert all(r.pair is not None and r.latency_ms is not None for r in responses)
    assert any(r.fields.get("state") == 6 for r in responses)  # the grip, seen through the tap


def test_can_tap_on_the_simulated_bus() -> None:
    channel = f"eg2-simtap-{time.monotonic_ns()}"
    models = {1: GripperModel(1, now=time.monotonic(), object_width=600.0),
              2: GripperModel(2, now=time.monotonic(), object_width=300.0)}  # fmt: skip
    out = Collect()
    session = live_session([CanTap("can0", "virtual", channel)], [out])
    with CanGripperServer(models, channel=channel):
        thread = run_session(session)
        result = run_host_cycle("can", channel, [1, 2], 1, quirks=HostQuirks(padded_reads=True),
                                speed=1000, timeout_s=0.25)  # fmt: skip
        time.sleep(0.2)
        session.stop()
        thread.join(5)
    assert result.cycles == 1 and result.grips == {1: 1, 2: 1}
    frames = [r for r in out.got if r.protocol == "eg2-can"]
    assert frames and all(r.ok for r in frames)
    responses = [r for r in frames if r.direction == RESPONSE]
    assert result.responses <= len(responses) <= result.responses + result.timeouts
    assert all(r.pair is not None for r in responses)
    assert any(r.fields.get("padded") for r in frames if r.direction == REQUEST)
    states = session.tracker.states
    assert states[("can0", 1)].state in (1, 3, 5) and states[("can0", 2)].opening is not None
