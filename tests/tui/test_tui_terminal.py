"""``eg2scope tui`` as a user runs it: a process in a real pseudo-terminal (pexpect), the
screen read back through a terminal emulator (pyte), keys sent as a person types them, ``q``
to quit; the terminal is restored, the exit status is the contract's and the ``-o``
recording (or ``--rerun`` file) is complete. Every kind of input at 80x24 and 200x50."""

from __future__ import annotations

import fcntl
import json
import os
import pty
import re
import select
import signal
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

import pytest
from conftest import ROOT, eg2scope

from analyzer.recording.layout import MARKS
from analyzer.recording.reader import McapCaptureReader, read_metadata

pexpect = pytest.importorskip("pexpect")
pyte = pytest.importorskip("pyte")
pytestmark = pytest.mark.slow

COLUMNS, LINES = 200, 50
# a row: [seq] time (or, for a record without one in a narrow list, #seq) bus dir ID name
ROW = re.compile(r"^.\s*(?:\d+\s+)?(-|#\d+|[\d.]+)\s+(\S+)\s+([→←·])\s+(ID \d+|-)\s+(\S+)")


class Terminal:
    def __init__(
        self, argv: list[str], size: tuple[int, int] = (COLUMNS, LINES), **env: str
    ) -> None:
        columns, lines = size
        self.screen = pyte.Screen(columns, lines)
        self.stream = pyte.ByteStream(self.screen)
        self.raw = bytearray()
        self.child = pexpect.spawn(
            argv[0],
            argv[1:],
            cwd=str(ROOT),
            dimensions=(lines, columns),
            env={
                "TERM": "xterm-256color",
                "PATH": "/usr/bin:/bin",
                "TEXTUAL_ANIMATIONS": "none",
                **env,
            },
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

    def type(self, keys: str, gap: float = 0.05) -> None:
        """Keys one at a time, ``gap`` seconds apart (a person typing at normal speed)."""
        for key in keys:
            self.child.send(key)
            time.sleep(gap)
            self.read()

    def quit(self, timeout: float = 30.0) -> int | None:
        """``q``, then the exit status once the process has gone."""
        self.child.send("q")
        return finished(self, timeout)

    def after(self) -> str:
        """What was printed once the app had given the terminal back."""
        raw = bytes(self.raw)
        return raw[raw.rfind(b"\x1b[?1049l") :].decode(errors="replace")


def tui(*argv: str) -> list[str]:
    return [sys.executable, "-m", "analyzer", "tui", *argv]


def test_tui_demo_in_a_real_terminal(tmp_path: Path) -> None:
    out = tmp_path / "demo.mcap"
    term = Terminal([sys.executable, "-m", "analyzer", "tui", "--demo", "-o", str(out)])
    try:
        term.wait_for("commands")  # the footer
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


SIZES = {"80x24": (80, 24), "200x50": (200, 50)}
KINDS = [
    "serial dump", "modbus dump", "candump log", ".asc", ".blf", "demo recording", "can recording",
]  # fmt: skip


@pytest.mark.parametrize("size", list(SIZES))
@pytest.mark.parametrize("kind", KINDS)
def test_every_input_in_a_real_terminal(inputs: dict[str, Path], kind: str, size: str) -> None:
    """The capture replays to its end; every row on screen has time, bus, direction, ID and a
    whole name (or one that ends in an ellipsis), times never run backwards; q exits 0."""
    term = Terminal(tui(str(inputs[kind])), SIZES[size])
    try:
        screen = term.wait_for("replay done")
        rows = [m for line in screen.splitlines() if (m := ROW.match(line))]
        assert len(rows) >= 5, screen
        names = {m.group(5) for m in rows}
        assert not any(re.fullmatch(r"CMD_\w*", n) and len(n) <= 5 for n in names), names
        reached: dict[str, float] = {}  # a bus's own clock may step back: its order is kept
        keys = []
        for m in rows:
            if m.group(1)[0] not in "-#":
                t = float(m.group(1))
                keys.append(
                    reached.setdefault(m.group(2), t) if t < reached.get(m.group(2), t) else t
                )
                reached[m.group(2)] = keys[-1]
        assert keys == sorted(keys), screen
        status = term.quit()
    finally:
        if term.child.isalive():
            term.child.terminate(force=True)
    assert status == 0, term.after()
    assert "records decoded" in term.after()


def test_marks_typed_at_normal_speed_and_the_palette_in_the_demo() -> None:
    """m a and ' a typed 50 ms apart set and find the mark; Ctrl+P opens the palette and Esc
    closes it without a crash; q exits 0."""
    term = Terminal(tui("--demo"), SIZES["80x24"])
    try:
        term.wait_for("rs485")
        term.type(" ")  # pause the view: the cursor stays on one frame
        term.wait_for("paused")
        term.type("ma")
        term.wait_for("marks a")
        term.type("G")  # follow the newest frame again, then jump back to the mark
        term.wait_for("following")
        term.type("'a")
        term.wait_for("paused")
        assert "mark this frame" not in term.text()  # the prompt is gone
        term.child.send("\x10")  # Ctrl+P
        term.wait_for("Search for commands")
        term.type("\x1b")
        time.sleep(0.5)
        term.read()
        assert "Search for commands" not in term.text()
        status = term.quit()
    finally:
        if term.child.isalive():
            term.child.terminate(force=True)
    assert status == 0, term.after()


def test_rerun_on_the_tui_writes_a_real_rrd(tmp_path: Path, inputs: dict[str, Path]) -> None:
    """``--rerun FILE.rrd`` logs what ``record --rerun`` logs; where it went is said after the
    app has gone."""
    sys.path.insert(0, str(ROOT / "tests" / "rerun"))
    from rrd_helpers import read_rrd  # tests/rerun's reader of .rrd files

    for argv, name in (
        ([str(inputs["demo recording"])], "capture.rrd"),
        (["--demo"], "live.rrd"),
    ):
        out = tmp_path / name
        term = Terminal(tui(*argv, "--rerun", str(out)), SIZES["80x24"])
        try:
            term.wait_for("replay done" if argv != ["--demo"] else "rs485")
            time.sleep(1.0)
            status = term.quit()
        finally:
            if term.child.isalive():
                term.child.terminate(force=True)
        assert status == 0, term.after()
        assert f"Rerun recording written to {out}" in term.after()
        rrd = read_rrd(out)
        assert rrd.blueprints
        buses = {path.split("/")[1] for path in rrd.entities}
        assert {"can0", "rs232", "rs485"} <= buses, sorted(rrd.entities)


@pytest.mark.parametrize("source", ["recording", "demo"])
def test_an_engine_that_cannot_apply_is_a_usage_error(
    inputs: dict[str, Path], source: str, tmp_path: Path
) -> None:
    """A recording of serial lines (several byte streams) is no input of the native engine,
    nor is the live demo on its serial lines: a usage error before the demo starts (its
    scenario's truth file is left as it was)."""
    truth = tmp_path / "truth.jsonl"
    truth.write_text("kept\n")
    demo = ["--demo", "--scenario", "grip", "--truth", str(truth)]
    argv = [str(inputs["demo recording"])] if source == "recording" else demo
    term = Terminal(tui(*argv, "--engine", "native"))
    term.child.expect(pexpect.EOF, timeout=30)
    term.child.close()
    assert term.child.exitstatus == 2
    assert b"--engine native" in term.child.before
    assert truth.read_text() == "kept\n" and b"simulated" not in term.child.before


def finished(term: Terminal, timeout: float = 30.0) -> int | None:
    """The exit status once the process has gone by itself."""
    end = time.monotonic() + timeout
    while term.child.isalive() and time.monotonic() < end:
        term.read()
    term.read()
    if term.child.isalive():
        term.child.terminate(force=True)
        pytest.fail(f"still running {timeout} s on; the screen:\n{term.text()}")
    term.child.close()
    return term.child.exitstatus


@pytest.mark.parametrize("size", list(SIZES))
def test_esc_cancels_the_filter_and_the_mark_prompt_then_q_quits(size: str) -> None:
    """/ then Esc: the box goes and the list has the keys again (q quits, not typed in); an
    invalid filter then Esc: the applied filter stays, said so; m then Esc cancels the mark."""
    term = Terminal(tui(str(ROOT / "captures" / "can_pick_place.log")), SIZES[size])
    try:
        term.wait_for("replay done")
        term.type("/", gap=0.3)
        term.type("\x1b", gap=0.5)  # Esc alone: a terminal sends no more after it
        term.wait_for("filter edit cancelled")  # the toast: "...; everything is shown"
        term.type("/dev == 1\r", gap=0.1)
        term.wait_for("of 91 shown")
        term.type("/", gap=0.3)  # the box takes the keys again, its text selected
        term.type("dev == 1 and", gap=0.1)
        term.wait_for("not applied")
        term.type("\x1b", gap=1.0)
        screen = term.text()
        assert "not applied" not in screen  # the error line went with the edit
        assert "dev == 1 and" not in screen and "dev == 1" in screen  # the applied one, back
        assert "of 91 shown" in screen
        term.type("m", gap=0.3)
        term.wait_for("mark this frame")
        term.type("\x1b", gap=0.5)
        term.wait_for("cancelled")
        assert "mark this frame" not in term.text() and "marks" not in term.text()
        status = term.quit()
    finally:
        if term.child.isalive():
            term.child.terminate(force=True)
    assert status == 0, term.after()


def cut_candump_log(folder: Path) -> Path:
    out = folder / "cut.log"
    out.write_bytes((ROOT / "captures" / "can_pick_place.log").read_bytes()[:1000])
    return out


@pytest.mark.parametrize("kind", ["serial dump", "cut candump log"])
def test_following_shows_the_newest_row_of_a_small_replay_at_80x24(
    tmp_path: Path, inputs: dict[str, Path], kind: str
) -> None:
    """A capture decoded in one update, shorter than two screens: "following" shows its
    newest record (the truncated frame at its end), not its first page."""
    path = inputs[kind] if kind in inputs else cut_candump_log(tmp_path)
    term = Terminal(tui(str(path)), SIZES["80x24"])
    try:
        screen = term.wait_for("replay done")
        time.sleep(1.0)  # the list has laid out its final size
        term.read()
        screen = term.text()
        assert "following" in screen
        rows = [line for line in screen.splitlines() if ROW.match(line)]
        assert rows, screen
        last = rows[-1]
        if kind == "serial dump":
            assert "truncated frame (9 bytes)" in last, screen
        else:  # the last whole line of the log: device 1's answer, 64.34 ms in
            assert "0.064340" in last and "←" in last and "ID 1" in last, screen
        status = term.quit()
    finally:
        if term.child.isalive():
            term.child.terminate(force=True)
    assert status in (0, 3), term.after()


@pytest.mark.parametrize(
    ("kind", "want"), [("serial dump", 0), ("cut candump log", 3), (".blf", 0)]
)
def test_sigterm_after_a_finished_replay_is_no_interruption(
    tmp_path: Path, inputs: dict[str, Path], kind: str, want: int
) -> None:
    """The whole capture was read: SIGTERM (as q and Ctrl+C) ends it 0, or 3 if damaged."""
    path = inputs[kind] if kind in inputs else cut_candump_log(tmp_path)
    term = Terminal(tui(str(path)), SIZES["80x24"])
    try:
        term.wait_for("replay done")
        time.sleep(0.5)
        term.child.kill(signal.SIGTERM)
        status = finished(term)
    finally:
        if term.child.isalive():
            term.child.terminate(force=True)
    assert status == want, term.after()
    assert "read to its end" in term.after()


def test_sigterm_before_the_end_of_a_replay_is_an_interruption(inputs: dict[str, Path]) -> None:
    """A replay in real time (--speed 1) stopped part-way: 130, and it says how far it got."""
    term = Terminal(tui(str(inputs["demo recording"]), "--speed", "1"), SIZES["80x24"])
    try:
        term.wait_for("replay playing")
        time.sleep(0.5)
        term.child.kill(signal.SIGTERM)
        status = finished(term)
    finally:
        if term.child.isalive():
            term.child.terminate(force=True)
    assert status == 130, term.after()
    assert "stopped at" in term.after()


def test_without_a_terminal_the_engine_usage_error_comes_first(inputs: dict[str, Path]) -> None:
    """Usage errors of the command line before "the TUI needs a terminal"."""
    done = eg2scope("tui", str(inputs["demo recording"]), "--engine", "native")
    assert done.returncode == 2
    assert "--engine native" in done.stderr and "needs a terminal" not in done.stderr
    done = eg2scope("tui", str(ROOT / "captures" / "serial_session.bin"))
    assert done.returncode == 2 and "needs a terminal" in done.stderr


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_a_signal_ends_the_live_tui_at_once(tmp_path: Path, sig: signal.Signals) -> None:
    """``systemctl stop``, ``kill``, the terminal's SIGHUP: the live session is stopped (0),
    within seconds, its recording finished."""
    out = tmp_path / "run.mcap"
    term = Terminal(tui("--demo", "-o", str(out)), SIZES["80x24"])
    try:
        term.wait_for("rs485")
        term.child.kill(sig)
        status = finished(term, timeout=10)
    finally:
        if term.child.isalive():
            term.child.terminate(force=True)
    assert status == 0, term.after()
    assert "records decoded" in term.after()
    with McapCaptureReader(out) as reader:
        assert list(reader) and not reader.damaged


def test_keep_says_the_oldest_go_in_a_real_terminal() -> None:
    term = Terminal(tui("--demo", "--keep", "1000"), SIZES["200x50"])
    try:
        term.wait_for("keeping the last 1,000", timeout=60)
        status = term.quit()
    finally:
        if term.child.isalive():
            term.child.terminate(force=True)
    assert status == 0, term.after()


def test_no_color_runs_the_tui_in_monochrome() -> None:
    """NO_COLOR=1: Textual's monochrome filter reads every segment's style; a row padded with
    no style crashed the app at its first short row."""
    term = Terminal(tui("--demo"), SIZES["80x24"], NO_COLOR="1")
    try:
        term.wait_for("rs485")
        time.sleep(2.0)
        status = term.quit()
    finally:
        if term.child.isalive():
            term.child.terminate(force=True)
    assert status == 0, term.after()
    assert b"Traceback" not in term.raw and b"AttributeError" not in term.raw


def test_the_live_tui_ends_when_its_terminal_goes() -> None:
    """The pty's master closed (the window, the ssh connection, the script driving it gone):
    the kernel hangs the terminal up (SIGHUP to its session): the app ends, 0, at once."""
    term = Terminal(tui("--demo"), SIZES["80x24"])
    try:
        term.wait_for("rs485")
        term.child.ptyproc.fileobj.close()  # the master: nothing else holds it
        end = time.monotonic() + 10
        while term.child.isalive() and time.monotonic() < end:
            time.sleep(0.1)
        assert not term.child.isalive(), "still running 10 s after its terminal went"
    finally:
        if term.child.isalive():
            term.child.terminate(force=True)
    assert term.child.exitstatus == 0


@pytest.mark.parametrize(("kind", "want"), [("live", 0), ("replay", 130)])
def test_a_tui_on_a_terminal_that_hangs_up_without_a_signal_ends(
    inputs: dict[str, Path], kind: str, want: int
) -> None:
    """A terminal that is not the process's controlling one sends no SIGHUP when it goes: the
    app sees the hang-up itself and ends (live 0; a replay cut short 130), where Textual alone
    read the ended input in a busy loop and its writes then waited forever (SIGTERM too)."""
    argv = ["--demo"] if kind == "live" else [str(inputs["demo recording"]), "--speed", "1"]
    ready = "ID 1" if kind == "live" else "replay playing"
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 80, 0, 0))
    env = {"TERM": "xterm-256color", "PATH": "/usr/bin:/bin", "TEXTUAL_ANIMATIONS": "none"}
    proc = subprocess.Popen(
        tui(*argv), cwd=ROOT, env=env, stdin=slave, stdout=slave, stderr=slave,
        start_new_session=True,  # a session of its own, without a controlling terminal
    )  # fmt: skip
    os.close(slave)
    try:
        screen = pyte.Screen(80, 24)
        stream = pyte.ByteStream(screen)
        end = time.monotonic() + 30
        while ready not in "\n".join(screen.display) and time.monotonic() < end:
            if select.select([master], [], [], 0.1)[0]:
                stream.feed(os.read(master, 65536))
        assert ready in "\n".join(screen.display), "\n".join(screen.display)
        os.close(master)
        master = -1
        assert proc.wait(timeout=10) == want
    finally:
        if master >= 0:
            os.close(master)
        if proc.poll() is None:
            proc.kill()
            proc.wait()
