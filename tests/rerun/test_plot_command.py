"""``eg2scope plot`` end to end: every kind of input saved to an .rrd and read back, live from
the simulator (real ptys, the virtual CAN bus), the default target without a display, the web
viewer bound to 127.0.0.1 only, a running viewer reached with --connect, the usage errors, and
the ``--rerun [TARGET]`` option the live commands share."""

from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
import threading
import time
import tty
import urllib.request
from pathlib import Path
from typing import Any

import can
import psutil
import pytest
from rerun_inputs import CAPTURES, CASES, INPUTS, ROOT, TIMED, Collector
from rrd_helpers import blueprint_text, read_rrd, views

from analyzer.cli import main
from analyzer.commands.common import add_rerun_argument
from analyzer.plot.listener import RerunListener, rerun_listener
from analyzer.plot.target import (
    CONNECT,
    SAVE,
    SERVE_WEB,
    SPAWN,
    RerunTarget,
    can_display,
    parse_target,
    rerun_executable,
    rrd_name,
)
from analyzer.session.capture import CaptureOptions, run_capture
from decoders import build as b
from decoders.eg2_serial import Cmd
from decoders.registers import opening_mm

NO_DISPLAY = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
EG2SCOPE = [sys.executable, "-m", "analyzer"]


def opening_counts(path: Path) -> dict[str, int]:
    """Opening readings per gripper entity, from a session of its own."""
    collector = Collector()
    run_capture(CaptureOptions(str(path), progress=False), [collector])
    counts: dict[str, int] = {}
    for s in collector.samples:
        if s.changed.get("opening") is not None:
            key = f"/{s.bus}/{s.device}/opening_mm/measured"
            counts[key] = counts.get(key, 0) + 1
    return counts


@pytest.mark.parametrize(
    ("name", "engine"),
    [c for c in CASES if not c[0].startswith("faults")],
    ids=lambda x: str(x),
)
def test_plot_saves_every_kind_of_input(tmp_path: Path, name: str, engine: str) -> None:
    capture = INPUTS[name](tmp_path)
    out = tmp_path / "out.rrd"
    argv = ["plot", str(capture), "--save", str(out), "--no-progress", "--engine", engine]
    assert main(argv) == 0
    rrd = read_rrd(out)
    counts = opening_counts(capture)
    assert counts
    for path, n in counts.items():
        assert len(rrd[path].values) == n, path
    assert rrd.timelines() == ({"capture_time", "frame"} if name in TIMED else {"frame"})
    shown = views(rrd)
    assert shown and all(v.entities for v in shown)  # no empty view


def test_native_engine_on_recorded_byte_streams_is_a_usage_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "x.rrd"
    capture = str(INPUTS["mixed"](tmp_path))
    with pytest.raises(SystemExit) as exc:
        main(["plot", capture, "--engine", "native", "--save", str(out)])
    assert exc.value.code == 2
    assert "--engine native" in capsys.readouterr().err
    assert not out.exists()  # no recording begun


@pytest.mark.parametrize(
    ("capture", "written"),
    [("can_pick_place.log", "can_pick_place.rrd"), ("serial_session.bin", "serial_session.rrd")],
)
def test_without_a_display_plot_writes_the_file_and_says_how_to_open_it(
    tmp_path: Path, capture: str, written: str
) -> None:
    proc = subprocess.run(
        [*EG2SCOPE, "plot", str(CAPTURES / capture)],
        cwd=tmp_path,
        env={**NO_DISPLAY, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert f"open it with: rerun {written}" in proc.stderr
    assert read_rrd(tmp_path / written).blueprints
    assert proc.stdout == ""


def serve_web(argv: list[str], tmp_path: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [*EG2SCOPE, "plot", *argv, "--serve-web"],
        cwd=tmp_path,
        env={**NO_DISPLAY, "PYTHONPATH": str(ROOT)},
        stderr=subprocess.PIPE,
        text=True,
    )


def listening_addresses(tree: list[psutil.Process]) -> list[Any]:
    return [
        c.laddr
        for p in tree
        if p.is_running()
        for c in p.net_connections(kind="inet")
        if c.status == psutil.CONN_LISTEN
    ]


def test_serve_web_binds_to_localhost_only_and_prints_a_webgl_url_once(tmp_path: Path) -> None:
    proc = serve_web([str(CAPTURES / "can_pick_place.log")], tmp_path)
    try:
        url, before = wait_for_serving(proc)
        assert url.startswith("http://127.0.0.1:")
        assert "renderer=webgl" in url  # WebGPU fails without a GPU; WebGL works everywhere
        tree = [psutil.Process(proc.pid), *psutil.Process(proc.pid).children(recursive=True)]
        listening = listening_addresses(tree)
        assert len(listening) >= 2  # the web viewer and the gRPC proxy
        assert {addr.ip for addr in listening} == {"127.0.0.1"}
        with urllib.request.urlopen(url, timeout=10) as page:
            assert page.status == 200
        children = tree[1:]
        before += wait_for_line(proc, "everything is sent")  # Ctrl-C before: exit 130
        proc.send_signal(signal.SIGINT)
        assert proc.wait(30) == 0
        assert not any(c.is_running() and c.status() != psutil.STATUS_ZOMBIE for c in children)
        assert proc.stderr is not None
        err = before + proc.stderr.read()
        assert err.count("http://127.0.0.1:") == 1, err  # the address, once
        assert "ERROR" not in err and "flush" not in err, err  # no failed flush at exit
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.parametrize(
    "argv", [[str(CAPTURES / "serial_session.bin")], ["--demo"]], ids=["capture", "live"]
)
def test_sigterm_ends_the_web_viewer_it_started(tmp_path: Path, argv: list[str]) -> None:
    """SIGTERM (a service manager, ``kill``) stops plot --serve-web and the viewer server it
    started: no process left, its ports free, nothing reported as failed."""
    proc = serve_web(argv, tmp_path)
    try:
        _, before = wait_for_serving(proc)
        children = psutil.Process(proc.pid).children(recursive=True)
        assert listening_addresses(children)
        if argv[0] != "--demo":
            before += wait_for_line(proc, "everything is sent")  # a capture: sent in full
        time.sleep(1.0)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(30) == 0  # a capture served in full, a live source stopped: clean
        psutil.wait_procs(children, timeout=10)
        assert not any(c.is_running() and c.status() != psutil.STATUS_ZOMBIE for c in children)
        assert proc.stderr is not None
        err = before + proc.stderr.read()
        assert "ERROR" not in err and "Traceback" not in err, err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_the_web_viewer_ends_when_eg2scope_is_killed(tmp_path: Path) -> None:
    """Killed outright (SIGKILL: no handler runs), eg2scope still takes its viewer server
    with it: the kernel ends the child when its parent dies (Linux)."""
    if not sys.platform.startswith("linux"):
        pytest.skip("the parent-death signal is Linux's")
    proc = serve_web([str(CAPTURES / "can_pick_place.log")], tmp_path)
    try:
        wait_for_serving(proc)
        children = psutil.Process(proc.pid).children(recursive=True)
        assert children
        proc.kill()
        proc.wait(10)
        _, alive = psutil.wait_procs(children, timeout=10)
        assert not alive
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def wait_for_serving(proc: subprocess.Popen[str]) -> tuple[str, str]:
    """The address plot prints, and its stderr up to it."""
    text = wait_for_line(proc, "serving the Rerun web viewer at ")
    found = re.search(r"serving the Rerun web viewer at (\S+) ", text)
    assert found is not None
    return found.group(1), text


def wait_for_line(proc: subprocess.Popen[str], needle: str) -> str:
    """plot's stderr up to and including the first line holding ``needle``."""
    assert proc.stderr is not None
    deadline = time.monotonic() + 60
    lines = []
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            break
        lines.append(line)
        if needle in line:
            return "".join(lines)
    raise AssertionError(f"never said {needle!r}: {''.join(lines)}")


@pytest.mark.filterwarnings("ignore:RRD file has no footer")  # the server's file: no footer
def test_connect_sends_to_a_running_viewer(tmp_path: Path) -> None:
    """Rerun's own server (bound to 127.0.0.1) receives the plot and saves what it got."""
    port = free_port()
    received = tmp_path / "received.rrd"
    server = subprocess.Popen(
        [*rerun_executable(), "--serve-grpc", "--bind", "127.0.0.1", "--port", str(port),
         "--save", str(received)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        wait_listening(port)
        url = f"rerun+http://127.0.0.1:{port}/proxy"
        capture = CAPTURES / "can_pick_place.log"
        assert main(["plot", str(capture), "--connect", url, "--no-progress"]) == 0
        time.sleep(1.0)
    finally:
        server.send_signal(signal.SIGINT)
        server.wait(20)
    rrd = read_rrd(received)
    for path, n in opening_counts(capture).items():
        assert len(rrd[path].values) == n


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_listening(port: int) -> None:
    import socket

    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise AssertionError(f"nothing listens on {port}")


# -- live ----------------------------------------------------------------------------------------


@pytest.mark.slow
def test_plot_demo_live_on_ptys_and_the_virtual_can_bus(tmp_path: Path) -> None:
    out = tmp_path / "demo.rrd"
    code = main(["plot", "--demo", "--duration", "4", "--noise", "0.05", "--save", str(out)])
    assert code == 0
    rrd = read_rrd(out)
    for bus in ("rs232", "rs485", "can0"):
        for device in (1, 2):
            assert rrd[f"/{bus}/{device}/opening_mm/measured"].values, (bus, device)
            assert rrd[f"/{bus}/{device}/state"].values, (bus, device)
            assert "gripped" in rrd[f"/{bus}/{device}/cycles"].values, (bus, device)
        assert sum(rrd[f"/{bus}/health/frames_per_s"].values) > 10
        assert max(rrd[f"/{bus}/health/load_pct"].values) > 0
    assert rrd.timelines() == {"capture_time", "frame"}
    text = blueprint_text(rrd)
    assert "VisibleTimeRanges" in text  # live: a sliding window
    assert "'ContainerBlueprint:container_kind': [[1]]" in text  # six grippers: tabs
    for bus in ("rs232", "rs485", "can0"):
        assert f"'ContainerBlueprint:display_name': [['{bus}']]" in text
    shown = views(rrd)  # grown as quantities appeared: each view has data
    assert all(v.entities for v in shown)
    names = {v.name for v in shown}
    assert "can0 ID 1: force" in names and "can0 ID 1: current" not in names  # CAN polls none
    assert "rs485 ID 1: current" in names
    # a tab for the bus health of all three buses, a view per unit
    health = {v.name: v.entities for v in shown if "bus health" in v.containers}
    loads = {f"/{bus}/health/load_pct" for bus in ("rs232", "rs485", "can0")}
    assert set(health["bus load (%)"]) == loads
    assert health["CAN controller state"] == ["/can0/health/state"]


def run_main_while(argv: list[str], feed: Any) -> int:
    result: dict[str, int] = {}
    thread = threading.Thread(target=lambda: result.setdefault("code", main(argv)))
    thread.start()
    time.sleep(0.8)  # the tap opens
    feed()
    thread.join(30)
    assert not thread.is_alive()
    return result["code"]


def test_plot_live_virtual_can_bus(tmp_path: Path) -> None:
    channel = f"eg2-plot-{os.getpid()}-{time.monotonic_ns()}"
    out = tmp_path / "can.rrd"

    def feed() -> None:
        with can.Bus(interface="virtual", channel=channel) as sender:
            for i in range(40):
                for f in (
                    b.can_read_request(2, 1120, 8),
                    b.can_read_response(2, 1120, b.u16le(20, 900 - 20 * i, 300, 35)),
                ):
                    sender.send(can.Message(arbitration_id=f.arbitration_id, data=f.data))
                time.sleep(0.01)

    argv = ["plot", "-i", "virtual", "-c", channel, "--duration", "2.5", "--save", str(out)]
    assert run_main_while(argv, feed) == 0
    values = read_rrd(out)[f"/{channel}/2/opening_mm/measured"].values
    assert values == pytest.approx([opening_mm(900 - 20 * i) for i in range(40)])


def test_plot_live_serial_pty(tmp_path: Path) -> None:
    master, slave = os.openpty()
    tty.setraw(slave)
    out = tmp_path / "pty.rrd"
    s = b.serial_frame

    def feed() -> None:
        for pos in (1000, 800, 600, 400):
            os.write(master, s(1, Cmd.READ_ACTPOS))
            time.sleep(0.003)
            os.write(master, s(1, Cmd.READ_ACTPOS, b.u16le(pos), response=True))
            time.sleep(0.02)

    port = os.ttyname(slave)
    argv = ["plot", "--serial", port, "-p", "serial", "--duration", "2", "--save", str(out)]
    try:
        assert run_main_while(argv, feed) == 0
    finally:
        os.close(master)
        os.close(slave)
    values = read_rrd(out)["/rs232/1/opening_mm/measured"].values
    assert values == pytest.approx([opening_mm(p) for p in (1000, 800, 600, 400)])


# -- usage ---------------------------------------------------------------------------------------


LOG = str(CAPTURES / "can_pick_place.log")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["plot"], "nothing to plot"),
        (["plot", LOG, "--demo"], "not both"),
        (["plot", LOG, "-i", "virtual", "-c", "x"], "not both"),
        (["plot", LOG, "-i", "virtual", "-c", "x", "-b", "250000"], "not both"),
        (["plot", LOG, "-b", "0"], "--bitrate of a capture must be a positive number, not 0"),
        (["plot", LOG, "--baud", "-5"], "--baud of a capture must be a positive number"),
        (["plot", LOG, "--save", "out.txt"], "*.rrd"),
        (["plot", LOG, "--connect", "http://127.0.0.1:9876"], "rerun+http://"),
        (["plot", LOG, "-o", "run.mcap"], "-o records a live source"),
        (["plot", LOG, "--save", "x.rrd", "--spawn"], "not allowed with"),
        (["plot", "--demo", "--buses", "serial,usb"], "unknown demo bus"),
    ],
)
def test_usage_errors_exit_2(
    argv: list[str],
    message: str,
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
    assert not list(tmp_path.iterdir())  # nothing written


def test_an_rrd_that_cannot_be_written_fails_before_decoding(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "no-such-dir" / "x.rrd"
    assert main(["plot", LOG, "--save", str(out)]) == 1
    assert "no-such-dir" in capsys.readouterr().err


def test_a_capture_that_cannot_be_read_opens_no_viewer(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "x.rrd"
    assert main(["plot", str(tmp_path / "missing.log"), "--save", str(out)]) == 1
    assert not out.exists()
    assert "missing.log" in capsys.readouterr().err


# -- targets and the --rerun option --------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "display", "target"),
    [
        (None, False, RerunTarget(SAVE, "run.rrd")),
        ("default", False, RerunTarget(SAVE, "run.rrd")),
        (None, True, RerunTarget(SPAWN)),
        ("spawn", False, RerunTarget(SPAWN)),
        ("web", False, RerunTarget(SERVE_WEB)),
        ("serve-web", True, RerunTarget(SERVE_WEB)),
        ("out.rrd", True, RerunTarget(SAVE, "out.rrd")),
        ("rerun+http://10.0.0.2:9876/proxy", False, RerunTarget(CONNECT, "rerun+http://10.0.0.2:9876/proxy")),
    ],
)  # fmt: skip
def test_rerun_targets(
    text: str | None, display: bool, target: RerunTarget, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    if display:
        monkeypatch.setenv("DISPLAY", ":0")
    else:
        monkeypatch.delenv("DISPLAY", raising=False)
    assert can_display() is display
    assert parse_target(text, "captures/run.log") == target


@pytest.mark.parametrize("text", ["out.mcap", "nonsense", "http://host:1/proxy"])
def test_bad_rerun_targets(text: str) -> None:
    with pytest.raises(ValueError, match=r"--rerun|rerun\+http|\.rrd"):
        parse_target(text)


@pytest.mark.parametrize(
    ("source", "name"),
    [
        ("captures/can_pick_place.log", "can_pick_place.rrd"),
        ("/x/run.log.gz", "run.rrd"),
        ("run.mcap", "run.rrd"),
        ("dump", "dump.rrd"),
        (".hidden", ".hidden.rrd"),
    ],
)
def test_rrd_name_is_the_capture_name(source: str, name: str) -> None:
    assert rrd_name(source) == name


def test_rrd_name_of_a_live_session_is_dated() -> None:
    assert re.fullmatch(r"eg2scope-\d{8}-\d{6}\.rrd", rrd_name(None))


def test_the_rerun_option_of_the_live_commands(tmp_path: Path) -> None:
    parser = argparse.ArgumentParser()
    add_rerun_argument(parser)
    assert rerun_listener(parser.parse_args([]).rerun) is None
    out = tmp_path / "live.rrd"
    listener = rerun_listener(parser.parse_args(["--rerun", str(out)]).rerun)
    assert isinstance(listener, RerunListener) and listener.live
    listener.close()
    assert read_rrd(out).blueprints
    args = parser.parse_args(["--rerun"])
    assert args.rerun == "default"
    with pytest.raises(ValueError, match="--rerun"):
        rerun_listener(parser.parse_args(["--rerun", "bogus"]).rerun)
