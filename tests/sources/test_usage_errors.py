"""Options that can never work fail at once, before anything opens, with a UsageError (a
ValueError: the command line's exit 2) saying what is wrong, on every command. (A device that
does not open is not a usage error: exit 1, tests/taps/test_never_opened.py.)"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
import uuid
from pathlib import Path
from typing import Any

import can
import pytest

from analyzer.commands.livesource import add_source_arguments, tap_options
from analyzer.errors import UsageError
from analyzer.sources.can_tap import CanTap
from analyzer.sources.serial_tap import SerialBridge, SerialPairTap, SerialTap
from analyzer.sources.tap_options import make_taps

ROOT = Path(__file__).resolve().parents[2]

BAD_SERIAL: list[tuple[dict[str, Any], str]] = [
    ({"port": "/dev/ttyUSB0", "baudrate": -9600}, "impossible baud rate -9600"),
    ({"port": "/dev/ttyUSB0", "baudrate": 0}, "impossible baud rate 0"),
    ({"port": "/dev/ttyUSB0", "baudrate": "fast"}, "impossible baud rate 'fast'"),
    ({"port": "/dev/ttyUSB0", "bytesize": 9}, "cannot use serial port /dev/ttyUSB0"),
    ({"port": "/dev/ttyUSB0", "parity": "X"}, "cannot use serial port /dev/ttyUSB0"),
    ({"port": ""}, "malformed serial port name ''"),
    ({"port": "   "}, "malformed serial port name"),
    ({"port": "nosuchscheme://x"}, "protocol 'nosuchscheme' not known"),
    ({"port": "socket://no-port-here"}, "cannot use serial port socket://no-port-here"),
    ({"port": "rfc2217://host:99999"}, "cannot use serial port rfc2217://host:99999"),
]


@pytest.mark.parametrize("kwargs,message", BAD_SERIAL, ids=[m for _, m in BAD_SERIAL])
def test_impossible_serial_settings(kwargs: dict[str, Any], message: str) -> None:
    kwargs = dict(kwargs)
    port = kwargs.pop("port")
    with pytest.raises(UsageError, match=message.replace("(", r"\(")):
        SerialTap("rs485", port, **kwargs)
    with pytest.raises(UsageError):
        SerialPairTap("rs232", [port, "/dev/ttyUSB9"], **kwargs)
    with pytest.raises(UsageError):
        SerialBridge("rs232", port, "/dev/ttyUSB9", **kwargs)


def test_a_port_that_may_appear_is_not_a_usage_error(tmp_path: Path) -> None:
    tap = SerialTap("rs485", str(tmp_path / "ttyUSB0"))  # plugged in later
    assert tap.port.endswith("ttyUSB0")
    assert (
        SerialTap("rs485", "socket://localhost:7777").settings["port"] == "socket://localhost:7777"
    )


BAD_CAN: list[tuple[tuple[Any, ...], str]] = [
    (("nosuchiface", "can0", None), "unknown python-can interface 'nosuchiface'"),
    (("", "can0", None), "unknown python-can interface ''"),
    (("virtual", "", None), "malformed CAN channel ''"),
    (("virtual", "can 0", None), "malformed CAN channel 'can 0'"),
    (("virtual", "can0\n", None), "malformed CAN channel"),
    (("socketcan", "a/b", None), "a socketcan channel is a network interface name"),
    (("socketcan", "can_interface_0123", None), "at most 15 characters"),
    (("virtual", "can0", -500000), "impossible CAN bit rate -500000"),
    (("virtual", "can0", 0), "impossible CAN bit rate 0"),
]


@pytest.mark.parametrize("args,message", BAD_CAN, ids=[m for _, m in BAD_CAN])
def test_impossible_can_settings(args: tuple[Any, ...], message: str) -> None:
    with pytest.raises(UsageError, match=message):
        CanTap("can0", *args)


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_source_arguments(parser)
    return parser.parse_args(argv)


@pytest.mark.parametrize(
    "argv,message",
    [
        (["--serial", "/dev/ttyUSB0", "--baud", "-9600"], "impossible baud rate -9600"),
        (["-i", "virtual", "-c", "a b"], "malformed CAN channel 'a b'"),
        (["-i", "socketcan", "-c", "../../etc"], "network interface name"),
        (["-i", "virtual", "-c", "x", "-b", "-1"], "impossible CAN bit rate -1"),
        (["-c", "can0"], "a CAN source needs an interface"),
        (["-i", "virtual"], "a CAN source needs a channel"),
        (["--serial", "a", "--serial", "b", "--serial", "c"], "--serial takes one port"),
        (["--serial", "/dev/ttyUSB0", "--serial", "/dev/ttyUSB0"], "must be distinct"),
        ([], "no source given"),
    ],
)
def test_make_taps_refuses_at_once(
    monkeypatch: pytest.MonkeyPatch, argv: list[str], message: str
) -> None:
    monkeypatch.delenv("CAN_INTERFACE", raising=False)
    monkeypatch.delenv("CAN_CHANNEL", raising=False)
    monkeypatch.setenv("HOME", "/nonexistent")  # no ~/can.ini
    with pytest.raises(UsageError, match=message):
        make_taps(tap_options(_parse(argv)))


def test_unknown_interface_is_refused_by_the_parser(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        _parse(["-i", "nosuchiface", "-c", "x"])
    assert exit_info.value.code == 2
    assert "invalid choice: 'nosuchiface'" in capsys.readouterr().err


def test_can_options_are_python_cans(monkeypatch: pytest.MonkeyPatch) -> None:
    """-i/-c/-b, --fd, --bus-kwargs as can.cli parses them; python-can's configuration
    (CAN_INTERFACE) fills in the interface, as can.logger does."""
    channel = f"eg2scope-test-{uuid.uuid4().hex}"
    bus_kwargs = ["--bus-kwargs", "state=ACTIVE", "f_clock_mhz=80"]
    args = _parse(["-i", "pcan", "-c", "PCAN_USBBUS1", "-b", "500000", "--fd", *bus_kwargs])
    (tap,) = make_taps(tap_options(args))
    assert isinstance(tap, CanTap)
    assert (tap.interface, tap.channel, tap.bitrate) == ("pcan", "PCAN_USBBUS1", 500000)
    assert tap.kwargs == {"fd": True, "state": "ACTIVE", "f_clock_mhz": 80}
    assert tap.passive == "no"  # state=ACTIVE overrides listen-only, and the tap says so
    monkeypatch.setenv("CAN_INTERFACE", "virtual")
    (tap,) = make_taps(tap_options(_parse(["-c", channel])))
    assert isinstance(tap, CanTap) and tap.interface == "virtual" and tap.bus == channel
    seen: list[dict[str, Any]] = []
    real = can.Bus

    def bus(**kwargs: Any) -> can.BusABC:
        seen.append(kwargs)
        return real(**kwargs)

    monkeypatch.setattr(can, "Bus", bus)
    b = tap.open_bus()
    b.shutdown()
    assert seen == [{"interface": "virtual", "channel": channel, "receive_own_messages": False}]


@pytest.mark.parametrize(
    "argv,message",
    [
        (["--serial", "/dev/ttyUSB0", "--baud", "-9600"], "impossible baud rate -9600"),
        (["-i", "nosuchiface", "-c", "x"], "invalid choice: 'nosuchiface'"),
        (["-i", "virtual", "-c", "bad channel"], "malformed CAN channel"),
    ],
)
def test_cli_exits_at_once_with_a_usage_error(argv: list[str], message: str) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    t0 = time.monotonic()
    proc = subprocess.run(
        [sys.executable, "-m", "analyzer", "live", *argv, "--duration", "20"],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
        cwd=ROOT,
    )
    assert time.monotonic() - t0 < 15  # not retried until --duration runs out
    assert proc.returncode == 2, proc.stderr
    assert message in proc.stderr and "Traceback" not in proc.stderr


# -- every command: a bad option value is exit 2 -----------------------------------------------

SERIAL_DUMP = str(ROOT / "captures" / "serial_session.bin")

# at least one bad value per command the parser refuses, and one it can only refuse after
# parsing (a UsageError): both must be exit 2, at once, with a message and no traceback
BAD_OPTIONS: list[tuple[str, list[str], str]] = [
    ("decode", [SERIAL_DUMP, "--format", "nope"], "invalid choice: 'nope'"),
    ("decode", [SERIAL_DUMP, "-p", "can"], "CAN is chosen by the file"),
    ("decode", [SERIAL_DUMP, "-o", SERIAL_DUMP], "is the input"),
    ("stats", [SERIAL_DUMP, "--device", "-1"], "must be 0 or more"),
    ("stats", [SERIAL_DUMP, "--protocol", "foo"], "unknown protocol 'foo'"),
    ("live", ["--serial", "/dev/ttyUSB0", "--protocol", "foo"], "unknown protocol 'foo'"),
    ("live", ["--serial", "/dev/ttyUSB0", "--protocol", "can"], "a CAN source is always CAN"),
    ("live", ["--serial", "/dev/ttyUSB0", "--baud", "-5"], "impossible baud rate -5"),
    ("record", ["--serial", "/dev/ttyUSB0", "-o", "run.txt"], "name the output *.mcap"),
    ("record", ["--demo", "-o", "x.mcap", "--queue-size", "0"], "must be 1 or more"),
    ("bridge", ["/dev/ttyUSB0", "/dev/ttyUSB1", "--protocol", "foo"], "unknown protocol"),
    ("bridge", ["/dev/ttyUSB0", "/dev/ttyUSB0"], "must differ"),
    ("sim", ["serial", "--id", "0"], "--id must be 1-254"),
    ("sim", ["serial", "--object-width", "wide"], "--object-width must be 0-1000"),
    ("demo", ["--buses", "lin"], "unknown demo bus lin"),
    ("demo", ["--duration", "0"], "must be a positive number"),
    ("plot", [], "nothing to plot"),
    ("plot", ["--demo", "--protocol", "foo"], "unknown protocol 'foo'"),
    ("tui", ["--protocol", "foo"], "unknown protocol 'foo'"),
    ("tui", [SERIAL_DUMP, "--demo"], "not both"),
    ("batch", [SERIAL_DUMP, "-o", "fleet", "--workers", "0"], "must be 1 or more"),
    ("batch", [SERIAL_DUMP], "required: --output"),
    ("cycles", [], "no cycles to find"),
    ("cycles", [SERIAL_DUMP, "--demo"], "not both"),
    ("cycles", [SERIAL_DUMP, "--device", "-1"], "must be 0 or more"),
]


def test_every_command_is_in_the_table() -> None:
    from analyzer.commands import SUBCOMMANDS

    assert {command for command, _, _ in BAD_OPTIONS} == set(SUBCOMMANDS)


@pytest.mark.parametrize(
    ("command", "argv", "message"),
    BAD_OPTIONS,
    ids=[f"{c}:{m}" for c, _, m in BAD_OPTIONS],
)
def test_a_bad_option_value_is_exit_2_on_every_command(
    tmp_path: Path, command: str, argv: list[str], message: str
) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(
        [sys.executable, "-m", "analyzer", command, *argv],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
        cwd=tmp_path,  # nothing may be written: the folder stays empty
    )
    assert proc.returncode == 2, proc.stderr
    assert message in proc.stderr and "Traceback" not in proc.stderr
    assert proc.stdout == "" and list(tmp_path.iterdir()) == []
