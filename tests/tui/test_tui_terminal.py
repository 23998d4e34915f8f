"""``eg2scope tui --demo`` as a user runs it: a process in a real pseudo-terminal (pexpect),
the screen read back through a terminal emulator (pyte), keys sent, ``q`` to quit; the
terminal is restored and the ``-o`` recording is complete."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import pytest

from analyzer.recording import MARKS, McapCaptureReader, read_metadata

pexpect = pytest.importorskip("pexpect")
pyte = pytest.importorskip("pyte")
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
COLUMNS, LINES = 200, 50


class Terminal:
    def __init__(self, argv: list[str]) -> None:
        self.screen = pyte.Screen(COLUMNS, LINES)
        self.stream = pyte.ByteStream(self.screen)
        self.raw = bytearray()
        self.child = pexpect.spawn(
            argv[0],
            argv[1:],
            cwd=str(ROOT),
            dimensions=(LINES, COLUMNS),
            env={"TERM": "xterm-256color", "PATH": "/usr/bin:/bin", "TEXTUAL_ANIMATIONS": "none"},
        )

    def read(self) -> None:
        while True:
            try:
                data = self.child.read_nonblocking(65536, timeout=0.05)
            except (pexpect.TIMEOUT, pexpect.EOF):
                return
            if not data:
                return
            self.raw += data
            self.stream.feed(data)

    def text(self) -> str:
        return "\n".join(self.screen.display)

    def wait_for(self, words: str, timeout: float = 30.0) -> str:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.read()
            if words in self.text():
                return self.text()
            time.sleep(0.1)
        pytest.fail(f"{words!r} never appeared; the screen:\n{self.text()}")


def test_tui_demo_in_a_real_terminal(tmp_path: Path) -> None:
    out = tmp_path / "demo.mcap"
    term = Terminal([sys.executable, "-m", "analyzer", "tui", "--demo", "-o", str(out)])
    try:
        term.wait_for("command palette")  # the footer
        term.wait_for("rs485")  # frames and the device panel's gripper rows
        term.child.send("?")
        assert "every key" in term.wait_for("every key")
        term.child.send("\x1b")  # Esc closes the help
        time.sleep(0.5)
        term.child.send(" ")  # pause the view, then mark the frame under the cursor
        term.wait_for("paused")
        term.child.send("m")
        time.sleep(0.3)
        term.child.send("a")
        term.wait_for("marks a")
        term.child.send("q")
        end = time.monotonic() + 30
        while term.child.isalive() and time.monotonic() < end:
            term.read()
        term.read()
    finally:
        if term.child.isalive():
            term.child.terminate(force=True)
    term.child.close()
    assert term.child.exitstatus == 0
    raw = bytes(term.raw)
    # the terminal is given back: alternate screen left, cursor shown, mouse reporting off
    assert raw.rfind(b"\x1b[?1049h") < raw.rfind(b"\x1b[?1049l")
    assert b"\x1b[?25h" in raw[raw.rfind(b"\x1b[?1049l") - 200 :]
    assert raw.rfind(b"\x1b[?1000h") < raw.rfind(b"\x1b[?1000l")
    assert b"records decoded" in raw  # the summary line after the app has gone
    # the recording is complete: an intact file with raw input, metadata and the mark
    reader = McapCaptureReader(out)
    with reader:
        items = list(reader)
    assert not reader.damaged and not reader.errors and items
    assert read_metadata(out)["tool"] == "eg2scope"
    from mcap.reader import make_reader

    with out.open("rb") as f:
        marks = [json.loads(m.data) for _, c, m in make_reader(f).iter_messages(topics=[MARKS])]
    assert [m["name"] for m in marks] == ["a"]
