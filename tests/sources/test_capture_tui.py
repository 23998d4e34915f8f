"""The TUI on the captures eg2scope reads now: the sample CAN capture as candump's default layout
(no times at all), as ``candump -td`` (gaps summed) and as a PCAN trace, replayed by the real
app at 80x24 and 200x50 (Textual's pilot) and in a real pseudo-terminal (pexpect + pyte): every
record arrives and the grippers' rows show what the -L original shows."""

from __future__ import annotations

import asyncio
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

import can
import pytest
from capture_helpers import CAN_LOG, ROOT, sample_frames, write_layout

from analyzer.session.capture import CaptureOptions, byte_protocol, open_reader
from analyzer.session.session import Session, SessionOptions
from analyzer.sources.can_message import frame_to_message
from analyzer.tui.app import Eg2ScopeApp, SessionPlan
from analyzer.tui.replay import ReplaySource
from analyzer.tui.widgets.devices import DevicePanel

os.environ["TEXTUAL_ANIMATIONS"] = "none"
pytestmark = pytest.mark.slow
SIZES = [(80, 24), (200, 50)]


def _capture(tmp_path: Path, layout: str) -> Path:
    frames = sample_frames()
    if layout == "trc":
        path = tmp_path / "capture.trc"
        with can.Logger(str(path)) as logger:
            for frame in frames:
                logger.on_message_received(frame_to_message(frame))
        return path
    return write_layout(tmp_path / f"capture-{layout or 'none'}.txt", frames, layout)


def _app(path: Path) -> Eg2ScopeApp:
    opts = CaptureOptions(str(path), progress=False)
    reader = open_reader(opts)
    source = ReplaySource(reader, None)

    def build(tui: list) -> Session:
        return Session(source, tui, SessionOptions(protocol=byte_protocol(opts)))

    return Eg2ScopeApp(SessionPlan(build, live=False, replay=source, title=path.name))


def _grippers(path: Path, size: tuple[int, int], expected: int) -> tuple[int, dict[int, object]]:
    """(records, {device: opening}) once the app has replayed the capture's records."""

    async def scenario() -> tuple[int, dict[int, object]]:
        app = _app(path)
        try:
            async with app.run_test(size=size) as pilot:
                await _until(pilot, lambda: app.store.count >= expected)
                panel = app.query_one(DevicePanel)
                await _until(pilot, lambda: len(panel.rows) >= 2)
                rows = {r.device: r.values["opening"] for r in panel.rows}
                count = app.store.count
                await pilot.press("q")  # as a user quits: the session stopped, then the app
                await _until(pilot, lambda: not app.is_running)
                return count, rows
        finally:
            if app.session is not None:
                app.session.stop()

    return asyncio.run(scenario())


async def _until(pilot: object, condition: Callable[[], bool], timeout: float = 20.0) -> None:
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            pytest.fail(f"timed out waiting for {condition}")
        await pilot.pause(0.1)  # type: ignore[attr-defined]


EXPECTED = len(CAN_LOG.read_text().splitlines())
ERROR_FRAMES = sum(f.is_error for f in sample_frames())  # python-can's TRCWriter drops them


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
@pytest.mark.parametrize("layout", ["", "d", "trc"], ids=["no-times", "td", "pcan-trace"])
def test_the_tui_replays_every_layout(tmp_path: Path, layout: str, size: tuple[int, int]) -> None:
    expected = EXPECTED - ERROR_FRAMES if layout == "trc" else EXPECTED
    count, rows = _grippers(_capture(tmp_path, layout), size, expected)
    want_count, want_rows = _grippers(CAN_LOG, size, EXPECTED)
    assert (count, want_count) == (expected, EXPECTED)
    assert rows == want_rows and rows[1] is not None and rows[2] is not None


def test_the_tui_in_a_real_terminal_on_a_log_without_times(tmp_path: Path) -> None:
    pexpect = pytest.importorskip("pexpect")
    pyte = pytest.importorskip("pyte")
    path = _capture(tmp_path, "")
    columns, lines = 80, 24
    screen = pyte.Screen(columns, lines)
    stream = pyte.ByteStream(screen)
    child = pexpect.spawn(
        sys.executable,
        ["-m", "analyzer", "tui", str(path)],
        cwd=str(ROOT),
        dimensions=(lines, columns),
        env={"TERM": "xterm-256color", "PATH": "/usr/bin:/bin", "TEXTUAL_ANIMATIONS": "none"},
    )
    try:
        end = time.monotonic() + 60
        text = ""
        while time.monotonic() < end and not ("replay done" in text and "can0   1" in text):
            try:
                stream.feed(child.read_nonblocking(65536, timeout=0.1))
            except (pexpect.TIMEOUT, pexpect.EOF):
                pass
            text = "\n".join(screen.display)
        assert "replay done" in text and "can0   1" in text, text
        child.send("q")
        child.expect(pexpect.EOF, timeout=30)
    finally:
        child.close(force=True)
    assert child.exitstatus == 0
