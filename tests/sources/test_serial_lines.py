"""RS485 passivity: the serial taps never raise DTR or RTS unless asked, from the moment a
port opens (real ptys; pyserial accepts the modem-line calls on them), and say so in their
settings."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterator
from typing import Any

import pytest
import serial
from taps.tap_helpers import Collector, Pty

from analyzer.commands.livesource import add_source_arguments, tap_options
from analyzer.sources.live import Tap, TapQueue
from analyzer.sources.serial_tap import SerialBridge, SerialPairTap, SerialTap
from analyzer.sources.tap_options import make_taps

Calls = list[tuple[Any, ...]]


@pytest.fixture
def ptys() -> Iterator[Callable[[], Pty]]:
    made: list[Pty] = []

    def make() -> Pty:
        made.append(Pty())
        return made[-1]

    yield make
    for p in made:
        p.close()


@pytest.fixture
def spy(monkeypatch: pytest.MonkeyPatch) -> dict[str, Calls]:
    """Every port pyserial makes records, in order, the modem-line settings and the open()
    (with the line states pyserial will apply while opening), per port name."""
    calls: dict[str, Calls] = {}
    real = serial.serial_for_url

    def spying(url: str, *args: Any, **kwargs: Any) -> Any:
        port = real(url, *args, **kwargs)
        base = type(port)
        log = calls.setdefault(url, [])

        class Spy(base):  # type: ignore[valid-type,misc]
            @property
            def dtr(self) -> Any:
                return base.dtr.fget(self)

            @dtr.setter
            def dtr(self, value: bool) -> None:
                log.append(("dtr", value))
                base.dtr.fset(self, value)

            @property
            def rts(self) -> Any:
                return base.rts.fget(self)

            @rts.setter
            def rts(self, value: bool) -> None:
                log.append(("rts", value))
                base.rts.fset(self, value)

            def open(self) -> None:
                log.append(("open", self._dtr_state, self._rts_state))
                super().open()

        port.__class__ = Spy
        return port

    monkeypatch.setattr(serial, "serial_for_url", spying)
    return calls


def _run(tap: Tap, opens: int) -> Collector:
    q = TapQueue()
    c = Collector(q)
    tap.start(q)
    try:
        c.wait_event("open", opens)
    finally:
        tap.stop()
    c.pump()
    return c


@pytest.mark.parametrize(
    "lines,dtr,rts",
    [({}, False, False), ({"rts": True}, False, True), ({"dtr": True, "rts": True}, True, True)],
    ids=["default", "rts high", "both high"],
)
def test_serial_tap_sets_the_lines_before_opening(
    ptys: Callable[[], Pty], spy: dict[str, Calls], lines: dict[str, bool], dtr: bool, rts: bool
) -> None:
    p = ptys()
    tap = SerialTap("rs485", p.name, **lines)
    c = _run(tap, 1)
    # set on the unopened port, applied by open(): never raised, not even for a moment
    assert spy[p.name] == [("dtr", dtr), ("rts", rts), ("open", dtr, rts)]
    low_high = {False: "low", True: "high"}
    assert tap.settings["dtr"] == low_high[dtr] and tap.settings["rts"] == low_high[rts]
    opened = c.of("open")[0].message
    assert f"RTS {low_high[rts]}, DTR {low_high[dtr]}" in opened


def test_pair_and_bridge_keep_the_lines_low(ptys: Callable[[], Pty], spy: dict[str, Calls]) -> None:
    a, b, host, device = ptys(), ptys(), ptys(), ptys()
    pair = SerialPairTap("rs232", [a.name, b.name])
    bridge = SerialBridge("rs232", host.name, device.name)
    _run(pair, 2)
    _run(bridge, 2)
    for p in (a, b, host, device):
        assert spy[p.name] == [("dtr", False), ("rts", False), ("open", False, False)]
    for tap in (pair, bridge):
        assert tap.settings["dtr"] == "low" and tap.settings["rts"] == "low"


def test_settings_are_plain_data_for_the_recording(ptys: Callable[[], Pty]) -> None:
    p = ptys()
    tap = SerialTap("rs485", p.name, 9600, parity=serial.PARITY_EVEN)
    assert tap.settings == {
        "kind": "serial",
        "port": p.name,
        "baudrate": 9600,
        "parity": "E",
        "rts": "low",
        "dtr": "low",
        "passive": "yes",
        "note": "read-only tap: eg2scope never writes to the port",
    }


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_source_arguments(parser)
    return parser.parse_args(argv)


@pytest.mark.parametrize(
    "argv,rts,dtr",
    [
        ([], False, False),
        (["--rts", "high"], True, False),
        (["--dtr", "high", "--rts", "low"], False, True),
    ],
)
def test_line_options(ptys: Callable[[], Pty], argv: list[str], rts: bool, dtr: bool) -> None:
    p, q = ptys(), ptys()
    for ports in (["--serial", p.name], ["--serial", p.name, "--serial", q.name]):
        (tap,) = make_taps(tap_options(_parse([*ports, *argv])))
        assert isinstance(tap, SerialTap | SerialPairTap)
        assert (tap.rts, tap.dtr) == (rts, dtr)
    (bridge,) = make_taps(tap_options(_parse(["--bridge", p.name, q.name, *argv])))
    assert isinstance(bridge, SerialBridge) and (bridge.rts, bridge.dtr) == (rts, dtr)


def test_line_option_values_are_checked() -> None:
    with pytest.raises(SystemExit):
        _parse(["--serial", "/dev/ttyUSB0", "--rts", "on"])
