"""The one python-can Message <-> CanFrame conversion, and the parts that use it."""

from __future__ import annotations

import uuid
from pathlib import Path

import can
import pytest
from can.interfaces.virtual import VirtualBus
from taps.tap_helpers import Collector

from analyzer.sources.can_files import open_can_file
from analyzer.sources.can_message import frame_to_message, message_to_frame
from analyzer.sources.can_tap import CanTap
from analyzer.sources.live import TapQueue
from decoders.model import CanFrame

# (message, the frame it is): every kind of frame, with python-can's meaning of ``dlc``
CASES = [
    (
        can.Message(timestamp=1.5, arbitration_id=0x04FF0001, data=b"\x00\xf4\x01"),
        CanFrame(1.5, 0x04FF0001, b"\x00\xf4\x01", True, False, False, False, 3, None),
    ),
    (
        can.Message(timestamp=2.0, arbitration_id=0x7FF, is_extended_id=False, channel="can1"),
        CanFrame(2.0, 0x7FF, b"", False, False, False, False, 0, "can1"),
    ),
    (  # remote: a DLC, no data
        can.Message(arbitration_id=0x123, is_extended_id=False, is_remote_frame=True, dlc=5),
        CanFrame(0.0, 0x123, b"", False, True, False, False, 5, None),
    ),
    (  # classic CAN with a DLC of 9-15 carries 8 bytes
        can.Message(arbitration_id=0x123, is_extended_id=False, data=bytes(8), dlc=15),
        CanFrame(0.0, 0x123, bytes(8), False, False, False, False, 15, None),
    ),
    (  # CAN FD: dlc is the byte count
        can.Message(arbitration_id=0x1ABCDEF, is_fd=True, bitrate_switch=True, data=bytes(12)),
        CanFrame(0.0, 0x1ABCDEF, bytes(12), True, False, False, True, 12, None),
    ),
    (  # more than 8 bytes without the flag (a .csv lost it): still CAN FD
        can.Message(arbitration_id=0x1, data=bytes(64)),
        CanFrame(0.0, 0x1, bytes(64), True, False, False, True, 64, None),
    ),
    (
        can.Message(timestamp=3.0, is_error_frame=True, arbitration_id=0x80, dlc=0, channel=0),
        CanFrame(3.0, 0x80, b"", True, False, True, False, 0, "0"),
    ),
]


@pytest.mark.parametrize("msg,frame", CASES, ids=[str(i) for i in range(len(CASES))])
def test_message_to_frame(msg: can.Message, frame: CanFrame) -> None:
    assert message_to_frame(msg) == frame


@pytest.mark.parametrize("msg,frame", CASES, ids=[str(i) for i in range(len(CASES))])
def test_frame_to_message_and_back(msg: can.Message, frame: CanFrame) -> None:
    back = frame_to_message(frame)
    assert isinstance(back, can.Message)
    assert back.dlc == frame.length and bytes(back.data) == frame.data
    assert message_to_frame(back) == frame


def test_a_time_replaces_the_timestamp() -> None:
    msg = can.Message(timestamp=12.0, arbitration_id=1, data=b"\x01")
    assert message_to_frame(msg, t=99.5).t == 99.5
    assert message_to_frame(msg).t == 12.0
    assert frame_to_message(CanFrame(None, 1, b"")).timestamp == 0.0


def test_frame_without_dlc_gets_its_length() -> None:
    assert frame_to_message(CanFrame(1.0, 0x10, b"\x01\x02", False)).dlc == 2


def test_tap_and_capture_file_give_the_same_frames(tmp_path: Path) -> None:
    """The live tap and a capture of the same traffic agree frame for frame (remote DLCs,
    FD, DLC 15): both convert through can_message."""
    channel = f"eg2scope-test-{uuid.uuid4().hex}"
    sent = [frame_to_message(f) for _, f in CASES if not f.is_error]
    sender = VirtualBus(channel=channel)
    tap = CanTap("can0", "virtual", channel)
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    try:
        c.wait_event("open")
        for m in sent:
            sender.send(m)
        c.wait(lambda c: len(c.items) == len(sent))
    finally:
        tap.stop()
        sender.shutdown()
    live = [i.payload for i in c.items]
    path = tmp_path / "same.blf"
    with can.Logger(str(path)) as logger:
        for m in sent:
            logger.on_message_received(m)
    with open_can_file(path) as reader:
        filed = list(reader)
    assert reader.errors == []
    strip = [("t", None), ("channel", None)]
    assert [_without(f, strip) for f in live] == [_without(f, strip) for f in filed]
    assert [f.channel for f in live] == [channel] * len(sent)


def _without(frame: object, fields: list[tuple[str, None]]) -> CanFrame:
    assert isinstance(frame, CanFrame)
    values = {k: getattr(frame, k) for k in CanFrame.__dataclass_fields__}
    values.update(fields)
    return CanFrame(**values)
