"""A recorder killed with SIGKILL mid-session: everything but the last flush period is
recovered from the file it leaves, with one clear, consistent message, and reading never
raises."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from mcap_checks import assert_time_ordered

from analyzer.recording.reader import McapCaptureReader
from decoders.model import CanFrame, Chunk

ROOT = Path(__file__).resolve().parents[2]

CHILD = r"""
import sys, time
from analyzer.recording.recorder import McapRecorder
from analyzer.model import Item
from decoders.model import CanFrame, Chunk

rec = McapRecorder(sys.argv[1], {"passive": "yes"}, flush_interval_s=0.5)
print("ready", flush=True)
n = 0
start = time.monotonic()
next_report = start + 0.5
while True:  # 2000 items/s, in batches every 10 ms, as a session gives them
    due = int((time.monotonic() - start) * 2000)
    batch = []
    while n < due:
        data = n.to_bytes(4, "little")
        if n % 2:
            batch.append(Item("can0", CanFrame(time.time(), 0x100 + n % 5, data)))
        else:
            batch.append(Item("ttyUSB0", Chunk(data, time.time(), "request"), "tx"))
        n += 1
    rec.on_raw(batch)
    rec.tick(time.time())
    now = time.monotonic()
    if now >= next_report:
        print(n, flush=True)
        next_report += 0.5
    time.sleep(0.01)
"""


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
def test_sigkilled_recorder_leaves_a_recoverable_file(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(path)], stdout=subprocess.PIPE, env=env, text=True
    )
    reports: list[tuple[float, int]] = []  # (when the parent saw it, items written by then)
    ready = threading.Event()

    def read_reports() -> None:
        assert child.stdout is not None
        for line in child.stdout:
            if line.strip() == "ready":
                ready.set()
            elif line.strip().isdigit():
                reports.append((time.monotonic(), int(line)))

    reader = threading.Thread(target=read_reports, daemon=True)
    reader.start()
    try:
        assert ready.wait(30), "the recorder did not start"
        time.sleep(2.5)
    finally:
        killed_at = time.monotonic()
        child.send_signal(signal.SIGKILL)
        child.wait(10)
        reader.join(5)
    assert child.returncode == -signal.SIGKILL
    assert reports, "the recorder reported nothing"
    # everything written up to ~1 s before the kill must be recovered
    safe = max((n for when, n in reports if when <= killed_at - 1.0), default=0)
    assert safe >= 1000, reports  # ~1.5 s of writing at 2000/s

    with McapCaptureReader(path) as rd:
        items = list(rd)  # must not raise
        errors = rd.errors
        assert rd.metadata.get("passive") == "yes"
    size = path.stat().st_size
    assert len(errors) == 1 and errors[0].startswith("recovered a damaged recording: read ")
    # one consistent account: the file ends after its last whole record (killed between
    # two flushes), or in the middle of one (killed while writing)
    assert errors[0] in (
        f"recovered a damaged recording: read all {len(items)} /raw and /events messages in its "
        f"{size} bytes; it was not finished (no index: the recorder was killed or did not "
        "close it), so what it had not yet written is lost",
    ) or (
        errors[0].startswith(
            f"recovered a damaged recording: read {len(items)} /raw and /events messages; the "
            "file is cut short in the middle of a record at byte "
        )
        and f" of {size} (the recorder was killed or the copy cut)" in errors[0]
    ), errors
    assert "ends in the middle" not in errors[0]
    assert assert_time_ordered(path, finished=False) >= len(items)
    assert len(items) >= safe, (len(items), reports)
    # the recovered items are exactly the first ones written, in order
    for n, item in enumerate(items):
        p = item.payload
        assert p.data == n.to_bytes(4, "little")
        if n % 2:
            assert isinstance(p, CanFrame) and item.bus == "can0"
            assert p.arbitration_id == 0x100 + n % 5
        else:
            assert isinstance(p, Chunk) and (item.bus, item.stream, p.direction) == (
                "ttyUSB0",
                "tx",
                "request",
            )
