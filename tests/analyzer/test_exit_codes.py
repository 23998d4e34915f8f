"""Exit codes a script can trust, through real processes (docs/contracts.md, "Exit codes"):

- a live source that never opened: 1 at once, saying which device and why, no file made;
- a live command stopped by Ctrl-C or SIGTERM (live, record, bridge, demo, live plot, the TUI,
  the simulator): 0, with its recording finished; a ``--duration`` that ran out: 0;
- a file job (decode, stats, batch) interrupted before the end of its input: 130;
- an empty capture: 0, said on stderr; damage: 3, without the "empty" note.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import orjson
import pytest
from cli_process import ENV, eg2scope
from recording.mcap_checks import assert_time_ordered
from taps.tap_helpers import Pty

from analyzer.recording.reader import McapCaptureReader
from decoders import build as b

ROOT = Path(__file__).resolve().parents[2]
CAPTURES = ROOT / "captures"
SIGNALS = ["SIGINT", "SIGTERM"]


def start(*args: str) -> subprocess.Popen[str]:
    """The command, its stdout and stderr going to files (a pipe nobody reads would fill
    and hold the capture up); ``stop_with`` reads them."""
    outputs = tempfile.TemporaryFile("w+"), tempfile.TemporaryFile("w+")  # noqa: SIM115
    proc = subprocess.Popen(
        [sys.executable, "-m", "analyzer", *args],
        stdout=outputs[0],
        stderr=outputs[1],
        text=True,
        env=ENV,
        cwd=ROOT,
    )
    proc.outputs = outputs  # type: ignore[attr-defined]
    return proc


def outputs(proc: subprocess.Popen[str]) -> tuple[str, str]:
    proc.wait(timeout=60)
    texts = []
    for f in proc.outputs:  # type: ignore[attr-defined]
        f.seek(0)
        texts.append(f.read())
        f.close()
    return texts[0], texts[1]


def wait_for_data(path: Path, proc: subprocess.Popen[str], size: int = 4096) -> None:
    """Until the recording ``path`` holds data (the source opened, frames came), so a signal
    stops a capture that runs."""
    deadline = time.monotonic() + 60
    while not (path.exists() and path.stat().st_size > size):
        assert proc.poll() is None, outputs(proc)[1]
        assert time.monotonic() < deadline, "no data was recorded"
        time.sleep(0.1)
    time.sleep(0.5)


def wait_reading(proc: subprocess.Popen[str], path: Path, past: int = 1 << 16) -> None:
    """Until the process has read ``past`` bytes of ``path`` (Linux: its descriptor's position
    in /proc), so a signal interrupts the job, not the interpreter's start."""
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        for fd in Path(f"/proc/{proc.pid}/fd").iterdir():
            try:
                if Path(os.readlink(fd)) != path:
                    continue
                info = Path(f"/proc/{proc.pid}/fdinfo/{fd.name}").read_text()
            except OSError:
                continue
            if int(info.split()[1]) > past:  # "pos: N"
                return
        time.sleep(0.05)
    raise AssertionError("the job did not start reading its input")


def stop_with(proc: subprocess.Popen[str], sig: str) -> tuple[str, str]:
    proc.send_signal(getattr(signal, sig))
    return outputs(proc)


def assert_finished(path: Path) -> list[object]:
    """The MCAP recording is complete (summary, index and footer written) and readable."""
    from mcap.reader import make_reader

    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count > 0
    assert_time_ordered(path)
    with McapCaptureReader(path) as reader:
        items = list(reader)
        assert not reader.errors
    return items


@pytest.fixture
def pty() -> Iterator[Pty]:
    p = Pty()
    yield p
    p.close()


# -- a source that never opened: 1 at once ----------------------------------------------------


@pytest.mark.parametrize("command", ["live", "record"])
def test_a_missing_port_fails_at_once_and_touches_no_file(tmp_path: Path, command: str) -> None:
    out = tmp_path / "run.mcap"
    out.write_bytes(b"a recording the user keeps")
    port = tmp_path / "ttyUSB0"
    t0 = time.monotonic()
    # --force: even where replacing it is allowed, a source that never opened touches nothing
    res = eg2scope(command, "--serial", str(port), "-o", str(out), "--force", "--duration", "30")
    assert time.monotonic() - t0 < 20  # not retried until --duration runs out
    assert res.returncode == 1, res.stderr
    assert res.stderr.strip() == (
        f"eg2scope: error: cannot open {port}: no such port "
        "(--wait waits for a device that is not plugged in yet)"
    )
    assert out.read_bytes() == b"a recording the user keeps"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.mcap"]


def test_one_missing_source_of_several_fails_the_command_and_says_which(tmp_path: Path) -> None:
    port = tmp_path / "ttyACM0"
    res = eg2scope("live", "-i", "virtual", "-c", "eg2scope-ok", "--serial", str(port))
    assert res.returncode == 1, res.stderr
    assert f"cannot open {port}: no such port" in res.stderr
    assert "eg2scope-ok" not in res.stderr and "Traceback" not in res.stderr


def test_a_can_interface_that_fails_to_open_is_exit_1(tmp_path: Path) -> None:
    res = eg2scope("live", "-i", "slcan", "-c", str(tmp_path / "ttyACM0"), "-f", "jsonl")
    assert res.returncode == 1, res.stderr
    assert f"cannot open slcan channel {tmp_path / 'ttyACM0'}: no such device" in res.stderr
    assert res.stdout == ""


def test_socketcan_on_a_missing_interface_is_exit_1() -> None:
    res = eg2scope("live", "-i", "socketcan", "-c", "nocan9", "--duration", "30")
    assert res.returncode == 1, res.stderr
    # which words depends on the kernel: no such interface, or no SocketCAN at all
    assert "cannot open socketcan channel nocan9: " in res.stderr
    assert "no such CAN interface" in res.stderr or "no SocketCAN" in res.stderr


def test_wait_waits_and_a_duration_ends_cleanly(tmp_path: Path) -> None:
    port = tmp_path / "ttyUSB0"
    res = eg2scope("live", "--serial", str(port), "--wait", "--duration", "1", "-f", "jsonl")
    assert res.returncode == 0, res.stderr
    events = [orjson.loads(line) for line in res.stdout.splitlines()]
    assert any(e["event"] == "open" and e["message"].startswith("waiting for") for e in events)


# -- a live capture stopped by the user: 0, recording finished ---------------------------------


@pytest.mark.parametrize("sig", SIGNALS)
@pytest.mark.parametrize("command", ["record", "demo", "plot"])
def test_the_demo_stopped_by_a_signal_is_a_clean_end(
    tmp_path: Path, command: str, sig: str
) -> None:
    out = tmp_path / "demo.mcap"
    extra = ["--save", str(tmp_path / "demo.rrd")] if command == "plot" else []
    demo = [] if command == "demo" else ["--demo"]
    proc = start(command, *demo, "-o", str(out), *extra)
    wait_for_data(out, proc)
    _, err = stop_with(proc, sig)
    assert proc.returncode == 0, err
    assert "eg2scope: stopped: " in err and "Traceback" not in err
    assert_finished(out)
    if command == "plot":
        from rerun.chunk import RrdReader

        chunks = list(RrdReader(tmp_path / "demo.rrd").stream())
        assert chunks  # the plot's file is written, and reads to its end


@pytest.mark.parametrize("sig", SIGNALS)
def test_live_on_a_port_stopped_by_a_signal_is_a_clean_end(
    tmp_path: Path, pty: Pty, sig: str
) -> None:
    out = tmp_path / "live.mcap"
    proc = start("live", "--serial", pty.name, "-p", "serial", "-o", str(out), "-f", "jsonl")
    frame = b.serial_frame(1, 0x41) + b.serial_frame(1, 0x41, bytes(7), response=True)
    deadline = time.monotonic() + 30
    while not (out.exists() and out.stat().st_size > 2048) and time.monotonic() < deadline:
        pty.write(frame)
        time.sleep(0.05)
    stdout, err = stop_with(proc, sig)
    assert proc.returncode == 0, err
    assert_finished(out)
    records = [orjson.loads(x) for x in stdout.splitlines()]
    assert records[-1]["event"] == "closed"
    assert not any("truncated" in r.get("flags", ()) for r in records)


@pytest.mark.parametrize("sig", SIGNALS)
def test_the_bridge_stopped_by_a_signal_is_a_clean_end(tmp_path: Path, sig: str) -> None:
    host, device = Pty(), Pty()
    out = tmp_path / "bridge.mcap"
    try:
        proc = start("bridge", host.name, device.name, "-p", "serial", "-o", str(out))
        deadline = time.monotonic() + 30
        while not (out.exists() and out.stat().st_size > 2048) and time.monotonic() < deadline:
            host.write(b.serial_frame(1, 0x41))
            time.sleep(0.05)
        _, err = stop_with(proc, sig)
    finally:
        host.close()
        device.close()
    assert proc.returncode == 0, err
    assert_finished(out)


@pytest.mark.parametrize("sig", SIGNALS)
def test_the_tui_stopped_by_a_signal_is_a_clean_end(tmp_path: Path, sig: str) -> None:
    import pexpect

    out = tmp_path / "tui.mcap"
    child = pexpect.spawn(
        sys.executable,
        ["-m", "analyzer", "tui", "--demo", "-o", str(out)],
        dimensions=(24, 80),
        env={**ENV, "TERM": "xterm-256color"},
        cwd=str(ROOT),
    )
    try:
        deadline = time.monotonic() + 60
        while not (out.exists() and out.stat().st_size > 4096):
            assert child.isalive() and time.monotonic() < deadline
            try:
                child.read_nonblocking(1 << 16, timeout=0.1)
            except pexpect.TIMEOUT:
                pass
        child.kill(getattr(signal, sig))
        child.expect(pexpect.EOF, timeout=60)
    finally:
        child.close()
    assert child.exitstatus == 0, child.before
    assert_finished(out)


def test_the_simulator_stopped_by_sigterm_is_a_clean_end() -> None:
    proc = start("sim", "serial")
    stdout = proc.outputs[0]  # type: ignore[attr-defined]
    deadline = time.monotonic() + 30
    while (stdout.seek(0) or True) and "Ctrl-C stops." not in stdout.read():  # serving
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.1)
    _, err = stop_with(proc, "SIGTERM")
    assert proc.returncode == 0, err


@pytest.mark.parametrize("how", ["SIGINT", "duration"])
def test_a_clean_demo_ends_without_a_single_error(tmp_path: Path, how: str) -> None:
    """No noise, stopped by Ctrl-C or by the end of --duration: no record has an error (the
    frames the stop cut are cut_off, not truncated), and the recording decodes to the same."""
    out = tmp_path / "clean.mcap"
    if how == "duration":
        res = eg2scope("record", "--demo", "--noise", "0", "-o", str(out), "--duration", "4")
        code, err = res.returncode, res.stderr
    else:
        proc = start("record", "--demo", "--noise", "0", "-o", str(out))
        wait_for_data(out, proc, 1 << 16)
        _, err = stop_with(proc, how)
        code = proc.returncode
    assert code == 0, err
    assert " 0 with errors" in err
    replay = eg2scope("decode", str(out), "-f", "jsonl")
    assert replay.returncode == 0, replay.stderr
    records = [orjson.loads(x) for x in replay.stdout.splitlines()]
    assert sum(1 for r in records if r["kind"] != "event") > 100
    assert not [r for r in records if r.get("errors")]
    warnings = {w for r in records for w in r.get("warnings", ())}
    assert "no response before the source was lost" not in warnings
    assert "no response before the end of the capture" not in warnings  # the recording says
    # what the stop cut comes last on its bus: after its first cut_off record, nothing else
    for bus in {r["bus"] for r in records}:
        on_bus = [r for r in records if r["bus"] == bus and r["kind"] != "event"]
        cut = ["cut_off" in r["flags"] for r in on_bus]
        assert cut == sorted(cut), bus


# -- file jobs interrupted: 130 -----------------------------------------------------------------


@pytest.fixture(scope="module")
def big_dump(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A raw serial dump long enough that the Python decoders take many seconds on it."""
    path = tmp_path_factory.mktemp("big") / "big.bin"
    exchange = b.serial_frame(1, 0xD9) + b.serial_frame(1, 0xD9, b.u16le(500), response=True)
    path.write_bytes(exchange * 400_000)
    return path


@pytest.fixture(scope="module")
def big_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A candump log long enough that decoding it with the Python engine takes many seconds."""
    path = tmp_path_factory.mktemp("big") / "big.log"
    request = b.can_read_request(1, 1120, 8)
    response = b.can_read_response(1, 1120, bytes(8))
    with path.open("w") as f:
        for i in range(400_000):
            frame = (request, response)[i % 2]
            f.write(f"({1.7e9 + i * 1e-4:.6f}) can0 {frame.arbitration_id:08X}#")
            f.write(frame.data.hex().upper() + "\n")
    return path


@pytest.mark.parametrize("sig", SIGNALS)
@pytest.mark.parametrize(
    "args",
    [
        ["decode", "--engine", "python", "-j", "1"],  # one session
        ["decode", "--engine", "python", "-j", "2"],  # parts in worker processes
        ["stats"],
    ],
    ids=["decode", "decode-parts", "stats"],
)
def test_a_file_job_interrupted_is_130(
    tmp_path: Path, big_dump: Path, args: list[str], sig: str
) -> None:
    out = ["-o", str(tmp_path / "out.jsonl"), "-f", "jsonl"] if args[0] == "decode" else []
    proc = start(args[0], str(big_dump), *args[1:], *out)
    wait_reading(proc, big_dump)
    assert proc.poll() is None, "the job ended before it could be interrupted"
    _, err = stop_with(proc, sig)
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == "eg2scope: interrupted" and "Traceback" not in err


def wait_for_a_child(proc: subprocess.Popen[str]) -> None:
    """Until the process has forked its first child (spun on: the window is milliseconds)."""
    children = Path(f"/proc/{proc.pid}/task/{proc.pid}/children")
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        if children.read_text().split():
            return
    pytest.fail("no worker process was started")


@pytest.mark.parametrize("sig", SIGNALS)
def test_a_signal_while_the_parts_workers_start_is_130_without_a_traceback(
    tmp_path: Path, big_dump: Path, sig: str
) -> None:
    """The signal comes as the pool forks its workers: no worker prints a KeyboardInterrupt
    (it ran the parent's handler before its own setup), and the parent does not lose the
    interrupt inside a fork hook ("Exception ignored", then exit 0)."""
    for _ in range(5):
        out = tmp_path / "out.jsonl"
        argv = ["--engine", "python", "-j", "4", "-o", str(out), "-f", "jsonl"]
        proc = start("decode", str(big_dump), *argv)
        wait_for_a_child(proc)
        _, err = stop_with(proc, sig)
        assert proc.returncode == 130, err
        assert "Traceback" not in err and "Exception ignored" not in err, err


def test_batch_interrupted_is_130(tmp_path: Path, big_dump: Path) -> None:
    proc = start("batch", str(big_dump), "-o", str(tmp_path / "fleet"), "--workers", "1")
    wait_reading(proc, big_dump, 1 << 20)
    assert proc.poll() is None
    _, err = stop_with(proc, "SIGTERM")
    assert proc.returncode == 130, err


# -- empty and damaged captures ------------------------------------------------------------------


def _empty_captures(tmp_path: Path) -> dict[str, Path]:
    import can

    paths = {name: tmp_path / name for name in ("empty.bin", "empty.log", "empty.asc")}
    paths["empty.bin"].write_bytes(b"")
    paths["empty.log"].write_text("# a candump log with no frame\n")
    with can.ASCWriter(str(paths["empty.asc"])):
        pass  # a header and no frame
    blf = paths["empty.blf"] = tmp_path / "empty.blf"
    with can.BLFWriter(str(blf)):
        pass
    mcap = paths["empty.mcap"] = tmp_path / "empty.mcap"
    from analyzer.recording.recorder import McapRecorder

    McapRecorder(mcap).close()  # a recording of a source that captured nothing
    return paths


@pytest.mark.parametrize("engine", ["python", "auto"])
def test_an_empty_capture_says_so(tmp_path: Path, engine: str) -> None:
    for name, path in _empty_captures(tmp_path).items():
        for command in ("decode", "stats"):
            args = ["--engine", engine] if command == "decode" else []
            res = eg2scope(command, str(path), *args)
            assert res.returncode == 0, (name, res.stderr)
            why = "empty file: no records" if name == "empty.bin" else "no frames in this capture"
            assert f"eg2scope: {path}: {why}" in res.stderr, (name, command, res.stderr)


@pytest.mark.parametrize("engine", ["python", "auto"])
def test_a_filter_that_matched_nothing_says_so(engine: str) -> None:
    log = CAPTURES / "can_pick_place.log"
    res = eg2scope("decode", str(log), "--device", "77", "--engine", engine)
    assert res.returncode == 0 and res.stdout == ""
    assert res.stderr.strip() == f"eg2scope: {log}: no records matched --device 77"


def test_damage_names_the_file_once_and_is_exit_3(tmp_path: Path) -> None:
    path = tmp_path / "random.blf"
    path.write_bytes(os.urandom(1000))
    res = eg2scope("decode", str(path))
    assert res.returncode == 3
    assert res.stderr.count("random.blf") == 1, res.stderr
    assert res.stderr.startswith(f"eg2scope: {path}: cannot open: not a BLF capture")
    assert "no frames" not in res.stderr


# -- the terminal: no bar over the records, no binary on it --------------------------------------


def _on_a_terminal(*args: str) -> tuple[int, bytes]:
    import pexpect

    child = pexpect.spawn(
        sys.executable,
        ["-m", "analyzer", *args],
        dimensions=(30, 120),
        env={**ENV, "TERM": "xterm-256color"},
        cwd=str(ROOT),
    )
    out = b""
    while True:
        try:
            out += child.read_nonblocking(1 << 16, timeout=60)
        except pexpect.EOF:
            break
    child.close()
    return child.exitstatus, out


@pytest.mark.parametrize("engine", ["python", "auto"])
def test_records_on_a_terminal_get_no_progress_bar(
    big_log: Path, tmp_path: Path, engine: str
) -> None:
    log = tmp_path / "medium.log"
    with big_log.open() as f:
        log.write_text("".join(next(f) for _ in range(20_000)))
    code, out = _on_a_terminal("decode", str(log), "--engine", engine)
    assert code == 0
    assert "━".encode() not in out  # the bar's characters: it would cut into the records
    assert out.count(b"\r\n") == 20_000


@pytest.mark.parametrize("target", [None, "/dev/tty", "-"])
def test_parquet_to_a_terminal_is_refused_before_anything(
    big_log: Path, target: str | None
) -> None:
    args = ["decode", str(big_log), "-f", "parquet"] + (["-o", target] if target else [])
    code, out = _on_a_terminal(*args)
    assert code == 2
    assert out.strip() == (
        b"eg2scope: error: --format parquet writes a binary file, not to a terminal: "
        b"give -o FILE.parquet"
    )


def test_a_bar_on_a_terminal_and_the_first_message_do_not_share_a_line(
    big_log: Path, tmp_path: Path
) -> None:
    """The bar (stderr on a terminal, records to a file) is gone before the damage is said."""
    damaged = tmp_path / "damaged.log"
    damaged.write_bytes(big_log.read_bytes() + b"not a frame line\n")
    import pyte

    code, out = _on_a_terminal(
        "decode", str(damaged), "-o", str(tmp_path / "o.jsonl"), "-f", "jsonl"
    )
    assert code == 3
    screen = pyte.Screen(120, 30)
    pyte.ByteStream(screen).feed(out)
    lines = [line.rstrip() for line in screen.display if line.strip()]
    assert lines and not any("━" in line for line in lines)  # the bar is gone
    said = "".join(line.ljust(120) for line in lines).rstrip()
    assert said.startswith(f"eg2scope: {damaged}: line 400001: cannot parse: 'not a frame")


def test_the_tui_on_a_missing_port_fails_at_once_and_touches_no_file(tmp_path: Path) -> None:
    out = tmp_path / "run.mcap"
    out.write_bytes(b"a recording the user keeps")
    port = tmp_path / "ttyUSB0"
    code, said = _on_a_terminal("tui", "--serial", str(port), "-o", str(out), "--force")
    assert code == 1
    why = f"cannot open {port}: no such port (--wait waits for a device that is not plugged in yet)"
    assert said.strip() == f"eg2scope: error: {why}".encode()
    assert out.read_bytes() == b"a recording the user keeps"


def test_ctrl_c_while_the_commands_load_is_an_interruption_without_traceback(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The subcommands' imports take a moment after start: a Ctrl-C then (Python raises
    KeyboardInterrupt inside whatever import runs) ends eg2scope with 130 and one line."""
    import importlib

    from analyzer import cli

    real = importlib.import_module

    def interrupted_import(name: str, package: str | None = None) -> object:
        if name.endswith("commands.decode"):  # the module of the command run
            raise KeyboardInterrupt
        return real(name, package)

    monkeypatch.setattr(cli.importlib, "import_module", interrupted_import)
    assert cli.main(["decode", "x.bin"]) == 130
    err = capsys.readouterr().err
    assert err == "eg2scope: interrupted before it began\n"


def test_damage_in_a_part_is_said_once_with_the_files_line_number(
    big_log: Path, tmp_path: Path
) -> None:
    """A malformed line inside a part of a parallel decode sends the rest to one piece, which
    says where the damage is in the file's own line numbers; the change of method is not a
    message of its own (its text would quote the part's line number)."""
    damaged = tmp_path / "damaged.log"
    lines = big_log.read_bytes().splitlines(keepends=True)
    damaged.write_bytes(b"".join([*lines[:300_000], b"not a frame line\n", *lines[300_000:]]))
    out = tmp_path / "o.jsonl"
    proc = subprocess.run(
        [sys.executable, "-m", "analyzer", "decode", str(damaged), "--engine", "python",
         "--jobs", "2", "-f", "jsonl", "-o", str(out), "--no-progress"],
        capture_output=True, text=True, env=ENV, cwd=ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 3, proc.stderr
    assert proc.stderr == (
        f"eg2scope: {damaged}: line 300001: cannot parse: 'not a frame line' "
        "(not a candump frame)\n"
    )
    assert sum(1 for _ in out.open()) == 400_000
