"""``eg2scope plot`` of scenario recordings whose truth the simulator wrote: every grip cycle on
its gripper's lane with its true outcome, and each bus's health second by second as ``stats``
counts it.

Real processes throughout: ``record --demo --scenario NAME --truth FILE`` records the ``tour``
(every outcome a script plays) on all three buses and on CAN alone, and ``bus-off`` (a CAN
controller's bus-off period) on all three; ``plot REC --save`` plots each (the CAN recording on
both engines), ``cycles --format jsonl`` and ``stats --format json`` read the same recordings.
The .rrd files are read back with rerun-sdk's reader (``rrd_helpers``).
"""

from __future__ import annotations

import json
import subprocess
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from native_core import why_not
from plot_checks import check_bus_health, check_cycles, lane_rows, per_second, plotted_cycles
from rrd_helpers import Rrd, read_rrd, views
from scenario_capture import EG2SCOPE, ROOT, read_truth, record_scenarios

WIDTH_TOLERANCE_MM = 0.2
ALL_BUSES = ("rs232", "rs485", "can0")
GIVEN_RATES = ("-b", "1000000", "--baud", "9600")  # "tour-rates": the tour at these rates


@dataclass(frozen=True)
class Plotted:
    """One recording: its plot read back, ``cycles``' and ``stats``' output, the truth."""

    rrd: Rrd
    cycles: list[dict[str, Any]]
    stats: dict[str, Any]
    truth: list[dict[str, Any]]


def _start(*argv: str) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [*EG2SCOPE, *argv], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )


def _out(proc: subprocess.Popen[bytes]) -> bytes:
    stdout, stderr = proc.communicate(timeout=180)
    assert proc.returncode == 0, f"{proc.args}: exit {proc.returncode}\n{stderr.decode()}"
    return stdout


@pytest.fixture(scope="module")
def plotted(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Plotted]]:
    """``tour`` and ``bus-off`` on all buses (Python engine), ``tour`` on CAN alone on both
    engines (``can-native``, ``can-python``; the native one where the core is built)."""
    mixed, can_only = tmp_path_factory.mktemp("mixed"), tmp_path_factory.mktemp("can")
    record_scenarios(["tour", "bus-off"], mixed)
    record_scenarios(["tour"], can_only, buses="can")
    runs = {"tour": (mixed, "tour", "python"), "bus-off": (mixed, "bus-off", "python"),
            "can-python": (can_only, "tour", "python"),
            "tour-rates": (mixed, "tour", "python")}  # fmt: skip
    if not why_not():
        runs["can-native"] = (can_only, "tour", "native")
    procs = {}
    for key, (folder, name, engine) in runs.items():
        mcap, rrd = str(folder / f"{name}.mcap"), str(folder / f"{key}.rrd")
        rates = GIVEN_RATES if key == "tour-rates" else ()
        procs[key] = (
            _start("plot", mcap, "--save", rrd, "--no-progress", "--engine", engine, *rates),
            _start("cycles", mcap, "--format", "jsonl", "--no-progress", "--engine", engine),
            _start("stats", mcap, "--format", "json", "--no-progress", *rates),
        )
    out = {}
    for key, (plot, cycles, stats) in procs.items():
        folder, name, _ = runs[key]
        _out(plot)
        found = [json.loads(line) for line in _out(cycles).splitlines()]
        out[key] = Plotted(
            read_rrd(Path(folder) / f"{key}.rrd"),
            found,
            json.loads(_out(stats)),
            read_truth(folder, name),
        )
    yield out


def true_pairs(p: Plotted, bus: str) -> list[tuple[dict[str, Any], dict[str, Any]]]:
    """(truth, plotted) for every cycle of the bus, each gripper's in the order they began; a
    last cycle cut off by the recording's end (``unfinished``, the script went on) left out,
    as tests/cycles/test_scenario_truth.py pairs them."""
    shown = plotted_cycles(p.rrd)
    out = []
    for device in sorted({t["device"] for t in p.truth if t["bus"] == bus}):
        truth = sorted((t for t in p.truth if (t["bus"], t["device"]) == (bus, device)),
                       key=lambda t: t["start_t"])  # fmt: skip
        seen = [c for c in shown if (c["bus"], c["device"]) == (bus, device)]
        if seen and seen[-1]["shown"] == "unfinished":
            seen = seen[:-1]
            if len(truth) == len(seen) + 1:
                truth = truth[:-1]
        assert len(seen) == len(truth), (bus, device, truth, seen)
        out += list(zip(truth, seen, strict=True))
    return out


def check_truth(truth: dict[str, Any], seen: dict[str, Any]) -> None:
    what = f"{truth['bus']} #{truth['index']} {truth['command']}: {seen}"
    slipped = "slip" in truth["warnings"]
    assert seen["shown"] == ("slip" if slipped else truth["outcome"]), what
    assert seen["start_t"] / 1e9 >= truth["start_t"] - 0.05, what
    if truth["outcome"] == "gripped":
        width = float(seen["text"].split("width ")[1].split(" mm")[0])
        assert abs(width - truth["contact_mm"]) <= WIDTH_TOLERANCE_MM, what


@pytest.mark.parametrize("bus", ALL_BUSES)
def test_every_cycle_is_on_its_gripper_lane_with_its_true_outcome(
    plotted: dict[str, Plotted], bus: str
) -> None:
    pairs = true_pairs(plotted["tour"], bus)
    outcomes = {t["outcome"] for t, _ in pairs}
    assert {"gripped", "closed_empty", "faulted", "unanswered"} <= outcomes, outcomes
    for truth, seen in pairs:
        check_truth(truth, seen)


@pytest.mark.parametrize("key", ["tour", "bus-off", "can-python", "can-native"])
def test_the_lanes_and_logs_hold_the_cycles_command_finds(
    plotted: dict[str, Plotted], key: str
) -> None:
    """On both timelines: each lane row at its command's capture time and seq, the log's
    figures at the command, a line at the end."""
    if key not in plotted:
        pytest.skip(f"native core: {why_not()}")
    p = plotted[key]
    assert p.cycles
    check_cycles(p.rrd, p.cycles)


def test_the_native_engine_plots_the_cycles_and_health_of_the_python_one(
    plotted: dict[str, Plotted],
) -> None:
    if "can-native" not in plotted:
        pytest.skip(f"native core: {why_not()}")
    native, python = plotted["can-native"].rrd, plotted["can-python"].rrd
    assert lane_rows(native) == lane_rows(python)
    for path, e in python.entities.items():
        if "/cycles" in path or "/health/" in path:
            assert native[path].rows() == e.rows(), path
    for truth, seen in true_pairs(plotted["can-native"], "can0"):
        check_truth(truth, seen)


@pytest.mark.parametrize("key", ["tour", "bus-off", "can-python", "tour-rates"])
def test_each_second_of_health_is_what_stats_counts(plotted: dict[str, Plotted], key: str) -> None:
    p = plotted[key]
    buses = p.stats["buses"]
    assert {b["bus"] for b in buses} == ({"can0"} if key.startswith("can") else set(ALL_BUSES))
    for figures in buses:
        check_bus_health(p.rrd, figures)


def test_the_rates_given_count_every_seconds_load(plotted: dict[str, Plotted]) -> None:
    """``plot REC -b 1000000 --baud 9600``: the CAN bus's load of each second is half its load
    at the EG2's 500000, a serial line's its recorded baud over 9600 times the load at that
    baud; ``stats`` at the same options says where the rates came from."""
    given, own = plotted["tour-rates"], plotted["tour"]
    was = {b["bus"]: b for b in own.stats["buses"]}
    for figures in given.stats["buses"]:
        bus = figures["bus"]
        if figures["kind"] == "can":
            assert (was[bus]["bitrate"], was[bus]["bitrate_from"]) == (500_000, "default")
            assert (figures["bitrate"], figures["bitrate_from"]) == (1_000_000, "--bitrate")
            times = 0.5
        else:
            assert (figures["baud"], figures["baud_from"]) == (9600, "--baud")
            assert was[bus]["baud_from"] == "recording"
            times = was[bus]["baud"] / 9600
        loads = per_second(given.rrd, bus, "load_pct")
        at_own = per_second(own.rrd, bus, "load_pct")
        assert loads.keys() == at_own.keys(), bus
        for second, load in loads.items():
            assert load == pytest.approx(at_own[second] * times, abs=0.02), (bus, second)


def test_the_bus_off_period_is_on_the_controller_lane(plotted: dict[str, Plotted]) -> None:
    """Each bus-off period ``stats`` reports turns the CAN controller's lane to ``bus_off`` in
    the second it began (the worst state of the second), and the lane is error-active again
    the second after the controller restarted."""
    p = plotted["bus-off"]
    (can,) = [b for b in p.stats["buses"] if b["bus"] == "can0"]
    periods = [s for s in can["error_states"] if s["state"] == "bus_off"]
    assert periods, can["error_states"]
    state = p.rrd["/can0/health/state"]
    lane = sorted(zip(state.capture_time, state.values, strict=True))

    def state_in(second: int) -> str:
        return [v for t, v in lane if t is not None and t // 1_000_000_000 <= second][-1]

    for period in periods:
        assert state_in(int(period["start"])) == "bus_off", (period, lane)
        assert state_in(int(period["end"]) + 1) == "error_active", (period, lane)
    assert p.rrd["/can0/health/errors_per_s"].values, "the error frames counted"
    assert max(p.rrd["/can0/health/errors_per_s"].values) > 0


def test_the_health_views_group_every_bus_by_unit(plotted: dict[str, Plotted]) -> None:
    """One view for the loads of all buses, one for their rates, one for the controllers'
    lanes, one for the latencies: not one view per series."""
    shown = {v.name: v.entities for v in views(plotted["tour"].rrd) if "bus health" in v.containers}
    assert set(shown["bus load (%)"]) == {f"/{b}/health/load_pct" for b in ALL_BUSES}
    rates = set(shown["frames, errors, unanswered per s"])
    assert {f"/{b}/health/frames_per_s" for b in ALL_BUSES} <= rates
    assert {f"/{b}/health/errors_per_s" for b in ALL_BUSES} <= rates
    assert shown["CAN controller state"] == ["/can0/health/state"]  # serial lines have none
    assert set(shown) == {"bus load (%)", "frames, errors, unanswered per s",
                          "CAN controller state", "latency (ms)"}  # fmt: skip
    lanes = [v for v in views(plotted["tour"].rrd) if v.name.endswith(": cycles, state")]
    assert {e for v in lanes for e in v.entities if e.endswith("/cycles")} == {
        f"/{bus}/{device}/cycles" for bus, device in lane_rows(plotted["tour"].rrd)
    }
