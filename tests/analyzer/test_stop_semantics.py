"""A user's stop is not an error of the bus: the frame it cuts and the requests still waiting
are flagged ``cut_off`` (no error, not ``unanswered``); a source that was really lost keeps
``truncated`` and "no response before the source was lost". Real ptys, python-can's virtual
bus on both engines, and recordings decoded again."""

from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Sequence
from typing import Any

import can
import pytest
from native_core import needs_native

from analyzer.model import Item, SourceEvent
from analyzer.session.listener import Listener
from analyzer.session.session import Session, SessionOptions
from analyzer.sources.can_tap import CanTap
from analyzer.sources.serial_tap import SerialTap
from analyzer.sources.source import LiveSource
from decoders import build as b
from decoders.model import Record

STOPPED = "no response before the capture was stopped"


class StopWhen(Listener):
    """Collects what the session gives and stops it once ``enough(raw items so far)``."""

    wants_raw = True

    def __init__(self, session_box: list[Session], enough: Any) -> None:
        self.box = session_box
        self.enough = enough
        self.raw: list[Item] = []
        self.records: list[Record] = []
        self.events: list[SourceEvent] = []

    def on_raw(self, items: list[Any]) -> None:
        self.raw += items
        if self.enough(self.raw):
            self.box[0].stop()  # in this batch: before a quiet line could decide the bytes

    def on_records(self, records: Sequence[Record]) -> None:
        self.records += list(records)

    def on_event(self, event: SourceEvent) -> None:
        self.events.append(event)


def _run(session: Session, timeout: float = 10.0) -> None:
    thread = threading.Thread(target=session.run, daemon=True)
    thread.start()
    thread.join(timeout)
    assert not thread.is_alive(), "the session did not end"


def test_a_stop_cuts_off_the_frame_begun_and_the_request_waiting(pty: Any) -> None:
    request = b.serial_frame(1, 0x41)  # read run state: waits for its answer
    cut = b.serial_frame(2, 0x41)[:3]
    box: list[Session] = []
    collect = StopWhen(box, lambda raw: sum(len(i.payload.data) for i in raw) >= 9)
    source = LiveSource([SerialTap("rs232", pty.name)])
    box.append(Session(source, [collect], SessionOptions(protocol="eg2-serial")))
    source.start()
    pty.write(request + cut)
    _run(box[0])
    kinds = [(r.kind, r.flags, r.errors) for r in collect.records]
    assert kinds == [("frame", ["cut_off"], []), ("cut_off", ["cut_off"], [])]
    req, tail = collect.records
    assert req.warnings == [STOPPED] and req.pair is None
    assert tail.raw == cut and tail.summary == "frame cut off by the stop (3 bytes)"
    assert tail.warnings == ["cut off by the stop: the capture was stopped 3 bytes into this frame"]
    assert box[0].counts.errors == 0
    assert [e.kind for e in collect.events][-1] == "closed"


def test_a_lost_port_keeps_the_damage(pty: Any) -> None:
    """The port goes away with a frame begun and a request waiting: those are the bus's
    problem (truncated, unanswered "before the source was lost"), and the stop after it cuts
    off nothing more."""
    request = b.serial_frame(1, 0x41)
    box: list[Session] = []
    lost = threading.Event()

    class Watch(StopWhen):
        def on_event(self, event: SourceEvent) -> None:
            super().on_event(event)
            if event.kind == "lost":
                lost.set()

    collect = Watch(box, lambda raw: False)
    tap = SerialTap("rs232", pty.name, retry_interval=5.0)
    source = LiveSource([tap])
    box.append(Session(source, [collect], SessionOptions(protocol="eg2-serial")))
    source.start()
    thread = threading.Thread(target=box[0].run, daemon=True)
    thread.start()
    pty.write(request + b"\xeb\x90")
    deadline = time.monotonic() + 3
    while sum(len(i.payload.data) for i in collect.raw) < 8 and time.monotonic() < deadline:
        time.sleep(0.01)
    pty.close()  # the adapter is pulled out
    assert lost.wait(5)
    box[0].stop()
    thread.join(10)
    assert [(r.kind, r.flags) for r in collect.records] == [
        ("frame", ["unanswered"]),
        ("truncated", ["truncated"]),
    ]
    assert collect.records[0].warnings == ["no response before the source was lost"]
    assert box[0].counts.errors == 1


def _can_stop_records(engine: str) -> list[dict[str, Any]]:
    channel = f"eg2scope-stop-{uuid.uuid4().hex}"
    sender = can.Bus(interface="virtual", channel=channel)
    box: list[Session] = []
    collect = StopWhen(box, lambda raw: len(raw) >= 2)
    source = LiveSource([CanTap("can0", "virtual", channel)])
    box.append(Session(source, [collect], SessionOptions(engine=engine)))
    source.start()
    try:
        for frame in (b.can_read_request(1, 1120, 8), b.can_read_request(2, 1120, 8)):
            msg = can.Message(arbitration_id=frame.arbitration_id, data=frame.data)
            sender.send(msg)
        _run(box[0])
    finally:
        sender.shutdown()
    return [
        {k: v for k, v in r.to_dict().items() if k not in ("t", "latency_ms")}
        for r in collect.records
    ]


@pytest.mark.parametrize(
    "engine",
    [
        "python",
        "native",  # needs the core (tests/conftest.py: native_engine_case)
    ],
)
def test_can_requests_waiting_at_a_stop_are_cut_off(engine: str) -> None:
    records = _can_stop_records(engine)
    assert [(r["device"], r["flags"], r["warnings"]) for r in records] == [
        (1, ["cut_off"], [STOPPED]),
        (2, ["cut_off"], [STOPPED]),
    ]


@needs_native
def test_both_engines_cut_off_alike() -> None:
    assert _can_stop_records("native") == _can_stop_records("python")


@pytest.fixture
def pty() -> Any:
    from taps.tap_helpers import Pty

    p = Pty()
    yield p
    p.close()
