"""The scenarios as data (names, widths, what each bus plays), the bus-off's error frames as
linux/can/error.h lays them out, the jaw that stalls on an obstruction, and the command lines
that ask for a scenario."""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import serial

from analyzer.cli import build_parser
from analyzer.commands.demo import demo_options
from analyzer.errors import UsageError
from analyzer.sim.can_trouble import bus_off_frames
from analyzer.sim.gripper import FAULT_STALL, STOPPED, GripperModel
from analyzer.sim.scenarios import COMMANDS, NAMES, SCENARIOS, SCRIPT_OUTCOMES, listing, scenario
from decoders import build
from decoders.eg2_serial import Eg2SerialDecoder
from decoders.model import RESPONSE, Chunk

ROOT = Path(__file__).resolve().parents[2]
EG2SCOPE = [sys.executable, "-m", "analyzer"]


def test_every_scenario_is_listed_on_a_line_of_its_own() -> None:
    lines = listing().splitlines()
    assert [line.split()[0] for line in lines] == list(NAMES)
    assert all(len(line) < 120 for line in lines)


@pytest.mark.parametrize("name", NAMES)
def test_every_step_names_a_known_command_and_outcome(name: str) -> None:
    for protocol in ("serial", "modbus", "can"):
        script = SCENARIOS[name].script(protocol)
        assert script and all(
            s.command in COMMANDS and s.outcome in SCRIPT_OUTCOMES for s in script
        )
        assert script[-1].command == "release"  # every scenario ends open
        json.dumps(SCENARIOS[name].to_json(protocol))  # plain values only
        for step in script:
            assert (step.contact is not None) == (step.outcome == "gripped")


def test_bus_off_happens_on_can_only() -> None:
    bus_off = SCENARIOS["bus-off"]
    assert bus_off.needs_can and any(s.bus_off for s in bus_off.script("can"))
    assert not any(s.bus_off for s in bus_off.script("serial") + bus_off.script("modbus"))
    assert [s.outcome for s in bus_off.script("modbus")] == ["gripped", "opened"]


def test_a_part_can_be_given_its_width() -> None:
    grip = scenario("grip:300")
    assert grip.part == 300 and grip.steps[0].contact == 300
    assert scenario("slip:500").steps[0].slip_to == 300
    assert {s.contact for s in scenario("tour:250").steps if s.contact} == {250}
    for bad in ("grip:50", "grip:wide", "stall:300", "nudge"):
        with pytest.raises(ValueError):
            scenario(bad)


def test_the_bus_off_frames_count_up_to_bus_off_and_restart() -> None:
    frames = bus_off_frames(0.3)
    delays = [d for d, _ in frames]
    assert delays == sorted(delays) and delays[-1] - delays[-3] >= 0.3
    assert all(f.is_error and not f.is_extended and len(f.data) == 8 for _, f in frames)
    errors = [f for _, f in frames if f.arbitration_id & build.CAN_ERR_BUSERROR]
    assert [f.data[6] for f in errors] == list(range(8, 256, 8))  # TX error counter
    assert all(f.arbitration_id == 0x288 and f.data[2] == 0x88 for f in errors)
    status = [(f.data[1], f.data[6]) for _, f in frames if f.arbitration_id == 0x204]
    assert status == [(0x08, 96), (0x20, 128), (0x40, 0)]  # warning, passive, active again
    tail = [f.arbitration_id for _, f in frames[-3:]]
    assert tail == [0x040, 0x100, 0x204]  # bus off, restarted, error-active


def test_an_obstruction_stalls_the_closing_jaw() -> None:
    model = GripperModel(1, now=0.0, pace=4.0)
    model.place_jam(600)
    assert model.catch(500, 100, 0.0)
    model.step(1.0)
    assert (model.position, model.state, model.fault) == (600, STOPPED, FAULT_STALL)
    assert model.clear_faults(1.0) and model.release(500, 1.0)  # opening passes it freely
    model.step(2.0)
    assert model.position == 1000


def _args(*argv: str) -> argparse.Namespace:
    return build_parser().parse_args(list(argv))


@pytest.mark.parametrize("command", ["demo", "record", "plot", "tui"])
def test_every_demo_command_takes_a_scenario(command: str) -> None:
    extra = ["--demo"] if command != "demo" else []
    extra += ["-o", "x.mcap"] if command == "record" else []
    args = _args(command, *extra, "--scenario", "slip:500", "--time-scale", "3")
    opts = demo_options(args)
    assert opts.scenario is not None and opts.scenario.part == 500
    assert (opts.pace, opts.noise) == (3.0, 0.0)  # no noise to spoil the truth
    assert demo_options(_args(command, *extra)).noise == 0.01


def test_a_scenario_must_fit_the_buses() -> None:
    with pytest.raises(UsageError, match="needs the CAN bus"):
        demo_options(_args("demo", "--scenario", "bus-off", "--buses", "serial"))
    with pytest.raises(UsageError, match="--truth needs --scenario"):
        demo_options(_args("demo", "--truth", "t.jsonl"))


def test_sim_lists_and_refuses() -> None:
    listed = subprocess.run(
        [*EG2SCOPE, "sim", "--list-scenarios"], capture_output=True, text=True, cwd=ROOT
    )
    assert listed.returncode == 0 and listed.stdout.strip() == listing()
    for argv in (["serial", "--scenario", "bus-off"], ["serial", "--truth", "-"], []):
        bad = subprocess.run([*EG2SCOPE, "sim", *argv], capture_output=True, text=True, cwd=ROOT)
        assert bad.returncode == 2, (argv, bad.stderr)


def test_sim_plays_a_scenario_to_a_sniffer(tmp_path: Path) -> None:
    """``eg2scope sim serial --scenario grip:300``, over and over: a tap opened once it runs
    sees the catch end in state 6 at 300 and the release in state 1; the truth says so."""
    link, truth = tmp_path / "line", tmp_path / "truth.jsonl"
    proc = subprocess.Popen(
        [
            *EG2SCOPE,
            "sim",
            "serial",
            "--scenario",
            "grip:300",
            "--time-scale",
            "4",
            "--link",
            str(link),
            "--truth",
            str(truth),
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    polled: set[tuple[Any, Any]] = set()
    try:
        deadline = time.monotonic() + 10
        while not os.path.lexists(f"{link}-tap") and time.monotonic() < deadline:
            time.sleep(0.02)
        decoder = Eg2SerialDecoder("tap")
        with serial.Serial(f"{link}-tap", 115200, timeout=0.05) as tap:
            while not {(6, 300), (1, 1000)} <= polled and time.monotonic() < deadline:
                for r in decoder.feed(Chunk(tap.read(4096), time.time(), RESPONSE)):
                    polled.add((r.fields.get("state"), r.fields.get("position")))
    finally:
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err
    assert {(6, 300), (1, 1000)} <= polled
    played = [json.loads(line) for line in truth.read_text().splitlines()]
    cycle = [("catch", "gripped", 300), ("release", "opened", None)]
    assert (
        played
        and [(p["command"], p["outcome"], p["contact"]) for p in played]
        == (cycle * len(played))[: len(played)]
    )  # over and over
