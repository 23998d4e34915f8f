"""A gap recorded live (the port lost, then reopened) is shown in place when the recording is
replayed: the reader yields the recorded source events in time order between the raw input."""

from __future__ import annotations

import json
import os
import threading
import time
from pathlib import Path

import pytest
from mcap_checks import assert_time_ordered
from taps.tap_helpers import Pty

from analyzer.cli import main
from analyzer.model import INFO, WARNING, Item, SourceEvent
from analyzer.recording.reader import McapCaptureReader, read_events
from analyzer.recording.recorder import McapRecorder
from analyzer.session.session import live_session
from analyzer.sources.live import wait_open
from analyzer.sources.serial_tap import SerialTap
from decoders import build as b
from decoders.model import Chunk

T0 = 1_763_700_000.0


def poll(gripper: int, opening: int) -> bytes:
    return b.serial_frame(gripper, 0xD9) + b.serial_frame(
        gripper, 0xD9, b.u16le(opening), response=True
    )


def wait_for(condition: object, timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():  # type: ignore[operator]
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)


def test_a_gap_recorded_live_is_shown_when_replayed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    link = tmp_path / "ttyEG2"
    first = Pty()
    link.symlink_to(first.name)
    path = tmp_path / "gap.mcap"
    tap = SerialTap("rs232", str(link), retry_interval=0.05)
    session = live_session([tap], [McapRecorder(path, {})])
    runner = threading.Thread(target=session.run, daemon=True)
    runner.start()
    second = None
    try:
        assert wait_open([tap], 5.0)
        os.write(first.master, poll(1, 500))
        time.sleep(0.3)
        first.close()  # the adapter is unplugged
        link.unlink()
        wait_for(lambda: not tap.is_open)
        time.sleep(0.3)
        second = Pty()  # and plugged in again
        link.symlink_to(second.name)
        wait_for(lambda: tap.is_open)
        os.write(second.master, poll(1, 400))
        time.sleep(0.3)
    finally:
        session.stop()
        runner.join(10)
        if second is not None:
            second.close()
    assert not runner.is_alive()
    assert_time_ordered(path)

    with McapCaptureReader(path) as reader:
        replay = list(reader)
        assert reader.errors == []
    kinds = [x.kind if isinstance(x, SourceEvent) else "data" for x in replay]
    gap = [k for k in kinds if k in ("data", "lost", "reopened")]
    # the data before the gap, the gap, the data after it: in that order
    assert gap[0] == "data" and gap[-1] == "data", kinds
    assert gap.index("lost") < gap.index("reopened"), kinds
    assert gap[gap.index("lost") : gap.index("reopened") + 1] == ["lost", "reopened"], kinds
    data = b"".join(x.payload.data for x in replay if isinstance(x, Item))
    assert data == poll(1, 500) + poll(1, 400)
    # the records' own problems are not replayed as events: decoding finds them again
    assert "decode" not in kinds

    # and the command line shows the gap, in text and in JSONL
    assert main(["decode", str(path)]) == 0
    text = capsys.readouterr().out
    assert "lost " in text and "reopened " in text and "gap" in text, text
    assert main(["decode", str(path), "--format", "jsonl"]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    events = [d["event"] for d in lines if d["kind"] == "event"]
    assert events.index("lost") < events.index("reopened"), events
    assert sum(1 for d in lines if d["kind"] == "frame") == 4


def test_replayed_events_keep_everything_they_were_recorded_with(tmp_path: Path) -> None:
    path = tmp_path / "events.mcap"
    events = [
        SourceEvent(T0 + 0.5, "can0", WARNING, "can0 lost: retrying", "lost"),
        SourceEvent(T0 + 0.9, "can0", WARNING, "can0 failed to receive (bus-off)", "lost", 1907),
        SourceEvent(T0 + 1.5, "can0", INFO, "can0 reopened after a 1.00 s gap", "reopened"),
    ]
    items = [Item("s", Chunk(bytes([k]), T0 + k * 0.4)) for k in range(6)]
    with McapRecorder(path, {}) as rec:  # one batch: written in time order
        rec.on_raw(items)
        for ev in events:
            rec.on_event(ev)
    assert_time_ordered(path)
    with McapCaptureReader(path) as reader:
        replay = list(reader)
    # by time: items at 0.0, 0.4, the lost at 0.5, 0.8, the lost at 0.9, 1.2, reopened at 1.5
    assert replay == [
        items[0],
        items[1],
        events[0],
        items[2],
        events[1],
        items[3],
        events[2],
        items[4],
        items[5],
    ]
    assert list(read_events(path)) == events
