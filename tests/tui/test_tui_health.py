"""The health line of each bus (issue 20), driven with Textual's Pilot: on the scenario ``tour``
(three buses, a bus-off on CAN) each bus's seconds add up to what ``eg2scope stats --format
json`` counts (a real process), the highest load of a whole second is stats' ``max``, and at
the end the line shows stats' figures of the whole capture; a raw dump, which has no times,
says so and shows no load; live, every bus of the demo has its load and frames per second."""

from __future__ import annotations

import asyncio
import json
import sys
from pathlib import Path
from typing import Any

import pytest
from conftest import CAPTURES, SIZES, capture_app, demo_app, eg2scope, tui_opts, until

from analyzer.errors import UsageError
from analyzer.health.bus import NO_TIMING
from analyzer.health.rates import DEFAULT_BAUD, RateOptions
from analyzer.health.seconds import HealthSecond
from analyzer.sim.rig import DemoRig
from analyzer.sources.tap_options import make_taps
from analyzer.tui.bus_rates import live_rates
from analyzer.tui.messages import HealthUpdate
from analyzer.tui.widgets.health import BusHealthLine, HealthLines, health_text


def stats_buses(path: Path, *argv: str) -> dict[str, dict[str, Any]]:
    done = eg2scope("stats", str(path), "--format", "json", *argv)
    assert done.returncode == 0, done.stderr
    return {b["bus"]: b for b in json.loads(done.stdout)["buses"]}


async def replayed(path: Path, size: str, *argv: str) -> tuple[list[HealthUpdate], HealthLines]:
    """The health updates the app got while it replayed the capture (``tui PATH ARGV``), and
    the lines at the end."""
    updates: list[HealthUpdate] = []

    def hook(message: Any) -> None:
        if isinstance(message, HealthUpdate):
            updates.append(message)

    app = capture_app(path, *argv)
    try:
        async with app.run_test(size=SIZES[size], message_hook=hook) as pilot:
            await until(pilot, lambda: app.done, timeout=60)
            await pilot.pause(0.3)
            lines = app.query_one(HealthLines)
            await pilot.press("q")
    finally:
        app.session.stop()
    return updates, lines


def shown(lines: HealthLines) -> list[str]:
    return str(lines.render()).splitlines()


def test_each_buses_seconds_add_up_to_stats_and_the_end_shows_its_figures(
    tour: dict[str, Path],
) -> None:
    path = tour["mixed"]
    updates, lines = asyncio.run(replayed(path, "200x50"))
    stats = stats_buses(path)
    assert set(lines.lines) == set(stats) == {"rs232", "rs485", "can0"}
    rows: dict[str, list[HealthSecond]] = {}
    for update in updates:
        for row in update.seconds:
            rows.setdefault(row.bus, []).append(row)
    assert [u.whole is not None for u in updates].count(True) == 1  # at the end, once
    for bus, figures in stats.items():
        seconds = rows[bus]
        assert [r.second for r in seconds] == sorted({r.second for r in seconds})  # each once
        assert sum(r.frames for r in seconds) == figures["frames"]
        assert sum(r.bits for r in seconds) == figures["bits"]
        # each second's load: stats' max is one of them (over the seconds the bus's span
        # covers whole, which leaves out the first and the last unless the span starts or
        # ends on a whole second), and none between those two is higher
        loads = [r.load_pct or 0.0 for r in seconds]
        top = figures["load_pct"]["max"]
        assert len(loads) >= 5, bus
        assert any(load == pytest.approx(top, abs=0.002) for load in loads)
        assert max(loads[1:-1]) <= top + 0.002
        assert lines.lines[bus].peak == pytest.approx(figures["load_pct"]["max"], abs=0.002)
        assert lines.lines[bus].whole == figures  # stats' own figures, at the end
    text = "\n".join(shown(lines))
    for bus, figures in stats.items():
        line = next(line for line in shown(lines) if line.startswith(bus))
        load = figures["load_pct"]
        assert f"load {load['mean']:.1f}% mean {load['max']:.1f}% max" in line, line
        assert f"{figures['frames_per_s']:,.0f} frames/s" in line, line
    assert any(r.state == "bus_off" for r in rows["can0"])  # the tour's bus-off
    assert "no errors" not in next(line for line in text.splitlines() if line.startswith("can0"))


def loads_of(updates: list[HealthUpdate]) -> dict[str, dict[int, float | None]]:
    """Each bus's load of each second, as the updates gave them."""
    loads: dict[str, dict[int, float | None]] = {}
    for update in updates:
        for row in update.seconds:
            loads.setdefault(row.bus, {})[row.second] = row.load_pct
    return loads


def test_the_rates_given_count_a_captures_loads(tour: dict[str, Path], tmp_path: Path) -> None:
    """``tui FILE --bitrate 1000000 --baud 9600``: every second's load of the CAN bus, and the
    line's, is half of what it is at the EG2's 500000; a serial line's is its recorded baud
    over 9600 times its load at that baud; the line ends on ``stats``' figures at the same
    options, and ``--rerun`` plots the same loads."""
    sys.path.insert(0, str(Path(__file__).parents[1] / "rerun"))
    from plot_checks import per_second  # tests/rerun's reading of a plot's health seconds
    from rrd_helpers import read_rrd

    path, rrd = tour["mixed"], tmp_path / "given.rrd"
    given = ("--bitrate", "1000000", "--baud", "9600")
    default_updates, default = asyncio.run(replayed(path, "200x50"))
    updates, lines = asyncio.run(replayed(path, "200x50", *given, "--rerun", str(rrd)))
    at_default, at_given = loads_of(default_updates), loads_of(updates)
    stats = stats_buses(path, *given)
    assert set(at_given) == set(at_default) == set(stats) == {"rs232", "rs485", "can0"}
    plotted = read_rrd(rrd)
    for bus, figures in stats.items():
        was, line = default.lines[bus].whole, lines.lines[bus]
        assert was is not None and line.whole == figures  # stats' own, at the same options
        if bus == "can0":
            assert (was["bitrate"], was["bitrate_from"]) == (500_000, "default")
            assert (figures["bitrate"], figures["bitrate_from"]) == (1_000_000, "--bitrate")
            times = 0.5
        else:
            assert was["baud_from"] == "recording"  # the option outranks the recording
            assert (figures["baud"], figures["baud_from"]) == (9600, "--baud")
            times = was["baud"] / 9600
        assert at_given[bus].keys() == at_default[bus].keys()
        for second, load in at_given[bus].items():
            assert load == pytest.approx((at_default[bus][second] or 0.0) * times, abs=0.02)
        assert line.peak == pytest.approx((default.lines[bus].peak or 0.0) * times, abs=0.02)
        assert per_second(plotted, bus, "load_pct") == pytest.approx(at_given[bus])
    for text in shown(lines):
        load = stats[text.split()[0]]["load_pct"]
        assert f"load {load['mean']:.1f}% mean {load['max']:.1f}% max" in text, text


def test_the_live_sources_rate_options_are_a_captures_rates_too() -> None:
    """``-b`` and ``--baud`` (python-can's and the serial tap's) given with a capture are its
    rates; live they are the taps' alone; a rate that is not positive is a usage error."""
    path = str(CAPTURES / "can_pick_place.log")
    assert tui_opts(path, "-b", "1000000", "--baud", "9600").rates == RateOptions(1_000_000, 9600)
    assert tui_opts(path, "--bitrate", "250000").rates == RateOptions(250_000, None)
    assert tui_opts(path).rates == RateOptions()
    live = tui_opts("--serial", "/dev/ttyUSB7", "--baud", "9600")
    assert (live.rates, live.taps.baud) == (RateOptions(), 9600)
    assert tui_opts("--serial", "/dev/ttyUSB7").taps.baud == DEFAULT_BAUD
    for bad in (("-b", "0"), ("--baud", "-9600")):
        with pytest.raises(UsageError, match="must be a positive number"):
            tui_opts(path, *bad)


def test_a_raw_dump_says_it_has_no_timing_rather_than_a_load() -> None:
    path = CAPTURES / "serial_session.bin"
    updates, lines = asyncio.run(replayed(path, "80x24"))
    stats = stats_buses(path)["serial"]
    assert stats["timing"] == NO_TIMING
    assert not [row for u in updates for row in u.seconds]  # no second is made up
    (line,) = shown(lines)
    assert NO_TIMING in line and "%" not in line and "/s" not in line, line
    assert (
        f"{stats['frames']} frames" in line and f"{stats['error_frames']['total']} errors" in line
    )


def test_a_second_is_shown_with_its_load_frames_errors_state_and_event() -> None:
    """The line while a session runs: the latest second's figures as the rows give them."""
    line = BusHealthLine("can0")
    for second, load, worst in ((10, 3.0, None), (11, 7.25, "no ACK"), (12, 5.5, None)):
        state = "bus_off" if second == 12 else "error_active"
        line.add(HealthSecond("can0", "can", second, 90, 500, load, 2, state, worst), whole=True)
    text = health_text(line, now=14.5, live=True).plain
    assert text.startswith("can0") and "load  5.5% max 7.2%" in text, text
    assert "90 frames/s" in text and "2 errors/s" in text and "bus off" in text, text
    assert "quiet 2 s" not in text and "no ACK 3 s ago" in text, text
    assert "quiet 4 s" in health_text(line, now=17.0, live=True).plain
    short = health_text(line, now=14.5, live=True, narrow=True).plain
    assert "90 fr/s 2 err/s" in short and len(short) < len(text), short


def test_the_event_shown_is_the_worst_recent_one() -> None:
    """A lesser event does not hide a worse one of the last minute; a minute later it does."""
    line = BusHealthLine("can0")
    for second, worst in ((10, "bus off"), (12, "no ACK"), (20, "error passive")):
        line.add(HealthSecond("can0", "can", second, 90, 500, 1.0, 1, "bus_off", worst), True)
    assert "bus off 11 s ago" in health_text(line, now=21.0, live=True).plain
    line.add(HealthSecond("can0", "can", 30, 90, 500, 1.0, 1, "bus_off", "bus off"), True)
    assert "bus off 1 s ago" in health_text(line, now=31.0, live=True).plain
    line.add(HealthSecond("can0", "can", 95, 90, 500, 1.0, 1, "error_active", "no ACK"), True)
    assert "no ACK 1 s ago" in health_text(line, now=96.0, live=True).plain


def test_every_live_bus_has_its_load_and_frames_per_second() -> None:
    async def scenario() -> None:
        with DemoRig() as rig:
            app = demo_app(rig)
            async with app.run_test(size=SIZES["80x24"]) as pilot:
                try:
                    lines = app.query_one(HealthLines)
                    buses = {"rs232", "rs485", "can0"}

                    def measured() -> bool:
                        found = lines.lines
                        return set(found) >= buses and all(found[b].peak for b in buses)

                    await until(pilot, measured, timeout=20)
                    await pilot.pause(0.6)  # redrawn
                    for text in shown(lines):
                        bus = text.split()[0]
                        last = lines.lines[bus].last
                        assert last is not None and last.frames > 0
                        assert f"{last.frames} fr/s" in text, text  # 80 columns: short units
                        assert f"load {last.load_pct:.1f}%" in text, text
                    await pilot.press("q")
                finally:
                    app.session.stop()

    asyncio.run(scenario())


def test_a_live_bus_is_measured_at_the_rate_its_tap_was_opened_at() -> None:
    """``--baud`` of a serial tap named later by its protocol (rs232 or rs485) and ``-b`` of
    a CAN tap: the loads are of those rates, not the EG2's defaults."""
    serial = make_taps(tui_opts("--serial", "/dev/ttyUSB7", "--baud", "9600").taps)
    assert [t.named_by_protocol for t in serial] == [True]
    rates = live_rates(serial)
    assert rates.serial("rs232").value == rates.serial("rs485").value == 9600
    can = make_taps(tui_opts("-i", "virtual", "-c", "tui-rates", "-b", "250000").taps)
    assert live_rates(can).can(can[0].bus).value == 250_000
