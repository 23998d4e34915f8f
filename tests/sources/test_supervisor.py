"""The supervisor loop shared by the taps: back-off, repeats collapsed into one event, fatal
settings; on python-can's virtual bus (an adapter stuck in bus-off) and a real pty."""

from __future__ import annotations

import itertools
import time
import uuid
from collections.abc import Callable
from typing import Any

import can
import pytest
from can.interfaces.virtual import VirtualBus
from taps.tap_helpers import Collector

from analyzer.model import ERROR, INFO, WARNING
from analyzer.sources.can_tap import CanTap
from analyzer.sources.live import TapQueue
from analyzer.sources.supervisor import Backoff

FIRST, CAP = 0.05, 0.4


def _channel() -> str:
    return f"eg2scope-test-{uuid.uuid4().hex}"


class _BusOff(VirtualBus):
    """An adapter that opens fine but fails every receive (stuck in bus-off)."""

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        raise can.CanOperationError("bus-off (error passive, TX error counter 256)")


def _buses(monkeypatch: pytest.MonkeyPatch, broken: Callable[[int], bool]) -> list[float]:
    """can.Bus opens a virtual bus; the n-th open (from 1) is stuck in bus-off when
    ``broken(n)``. Returns the (monotonic) times of the opens."""
    opened: list[float] = []

    def bus(*args: Any, interface: str, channel: str, **kwargs: Any) -> can.BusABC:
        opened.append(time.monotonic())
        kind = _BusOff if broken(len(opened)) else VirtualBus
        return kind(channel=channel, **kwargs)

    monkeypatch.setattr(can, "Bus", bus)
    return opened


def test_bus_off_backs_off_and_collapses_the_repeats(monkeypatch: pytest.MonkeyPatch) -> None:
    opened = _buses(monkeypatch, lambda n: True)
    tap = CanTap("can0", "virtual", _channel(), retry_interval=FIRST, max_retry_interval=CAP)
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    time.sleep(2.0)
    tap.stop()
    c.pump()
    # 0.05 + 0.1 + 0.2 + 0.4 + 0.4 ... : about 7 opens in 2 s, not thousands
    assert 4 <= len(opened) <= 9
    gaps = [b - a for a, b in itertools.pairwise(opened)]
    wants = [min(FIRST * 2**i, CAP) for i in range(len(gaps))]
    assert all(want * 0.9 <= gap <= want + 0.3 for gap, want in zip(gaps, wants, strict=True))
    kinds = [e.kind for e in c.events]
    assert kinds == ["passive", "open", "lost", "reopened", "lost", "closed"]
    first_lost, summary = c.of("lost")
    assert first_lost.count == 1 and first_lost.level == WARNING
    assert "bus-off" in first_lost.message
    assert "retrying with back-off from 0.05 s up to 0.4 s" in first_lost.message
    # every loss after the first reopen, in one event: the counts add up to every loss
    assert summary.count == len(opened) - 1
    assert first_lost.count + summary.count == len(opened)
    assert summary.level == WARNING
    assert f"{summary.count} more times" in summary.message and "bus-off" in summary.message
    assert summary.to_dict()["count"] == summary.count


def test_a_series_is_reported_once_the_device_works_again(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    opened = _buses(monkeypatch, lambda n: n <= 4)  # four bad opens, then it works
    ch = _channel()
    tap = CanTap("can0", "virtual", ch, retry_interval=FIRST, max_retry_interval=0.2)
    q = TapQueue()
    c = Collector(q)
    sender = VirtualBus(channel=ch)
    tap.start(q)
    try:
        summary = c.wait_event("lost", 2)  # while running, not at the end
        assert tap.is_open and len(opened) == 5
        assert summary.count == 3 and "open again now" in summary.message
        assert "reopened after each" in summary.message
        sender.send(can.Message(arbitration_id=0x01180001, data=b"\x08"))
        c.wait(lambda c: len(c.items) == 1)
    finally:
        tap.stop()
        sender.shutdown()
    c.pump()
    kinds = [e.kind for e in c.events]
    assert kinds == ["passive", "open", "lost", "reopened", "lost", "closed"]
    assert sum(e.count for e in c.of("lost")) == 4


def test_a_setting_the_interface_refuses_is_not_retried(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[dict[str, Any]] = []

    def bus(*args: Any, **kwargs: Any) -> can.BusABC:
        calls.append(kwargs)
        raise ValueError("bitrate 123 is not supported by this adapter")

    monkeypatch.setattr(can, "Bus", bus)
    tap = CanTap("can0", "virtual", _channel(), 123, retry_interval=FIRST)
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    try:
        err = c.wait_event("open")
        time.sleep(5 * FIRST)
    finally:
        tap.stop()
    assert err.level == ERROR and err.message.endswith("; not retrying")
    assert "bitrate 123 is not supported" in err.message
    assert len(calls) == 1
    assert tap.failed == "ValueError: bitrate 123 is not supported by this adapter"


def test_back_off_bounds() -> None:
    assert Backoff().first == 0.5 and Backoff().cap == 5.0 and Backoff().summary_every == 30.0
    with pytest.raises(ValueError):
        Backoff(2.0, 1.0)
    with pytest.raises(ValueError):
        Backoff(0.0, 1.0)


def test_a_lost_device_that_stays_away_is_one_lost_event(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Gone for good: one "lost", then quiet retries (backing off), no summary of nothing."""
    state = {"up": True}
    opened: list[float] = []

    def bus(*args: Any, interface: str, channel: str, **kwargs: Any) -> can.BusABC:
        if not state["up"]:
            opened.append(time.monotonic())
            raise can.CanInitializationError("No such device")
        state["up"] = False  # the first bus dies at once, and the adapter with it
        return _BusOff(channel=channel, **kwargs)

    monkeypatch.setattr(can, "Bus", bus)
    tap = CanTap("can0", "virtual", _channel(), retry_interval=FIRST, max_retry_interval=CAP)
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    time.sleep(1.2)
    tap.stop()
    c.pump()
    assert [e.kind for e in c.events] == ["passive", "open", "lost", "closed"]
    assert c.of("open")[0].level == INFO
    assert 3 <= len(opened) <= 6  # 0.05, 0.1, 0.2, 0.4, 0.4: backing off
