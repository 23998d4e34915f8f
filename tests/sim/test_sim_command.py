"""``eg2scope sim`` as a user runs it: in its own process, talked to through the printed path,
stopped with Ctrl-C."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import serial
from sim_helpers import read_exactly

from decoders.build import serial_frame, u16le
from decoders.eg2_serial import Cmd

ROOT = Path(__file__).parents[2]
# the subcommand on its own parser, so this test does not depend on the CLI's registry
MAIN = (
    "import argparse, sys\n"
    "from analyzer.commands import sim\n"
    "p = argparse.ArgumentParser(prog='eg2scope')\n"
    "sim.add_subparser(p.add_subparsers())\n"
    "a = p.parse_args(sys.argv[1:])\n"
    "sys.exit(a.func(a))\n"
)


def _start(*args: str) -> tuple[subprocess.Popen[str], list[str]]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-c", MAIN, "sim", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=ROOT,
    )
    assert proc.stdout is not None
    lines: list[str] = []
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line.rstrip("\n"))
        if line.startswith("Ctrl-C stops"):
            return proc, lines
    proc.kill()
    raise AssertionError(f"no banner: {lines} {proc.stderr.read() if proc.stderr else ''}")


def _interrupt(proc: subprocess.Popen[str]) -> tuple[int, str]:
    proc.send_signal(signal.SIGINT)
    try:
        _, err = proc.communicate(timeout=5.0)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise
    return proc.returncode, err


def test_serial_sim_serves_the_printed_path_and_stops_on_ctrl_c(tmp_path: Path) -> None:
    link = tmp_path / "sim-serial"
    proc, lines = _start("serial", "--id", "1", "--id", "2", "--link", str(link))
    try:
        text = "\n".join(lines)
        assert str(link) in text and f"{link}-tap" in text
        assert os.path.islink(link) and os.path.islink(f"{link}-tap")
        host = serial.Serial(str(link), 115200, timeout=1.0)
        tap = serial.Serial(f"{link}-tap", 115200, timeout=1.0)
        request = serial_frame(2, Cmd.READ_ACTPOS)
        host.write(request)
        response = serial_frame(2, Cmd.READ_ACTPOS, u16le(1000), response=True)
        assert read_exactly(host, len(response)) == response
        assert read_exactly(tap, len(request) + len(response)) == request + response
        host.close()
        tap.close()
    finally:
        rc, err = _interrupt(proc)
    assert rc == 0, err
    assert "served 1 requests" in err
    assert not os.path.lexists(link)


def test_modbus_sim_with_its_own_host_program(tmp_path: Path) -> None:
    link = tmp_path / "sim-modbus"
    proc, _ = _start("modbus", "--link", str(link), "--host-cycle", "--short-registers")
    try:
        tap = serial.Serial(f"{link}-tap", 115200, timeout=1.0)
        data = read_exactly(tap, 64, timeout=3.0)  # the built-in host is talking
        tap.close()
        assert len(data) == 64
    finally:
        rc, err = _interrupt(proc)
    assert rc == 0, err


def test_can_sim_explains_the_virtual_bus() -> None:
    proc, lines = _start("can", "-c", "eg2scope-cmd-test", "--id", "5")
    rc, err = _interrupt(proc)
    assert rc == 0, err
    text = "\n".join(lines)
    assert "eg2scope-cmd-test" in text
    assert "does not cross processes" in text and "socketcan" in text


def test_help_and_bad_arguments() -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run(
        [sys.executable, "-c", MAIN, "sim", "--help"], capture_output=True, text=True, env=env
    )
    assert out.returncode == 0
    for words in ("vcan0", "-tap", "--object-width", "--noise", "Ctrl-C"):
        assert words in out.stdout
    bad = subprocess.run(
        [sys.executable, "-c", MAIN, "sim", "serial", "--id", "300"],
        capture_output=True,
        text=True,
        env=env,
    )
    assert bad.returncode != 0
    assert "1-254" in bad.stderr
