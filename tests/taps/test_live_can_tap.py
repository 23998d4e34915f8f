"""Live CAN tap on python-can's virtual bus (and socketcan's vcan0 when the kernel has it)."""

from __future__ import annotations

import os
import threading
import time
import uuid
from collections.abc import Iterator
from typing import Any

import can
import pytest
from can.interfaces.virtual import VirtualBus
from tap_helpers import Collector as BaseCollector

from analyzer.model import INFO, WARNING
from analyzer.sources.can_tap import CanTap, listen_only_plan, parse_ip_link_details
from analyzer.sources.live import TapQueue
from decoders.model import CanFrame

RETRY = 0.05
REAL_BUS = can.Bus


class Collector(BaseCollector):
    """The tap queue, drained; plus the captured CAN frames."""

    def frames(self) -> list[CanFrame]:
        out = []
        for i in self.items:
            assert isinstance(i.payload, CanFrame)
            out.append(i.payload)
        return out


def _channel() -> str:
    return f"eg2scope-test-{uuid.uuid4().hex}"


@pytest.fixture
def sends(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[str]]:
    """Every bus the tap opens gets its transmit methods replaced by a recorder."""
    calls: list[str] = []

    def bus(*args: Any, **kwargs: Any) -> can.BusABC:
        b = REAL_BUS(*args, **kwargs)
        b.send = lambda *a, **k: calls.append("send")  # type: ignore[method-assign]
        b.send_periodic = lambda *a, **k: calls.append("send_periodic")  # type: ignore[method-assign,assignment]
        return b

    monkeypatch.setattr(can, "Bus", bus)
    yield calls


def _no_tracebacks(capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture) -> None:
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    assert not [r for r in caplog.records if r.levelno >= 30 or r.exc_info]


def test_virtual_bus_frames_captured_and_tap_never_sends(
    sends: list[str], capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    ch = _channel()
    sender = VirtualBus(channel=ch)
    tap = CanTap("can0", "virtual", ch, 500000)
    assert tap.passive == "yes"
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    try:
        passive = c.wait_event("passive")
        assert passive.level == INFO
        assert "virtual bus (simulated), the tap never sends" in passive.message
        opened = c.wait_event("open")
        assert ch in opened.message
        t0 = time.time()
        msgs = [
            can.Message(arbitration_id=0x1, data=b"\x6b\x01\x02", is_extended_id=False),
            can.Message(arbitration_id=0x1ABCDE, data=bytes(8), is_extended_id=True),
            can.Message(arbitration_id=0x7FF, is_remote_frame=True, dlc=4, is_extended_id=False),
            can.Message(
                arbitration_id=0x123, data=bytes(range(64)), is_fd=True, bitrate_switch=True
            ),
            can.Message(arbitration_id=0x0, is_error_frame=True, dlc=0),
        ]
        for m in msgs:
            sender.send(m)
        c.wait(lambda c: len(c.items) >= len(msgs))
        t1 = time.time()
        frames = c.frames()
        assert all(i.bus == "can0" for i in c.items)
        ts = [f.t for f in frames]
        assert all(t is not None and t0 <= t <= t1 for t in ts)
        assert ts == sorted(ts)  # type: ignore[type-var]
        a, b, r, fd, err = frames
        assert (a.arbitration_id, a.data, a.is_extended, a.dlc) == (1, b"\x6b\x01\x02", False, 3)
        assert (b.arbitration_id, b.is_extended, b.length) == (0x1ABCDE, True, 8)
        assert r.is_remote and r.data == b"" and r.dlc == 4 and r.length == 4
        assert fd.is_fd and fd.data == bytes(range(64))
        assert err.is_error
        assert all(f.channel == ch for f in frames)
    finally:
        tap.stop()
        sender.shutdown()
    c.pump()
    closed = c.of("closed")
    assert len(closed) == 1 and "5 frames" in closed[0].message
    assert sends == []
    assert tap.settings["interface"] == "virtual" and tap.settings["passive"] == "yes"
    _no_tracebacks(capsys, caplog)


def test_open_fails_then_retries_with_wait(
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
) -> None:
    ch = _channel()
    attempts = []

    def flaky(*args: Any, **kwargs: Any) -> can.BusABC:
        attempts.append(kwargs)
        if len(attempts) <= 3:
            raise can.CanInitializationError("no such adapter")
        return REAL_BUS(*args, **kwargs)

    monkeypatch.setattr(can, "Bus", flaky)
    sender = VirtualBus(channel=ch)
    tap = CanTap("can1", "virtual", ch, retry_interval=RETRY, wait=True)
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    try:
        assert tap.first_open() is None  # waited for: not a failure
        err = c.wait_event("open")
        assert err.level == WARNING
        assert err.message == (
            f"waiting for virtual channel {ch} (CanInitializationError: no such adapter; "
            "retrying with back-off from 0.05 s up to 5 s)"
        )
        ok = c.wait_event("open", 2)
        assert ok.level == INFO and "after waiting" in ok.message
        assert len(attempts) == 4
        assert attempts[-1]["receive_own_messages"] is False
        assert "bitrate" not in attempts[-1]
        sender.send(can.Message(arbitration_id=0x2, data=b"\x01", is_extended_id=False))
        c.wait(lambda c: len(c.items) == 1)
    finally:
        tap.stop()
        sender.shutdown()
    _no_tracebacks(capsys, caplog)


class _FlakyBus(VirtualBus):
    down = threading.Event()

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self.down.is_set():
            raise can.CanOperationError("Network is down [Error Code 100]")
        return super()._recv_internal(timeout)


def test_interface_goes_down_and_comes_back(
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
) -> None:
    ch = _channel()
    down = threading.Event()
    opened: list[_FlakyBus] = []

    class Flaky(_FlakyBus):
        pass

    Flaky.down = down

    def bus(*args: Any, interface: str, channel: str, **kwargs: Any) -> can.BusABC:
        if down.is_set():
            raise can.CanInitializationError(f"No such device: {channel}")
        b = Flaky(channel=channel, **kwargs)
        opened.append(b)
        return b

    monkeypatch.setattr(can, "Bus", bus)
    sender = VirtualBus(channel=ch)
    tap = CanTap("can0", "virtual", ch, retry_interval=RETRY)
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    try:
        c.wait_event("open")
        sender.send(can.Message(arbitration_id=0x10, data=b"a", is_extended_id=False))
        c.wait(lambda c: len(c.items) == 1)
        down.set()
        lost = c.wait_event("lost")
        assert lost.level == WARNING
        assert "CanOperationError: Network is down" in lost.message and ch in lost.message
        time.sleep(5 * RETRY)
        c.pump()
        assert [e.kind for e in c.events] == ["passive", "open", "lost"]
        assert opened[0]._open is False  # the dead bus was shut down
        down.clear()
        reopened = c.wait_event("reopened")
        assert "gap" in reopened.message
        sender.send(can.Message(arbitration_id=0x11, data=b"b", is_extended_id=False))
        c.wait(lambda c: len(c.items) == 2)
        assert [f.arbitration_id for f in c.frames()] == [0x10, 0x11]
    finally:
        tap.stop()
        sender.shutdown()
    c.pump()
    assert [e.kind for e in c.events] == ["passive", "open", "lost", "reopened", "closed"]
    assert all(not b._open for b in opened)
    _no_tracebacks(capsys, caplog)


def test_listen_only_requested_from_hardware_interfaces(monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[dict[str, Any]] = []
    ch = _channel()

    def bus(*args: Any, interface: str, channel: str, **kwargs: Any) -> can.BusABC:
        seen.append({"interface": interface, "channel": channel, **kwargs})
        return VirtualBus(channel=ch)

    monkeypatch.setattr(can, "Bus", bus)
    tap = CanTap("can0", "pcan", "PCAN_USBBUS1", 1000000, retry_interval=RETRY)
    assert tap.passive == "yes"
    assert tap.settings["listen_only_options"] == {"state": "PASSIVE"}
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    try:
        c.wait_event("open")
        ev = c.of("passive")[0]
        assert ev.level == INFO and "state='PASSIVE'" in ev.message
    finally:
        tap.stop()
    assert seen[0]["state"] is can.BusState.PASSIVE
    assert seen[0]["bitrate"] == 1000000 and seen[0]["receive_own_messages"] is False


def test_listen_only_plan() -> None:
    assert listen_only_plan("kvaser", {}) == (
        {"driver_mode": False},
        "yes",
        "listen-only requested (driver_mode=False); the tap never sends",
    )
    assert listen_only_plan("vector", {})[0] == {"listen_only": True}
    assert listen_only_plan("slcan", {})[0] == {"listen_only": True}
    assert listen_only_plan("nixnet", {})[0] == {"listen_only": True}
    assert listen_only_plan("systec", {})[0] == {"state": can.BusState.PASSIVE}
    assert listen_only_plan("pcan", {"state": "passive"})[1] == "yes"
    extra, passive, why = listen_only_plan("pcan", {"state": can.BusState.ACTIVE})
    assert (extra, passive) == ({}, "no") and "overridden" in why
    assert listen_only_plan("slcan", {}, listen_only=False)[1] == "no"
    extra, passive, why = listen_only_plan("ixxat", {})
    assert (extra, passive) == ({}, "unknown") and "acknowledges" in why
    assert listen_only_plan("virtual", {})[1] == "yes"


REAL_CAN_LISTEN_ONLY = """\
4: can0: <NOARP,UP,LOWER_UP,ECHO> mtu 16 qdisc pfifo_fast state UP mode DEFAULT qlen 10
    link/can  promiscuity 0 minmtu 0 maxmtu 0
    can <LISTEN-ONLY> state ERROR-ACTIVE (berr-counter tx 0 rx 0) restart-ms 0
\t  bitrate 500000 sample-point 0.875
"""
REAL_CAN_NORMAL = """\
4: can0: <NOARP,UP,LOWER_UP,ECHO> mtu 16 qdisc pfifo_fast state UP mode DEFAULT qlen 10
    link/can  promiscuity 0 minmtu 0 maxmtu 0
    can state ERROR-ACTIVE (berr-counter tx 0 rx 0) restart-ms 0
"""
REAL_CAN_OTHER_MODES = REAL_CAN_NORMAL.replace("can state", "can <BERR-REPORTING,ONE-SHOT> state")
VCAN = """\
5: vcan0: <NOARP,UP,LOWER_UP> mtu 72 qdisc noqueue state UNKNOWN mode DEFAULT qlen 1000
    link/can  promiscuity 0 allmulti 0 minmtu 0 maxmtu 0
    vcan numtxqueues 1 numrxqueues 1 gso_max_size 65536 gso_max_segs 65535
"""


def test_parse_ip_link_details() -> None:
    assert parse_ip_link_details("can0", REAL_CAN_LISTEN_ONLY)[0] == "yes"
    passive, why = parse_ip_link_details("can0", REAL_CAN_NORMAL)
    assert passive == "unknown" and "listen-only on" in why and "listen-only is off" in why
    assert parse_ip_link_details("can0", REAL_CAN_OTHER_MODES)[0] == "unknown"
    assert parse_ip_link_details("vcan0", VCAN)[0] == "yes"
    assert parse_ip_link_details("x", "")[0] == "unknown"


@pytest.mark.skipif(not os.path.exists("/sys/class/net/vcan0"), reason="no vcan0 on this machine")
def test_socketcan_vcan0() -> None:  # pragma: no cover - depends on the kernel
    tap = CanTap("can0", "socketcan", "vcan0")
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    try:
        c.wait(lambda c: bool(c.of("open")))
        assert tap.passive == "yes"
        with REAL_BUS(interface="socketcan", channel="vcan0") as sender:
            sender.send(can.Message(arbitration_id=0x1, data=b"\x01", is_extended_id=False))
        c.wait(lambda c: len(c.items) >= 1)
    finally:
        tap.stop()


def test_tiny_queue_counts_drops() -> None:
    ch = _channel()
    sender = VirtualBus(channel=ch)
    tap = CanTap("can0", "virtual", ch)
    q = TapQueue(maxsize=8)
    c = Collector(q)
    tap.start(q)
    try:
        c.wait_event("open")  # consumes passive and open: the queue is empty
        for i in range(300):  # a fast producer, and nobody consuming
            sender.send(can.Message(arbitration_id=i, data=b"", is_extended_id=False))
        deadline = time.monotonic() + 5
        while q.dropped < 300 - 8 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        tap.stop()
        sender.shutdown()
    assert q.dropped >= 300 - 8
    n = q.new_drops()
    assert n == q.dropped
    assert q.new_drops() == 0
    c.pump()
    assert [f.arbitration_id for f in c.frames()] == list(range(8))


def test_socketcan_passive_read_from_link_and_rechecked_on_reopen(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import analyzer.sources.can_tap as can_tap

    ch = _channel()
    states = [("unknown", "listen-only is off for can9: hint"), ("yes", "listen-only is on")]
    checks: list[str] = []

    def passive(channel: str) -> tuple[str, str]:
        checks.append(channel)
        return states[0] if len(checks) == 1 else states[1]

    down = threading.Event()

    class Flaky(_FlakyBus):
        pass

    Flaky.down = down

    def bus(*args: Any, interface: str, channel: str, **kwargs: Any) -> can.BusABC:
        assert interface == "socketcan" and channel == "can9"
        return Flaky(channel=ch, **kwargs)

    monkeypatch.setattr(can_tap, "socketcan_passive", passive)
    monkeypatch.setattr(can, "Bus", bus)
    tap = CanTap("can0", "socketcan", "can9", retry_interval=RETRY)
    assert tap.passive == "unknown" and checks == []  # read at start, not at construction
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    try:
        c.wait_event("open")
        first = c.of("passive")[0]
        assert first.level == WARNING and first.message.startswith("passive: unknown: listen-only")
        assert tap.passive == "unknown" and tap.settings["passive"] == "unknown"
        down.set()
        c.wait_event("lost")
        down.clear()
        c.wait_event("reopened")
        second = c.wait_event("passive", 2)
        assert second.level == INFO and second.message == "passive: listen-only is on"
        assert tap.passive == "yes" and tap.settings["passive_reason"] == "listen-only is on"
    finally:
        tap.stop()
    assert checks == ["can9", "can9"]
