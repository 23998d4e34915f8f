"""A source that never opened fails at once, saying which device and why; one that is waited
for (``wait``: ``--wait``) is opened when it appears. Real ptys, a missing path, python-can
interfaces that cannot open (slcan on a missing port, pcan without its driver, socketcan on a
missing interface or a kernel without SocketCAN), and the session a view (the TUI) runs."""

from __future__ import annotations

import socket
import threading
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
from tap_helpers import Pty

from analyzer.errors import SourceError
from analyzer.model import SourceEvent
from analyzer.session.listener import Listener
from analyzer.session.session import Session
from analyzer.sources.can_tap import CanTap
from analyzer.sources.live import Tap, TapQueue
from analyzer.sources.serial_tap import SerialPairTap, SerialTap
from analyzer.sources.source import LiveSource
from decoders import build as b
from decoders.model import Record


@pytest.fixture
def pty() -> Iterator[Pty]:
    p = Pty()
    yield p
    p.close()


def _kernel_has_socketcan() -> bool:
    try:
        socket.socket(socket.PF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except (OSError, AttributeError):
        return False
    return True


def _start_fails(taps: list[Tap]) -> str:
    """``LiveSource.start`` raises SourceError at once; its message."""
    source = LiveSource(taps)
    t0 = time.monotonic()
    with pytest.raises(SourceError) as info:
        source.start()
    assert time.monotonic() - t0 < 3.0  # one attempt, not a retry loop
    assert all(not getattr(t, "running", False) for t in taps)  # every tap closed again
    return str(info.value)


def test_a_missing_serial_port_fails_at_once(tmp_path: Path) -> None:
    path = tmp_path / "ttyUSB0"
    message = _start_fails([SerialTap("rs485", str(path))])
    assert message == (
        f"cannot open {path}: no such port (--wait waits for a device that is not plugged in yet)"
    )


def test_a_port_that_exists_opens_and_captures(pty: Pty) -> None:
    source = LiveSource([SerialTap("rs485", pty.name)])
    source.start()
    try:
        pty.write(b"\x01\x02")
        got = b""
        deadline = time.monotonic() + 5
        stop = threading.Event()
        for batch in source.batches(stop):
            got += b"".join(x.payload.data for x in batch if not isinstance(x, SourceEvent))
            if got == b"\x01\x02" or time.monotonic() > deadline:
                break
        assert got == b"\x01\x02"
    finally:
        source.stop()


def test_one_source_that_never_opens_fails_the_command_and_says_which(
    pty: Pty, tmp_path: Path
) -> None:
    """A pty that opens and a path that does not: the error names the missing one only, and the
    tap that had opened is closed again (its port is free)."""
    missing = tmp_path / "ttyACM7"
    opened = SerialTap("rs232", pty.name)
    message = _start_fails([opened, SerialTap("rs485", str(missing))])
    assert f"cannot open {missing}: no such port" in message
    assert pty.name not in message
    assert not opened.running and not opened.is_open


def test_a_pair_with_one_missing_port_names_it(pty: Pty, tmp_path: Path) -> None:
    missing = tmp_path / "ttyUSB1"
    message = _start_fails([SerialPairTap("rs232", [pty.name, str(missing)])])
    assert message.startswith(f"cannot open {missing}: no such port")


def test_slcan_on_a_missing_port_fails_at_once(tmp_path: Path) -> None:
    """python-can's slcan opens a serial adapter: a missing one is said in the user's words."""
    message = _start_fails([CanTap("can0", "slcan", str(tmp_path / "ttyACM0"))])
    assert message.startswith(f"cannot open slcan channel {tmp_path / 'ttyACM0'}: ")
    assert "no such device or port" in message and "--wait" in message


def test_pcan_without_its_driver_fails_at_once() -> None:
    import can

    try:
        can.Bus(interface="pcan", channel="PCAN_USBBUS1").shutdown()
    except Exception as exc:  # the expected case on a machine without the PCAN driver
        why = str(exc)
    else:
        pytest.skip("a PCAN adapter is installed and opens here")
    if "library" not in why.lower() and "driver" not in why.lower():
        pytest.skip(f"the PCAN driver is installed (opening fails for another reason: {why})")
    message = _start_fails([CanTap("can0", "pcan", "PCAN_USBBUS1")])
    assert message.startswith("cannot open pcan channel PCAN_USBBUS1: driver not found (")
    assert "--wait" not in message  # waiting does not install a driver


@pytest.mark.skipif(not _kernel_has_socketcan(), reason="this kernel has no SocketCAN (AF_CAN)")
def test_socketcan_on_a_missing_interface_fails_at_once() -> None:
    name = f"nocan{uuid.uuid4().hex[:6]}"
    message = _start_fails([CanTap(name, "socketcan", name)])
    assert message.startswith(f"cannot open socketcan channel {name}: no such CAN interface")


@pytest.mark.skipif(_kernel_has_socketcan(), reason="this kernel has SocketCAN (AF_CAN)")
def test_socketcan_on_a_kernel_without_it_fails_at_once_and_says_why() -> None:
    message = _start_fails([CanTap("can0", "socketcan", "can0")])
    assert message == (
        "cannot open socketcan channel can0: this kernel has no SocketCAN "
        "(address family AF_CAN not supported)"
    )


class _Collect(Listener):
    def __init__(self) -> None:
        self.records: list[Record] = []
        self.closed = False

    def on_records(self, records: list[Record]) -> None:  # type: ignore[override]
        self.records += records

    def close(self) -> None:
        self.closed = True


def test_the_session_a_view_runs_fails_at_once(tmp_path: Path) -> None:
    """The TUI builds a session on the taps and runs it on a thread: ``run`` raises the
    SourceError at once (the view shows it and exits 1), and its outputs are closed."""
    collect = _Collect()
    session = Session(LiveSource([SerialTap("rs485", str(tmp_path / "ttyUSB9"))]), [collect])
    failure: list[BaseException] = []

    def run() -> None:
        try:
            session.run()
        except BaseException as exc:
            failure.append(exc)

    thread = threading.Thread(target=run)
    thread.start()
    thread.join(5)
    assert not thread.is_alive()
    assert len(failure) == 1 and isinstance(failure[0], SourceError)
    assert "ttyUSB9: no such port" in str(failure[0])
    assert collect.closed and collect.records == []


def test_wait_waits_for_a_port_plugged_in_later(pty: Pty, tmp_path: Path) -> None:
    link = tmp_path / "ttyUSB0"
    tap = SerialTap("rs232", str(link), retry_interval=0.05, wait=True)
    source = LiveSource([tap])
    source.start()  # does not fail: the port is waited for
    try:
        time.sleep(0.3)
        assert not tap.is_open
        link.symlink_to(pty.name)
        frame = b.serial_frame(1, 0x41)
        deadline = time.monotonic() + 5
        while not tap.is_open and time.monotonic() < deadline:
            time.sleep(0.02)
        pty.write(frame)
        got = b""
        events: list[SourceEvent] = []
        stop = threading.Event()
        for batch in source.batches(stop):
            for x in batch:
                if isinstance(x, SourceEvent):
                    events.append(x)
                else:
                    got += x.payload.data
            if got == frame or time.monotonic() > deadline:
                break
        assert got == frame
        waiting = [e for e in events if e.kind == "open" and e.message.startswith("waiting")]
        assert len(waiting) == 1 and "no such port" in waiting[0].message
        assert any(e.kind == "open" and "after waiting" in e.message for e in events)
    finally:
        source.stop()


def test_a_queue_drained_of_a_failed_start(tmp_path: Path) -> None:
    """The events of taps that did not open do not linger for a later run of the source."""
    source = LiveSource([SerialTap("rs485", str(tmp_path / "gone"))])
    with pytest.raises(SourceError):
        source.start()
    assert isinstance(source.queue, TapQueue) and source.queue.get_batch(0.0) == []
