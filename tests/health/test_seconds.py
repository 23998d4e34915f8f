"""Bus health second by second (``HealthListener(seconds=True).take_seconds``): the rows the
TUI, Rerun and ``batch`` show. A CAN error episode gives each second's controller state and
worst event exactly; a real three-bus scenario recording (``record --demo --scenario bus-off``)
gives seconds that add up to ``stats``' totals per bus, handed out once each
while the session runs."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
from health_helpers import ENGINES, cli_buses
from scenario_capture import record_scenarios
from test_error_frames import episode_log

from analyzer.health.listener import HealthListener
from analyzer.health.seconds import HealthSecond
from analyzer.session.capture import CaptureOptions, run_capture
from analyzer.session.listener import Listener

# second: (frames, errors, the worst state during it, worst event)
EPISODE_SECONDS = {
    10: (0, 2, "error_warning", "protocol violation"),
    11: (0, 2, "error_passive", "error passive"),
    12: (0, 1, "bus_off", "bus off"),
    13: (0, 1, "bus_off", "controller restarted"),  # bus-off until 13.5
    14: (0, 5, "error_passive", "error passive"),
    15: (0, 1, "error_passive", "controller problem"),  # passive until 15.0
    16: (1, 1, "bus_off", "bus off"),
}


class Taker(Listener):
    """Takes the completed seconds after every batch, as a live view would."""

    def __init__(self, health: HealthListener) -> None:
        self.health = health
        self.rows: list[HealthSecond] = []
        self.takes = 0

    def on_records(self, records: Any) -> None:
        pass

    def tick(self, now: float) -> None:
        taken = self.health.take_seconds()
        self.takes += bool(taken)
        self.rows += taken


def seconds_of(path: Path, engine: str, taking: bool = False) -> list[HealthSecond]:
    health = HealthListener(seconds=True)
    listeners: list[Listener] = [health]
    if taking:
        listeners.append(Taker(health))
    run_capture(CaptureOptions(str(path), progress=False, engine=engine), listeners)
    taken = listeners[-1].rows if taking else []  # type: ignore[attr-defined]
    return taken + health.take_seconds(final=True)


@pytest.mark.parametrize("engine", ENGINES)
def test_an_error_episode_second_by_second(tmp_path: Path, engine: str) -> None:
    rows = seconds_of(episode_log(tmp_path / "episode.log"), engine)
    got = {r.second: (r.frames, r.errors, r.state, r.worst) for r in rows}
    assert got == EPISODE_SECONDS
    (bus,) = cli_buses(tmp_path / "episode.log")
    last = rows[-1]
    assert (last.bus, last.kind, last.bits) == ("can0", "can", bus["bits"])
    assert last.load_pct == pytest.approx(100 * bus["bits"] / 500_000, abs=1e-3)


@pytest.fixture(scope="module")
def bus_off_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("seconds")
    record_scenarios(["bus-off"], folder)
    return folder / "bus-off.mcap"


def test_seconds_add_up_to_the_stats_of_each_bus(bus_off_recording: Path) -> None:
    rows = seconds_of(bus_off_recording, "auto", taking=True)
    buses = {b["bus"]: b for b in cli_buses(bus_off_recording)}
    assert {r.bus for r in rows} == set(buses) == {"rs232", "rs485", "can0"}
    for name, bus in buses.items():
        mine = [r for r in rows if r.bus == name]
        seconds = [r.second for r in mine]
        assert seconds == sorted(set(seconds)), "each second once, in order"
        assert sum(r.bits for r in mine) == bus["bits"]
        assert sum(r.frames for r in mine) == bus["frames"]
        assert sum(r.errors for r in mine) == bus["error_frames"]["total"]
        rate = bus.get("bitrate") or bus["baud"]
        for r in mine:
            assert r.kind == bus["kind"]
            assert r.load_pct == pytest.approx(100 * r.bits / rate, abs=1e-3)
        inside = [r.load_pct for r in mine[1:-1]]  # the seconds the span covers whole
        if inside:
            assert max(inside) == pytest.approx(bus["load_pct"]["max"], abs=1e-3)
    can = [r for r in rows if r.bus == "can0"]
    assert "bus_off" in {r.state for r in can} and can[-1].state == "error_active"
    assert [r.state for r in can].count("bus_off") <= 2, "a bus-off of a few hundred ms"
    assert "bus off" in {r.worst for r in can}
    assert all(r.state is None for r in rows if r.kind == "serial")


def test_a_running_session_hands_out_completed_seconds(bus_off_recording: Path) -> None:
    health = HealthListener(seconds=True)
    taker = Taker(health)
    run_capture(CaptureOptions(str(bus_off_recording), progress=False), [health, taker])
    assert taker.takes and taker.rows, "seconds came out while the capture was read"
    last = {bus: max(r.second for r in taker.rows if r.bus == bus) for bus in ("can0",)}
    final = health.take_seconds(final=True)
    assert final and all(r.second >= last.get(r.bus, -math.inf) for r in final)
    assert not {(r.bus, r.second) for r in final} & {(r.bus, r.second) for r in taker.rows}


def test_no_rows_unless_asked(bus_off_recording: Path) -> None:
    health = HealthListener()
    run_capture(CaptureOptions(str(bus_off_recording), progress=False), [health])
    assert health.take_seconds(final=True) == [] and health.buses()


def test_the_simulated_modbus_line_keeps_its_silence(bus_off_recording: Path) -> None:
    """The simulated slave answers, and the simulated host asks again, no sooner than Modbus
    RTU's t3.5 (as real ones must): the demo's health shows no frames too close (a tap late on a
    loaded machine may squeeze a few; before, 40% of the frames were)."""
    (line,) = [b for b in cli_buses(bus_off_recording) if b["bus"] == "rs485"]
    assert line["closer_than_t3_5"] <= line["frames"] // 50
    (turnaround,) = line["turnaround_ms"]
    assert turnaround["median"] >= line["modbus_t3_5_ms"]
