"""Live serial taps on real pseudo-terminals (os.openpty in raw mode)."""

from __future__ import annotations

import os
import random
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from tap_helpers import Collector as BaseCollector
from tap_helpers import Pty

from analyzer.model import INFO, WARNING, Item
from analyzer.sources.live import TapQueue
from analyzer.sources.serial_tap import SerialBridge, SerialPairTap, SerialTap
from decoders.model import Chunk

RETRY = 0.05


class Collector(BaseCollector):
    """The tap queue, drained; plus the captured bytes per stream."""

    def data(self, stream: str | None = None) -> bytes:
        return b"".join(_chunk(i).data for i in self.items if stream is None or i.stream == stream)

    def wait_bytes(self, n: int, stream: str | None = None, timeout: float = 5.0) -> None:
        self.wait(lambda c: len(c.data(stream)) >= n, timeout)


def _chunk(item: Item) -> Chunk:
    assert isinstance(item.payload, Chunk)
    return item.payload


@pytest.fixture
def ptys() -> Iterator[Callable[[], Pty]]:
    made: list[Pty] = []

    def make() -> Pty:
        p = Pty()
        made.append(p)
        return p

    yield make
    for p in made:
        p.close()


def _no_tracebacks(capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture) -> None:
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    assert not [r for r in caplog.records if r.levelno >= 30 or r.exc_info]


def test_serial_tap_captures_in_order_and_never_writes(
    ptys: Callable[[], Pty], capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    p = ptys()
    tap = SerialTap("rs485", p.name, 115200, retry_interval=RETRY)
    assert tap.passive == "yes" and tap.settings["port"] == p.name
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    try:
        passive = c.wait_event("passive")
        assert passive.level == INFO and "never writes" in passive.message
        opened = c.wait_event("open")
        assert opened.level == INFO and p.name in opened.message and "115200" in opened.message
        sent = b""
        for i in range(30):
            chunk = bytes([i]) * (1 + i % 7) + b"\x00\xff\x11\x13\r\n"  # incl. XON/XOFF, CR/LF
            p.write(chunk)
            sent += chunk
            time.sleep(0.002)
        c.wait_bytes(len(sent))
        assert c.data() == sent
        ts = [_chunk(i).t for i in c.items]
        assert all(t is not None for t in ts)
        assert ts == sorted(ts)  # type: ignore[type-var]
        assert all(i.bus == "rs485" and i.stream == p.name for i in c.items)
        assert all(_chunk(i).direction is None for i in c.items)
        # nothing was ever written to the tapped port
        assert not p.readable(0.2)
    finally:
        t0 = time.monotonic()
        tap.stop()
        assert time.monotonic() - t0 < 0.5
    c.pump()
    closed = c.of("closed")
    assert len(closed) == 1 and f"{len(sent)} bytes" in closed[0].message
    assert not p.readable(0.05)
    _no_tracebacks(capsys, caplog)


def test_pair_tap_frames_each_wire_separately(ptys: Callable[[], Pty]) -> None:
    a, b = ptys(), ptys()
    tap = SerialPairTap("rs232", [a.name, b.name], 9600, directions=["request", "response"])
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    try:
        c.wait_event("open", 2)
        to_a = bytes(range(256)) * 4
        to_b = b"device says hello" * 40
        for i in range(0, 1024, 128):
            a.write(to_a[i : i + 128])
            b.write(to_b[i : i + 128])
        b.write(to_b[1024:])
        c.wait_bytes(len(to_a), a.name)
        c.wait_bytes(len(to_b), b.name)
        assert c.data(a.name) == to_a
        assert c.data(b.name) == to_b
        directions = {i.stream: _chunk(i).direction for i in c.items}
        assert directions == {a.name: "request", b.name: "response"}
        assert tap.passive == "yes"
        assert not a.readable(0.1) and not b.readable(0.0)
    finally:
        tap.stop()
    c.pump()
    assert len(c.of("closed")) == 2


def _read_until(p: Pty, n: int, into: bytearray, stop: threading.Event) -> None:
    while len(into) < n and not stop.is_set():
        if p.readable(0.05):
            into += os.read(p.master, 65536)


def test_bridge_relays_both_ways_unchanged(ptys: Callable[[], Pty]) -> None:
    host, device = ptys(), ptys()
    tap = SerialBridge("rs232", host.name, device.name, 115200)
    assert tap.passive == "no" and tap.settings["inline"] is True
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    rng = random.Random(42)
    up = rng.randbytes(6000)  # host -> device
    down = rng.randbytes(5000)  # device -> host
    at_device, at_host = bytearray(), bytearray()
    halt = threading.Event()
    readers = [
        threading.Thread(target=_read_until, args=(device, len(up), at_device, halt)),
        threading.Thread(target=_read_until, args=(host, len(down), at_host, halt)),
    ]
    try:
        passive = c.wait_event("passive")
        assert passive.level == WARNING and "not passive" in passive.message
        c.wait_event("open", 2)
        for r in readers:
            r.start()
        i = j = 0
        while i < len(up) or j < len(down):  # interleaved, random chunk sizes
            n = rng.randint(1, 400)
            host.write(up[i : i + n])
            i += n
            m = rng.randint(1, 400)
            device.write(down[j : j + m])
            j += m
            if rng.random() < 0.2:
                time.sleep(0.001)
        for r in readers:
            r.join(10)
        assert bytes(at_device) == up
        assert bytes(at_host) == down
        c.wait_bytes(len(up), "host")
        c.wait_bytes(len(down), "device")
        assert c.data("host") == up
        assert c.data("device") == down
        for item in c.items:
            want = "request" if item.stream == "host" else "response"
            assert _chunk(item).direction == want
        assert tap.unrelayed == {"host": 0, "device": 0}
    finally:
        halt.set()
        tap.stop()


def test_unplug_and_replug(
    ptys: Callable[[], Pty],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
) -> None:
    link = tmp_path / "ttyEG2"
    first = ptys()
    link.symlink_to(first.name)
    tap = SerialTap("rs485", str(link), retry_interval=RETRY)
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    try:
        c.wait_event("open")
        first.write(b"before")
        c.wait_bytes(6)
        first.close()  # adapter unplugged: reads on the tap side fail
        link.unlink()  # and its device node goes away
        lost = c.wait_event("lost")
        assert lost.level == WARNING and str(link) in lost.message and "retrying" in lost.message
        time.sleep(6 * RETRY)  # several failed retries: no more events
        c.pump()
        assert [e.kind for e in c.events] == ["passive", "open", "lost"]
        second = ptys()
        link.symlink_to(second.name)
        reopened = c.wait_event("reopened")
        assert (
            reopened.level == INFO and "gap" in reopened.message and str(link) in reopened.message
        )
        second.write(b"after")
        c.wait_bytes(11)
        assert c.data() == b"beforeafter"
        t_before = _chunk(c.items[0]).t
        t_after = _chunk(c.items[-1]).t
        assert t_before is not None and t_after is not None
        assert t_after - t_before >= 6 * RETRY
        assert lost.t <= reopened.t
    finally:
        tap.stop()
    c.pump()
    assert [e.kind for e in c.events] == ["passive", "open", "lost", "reopened", "closed"]
    _no_tracebacks(capsys, caplog)


def test_port_missing_at_start_is_waited_for_with_wait(
    ptys: Callable[[], Pty],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
) -> None:
    path = tmp_path / "ttyUSB0"
    tap = SerialTap("rs485", str(path), retry_interval=RETRY, wait=True)
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    try:
        assert tap.first_open() is None  # waited for: not a failure
        err = c.wait_event("open")
        assert err.level == WARNING
        assert err.message == (
            f"waiting for {path} (no such port; retrying with back-off from 0.05 s up to 5 s)"
        )
        time.sleep(4 * RETRY)
        c.pump()
        assert len(c.of("open")) == 1  # reported once, not at every retry
        p = ptys()
        path.symlink_to(p.name)
        ok = c.wait_event("open", 2)
        assert ok.level == INFO and "after waiting" in ok.message
        p.write(b"\x01\x02\x03")
        c.wait_bytes(3)
        assert c.data() == b"\x01\x02\x03"
    finally:
        tap.stop()
    _no_tracebacks(capsys, caplog)


def test_stop_while_retrying_is_quick(tmp_path: Path) -> None:
    ports = [str(tmp_path / "a"), str(tmp_path / "b")]
    tap = SerialPairTap("rs232", ports, retry_interval=0.5, wait=True)
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    c.wait_event("open", 2)
    t0 = time.monotonic()
    tap.stop()
    assert time.monotonic() - t0 < 0.6
    c.pump()
    assert len(c.of("closed")) == 2
    assert not tap.running


def test_url_ports_open(ptys: Callable[[], Pty]) -> None:
    tap = SerialTap("rs485", "loop://", 57600)
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    try:
        ev = c.wait_event("open")
        assert ev.level == INFO and "loop://" in ev.message
    finally:
        tap.stop()
    assert not c.items  # the tap never wrote, so the loopback returned nothing
    with pytest.raises(TypeError, match="read_timeout"):
        SerialTap("rs485", "loop://", timeout=1)


def test_tiny_queue_counts_drops(ptys: Callable[[], Pty]) -> None:
    p = ptys()
    tap = SerialTap("rs485", p.name)
    q = TapQueue(maxsize=4)
    tap.start(q)
    try:
        deadline = time.monotonic() + 5
        # passive + open fill part of the queue; then a fast producer overflows it
        while q.dropped == 0 and time.monotonic() < deadline:
            p.write(b"x")
            time.sleep(0.002)
        assert q.dropped > 0
    finally:
        tap.stop()
    dropped = q.dropped
    assert q.new_drops() == dropped
    assert q.new_drops() == 0
