"""Fixtures of the TUI tests: the real app on the simulated buses (real ptys and python-can's
virtual bus) or on a capture file, driven by Textual's Pilot."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import AsyncIterator, Callable
from contextlib import ExitStack, asynccontextmanager
from pathlib import Path
from typing import Any

import can
import pytest

os.environ["TEXTUAL_ANIMATIONS"] = "none"

from analyzer.cli import build_parser
from analyzer.commands.tui import tui_options
from analyzer.tui.app import Eg2ScopeApp
from analyzer.tui.launch import (
    TuiOptions,
    capture_listeners,
    capture_plan,
    extra_listeners,
    live_plan,
)
from analyzer.tui.notes import Notes

ROOT = Path(__file__).resolve().parents[2]
CAPTURES = ROOT / "captures"
SIZE = (200, 50)
SIZES = {"80x24": (80, 24), "120x35": (120, 35), "200x50": (200, 50)}
_readers = ExitStack()  # the captures' readers, closed when the tests end


def tui_opts(*argv: str) -> TuiOptions:
    """``eg2scope tui ARGV`` as the command line parses it and hands it on."""
    return tui_options(build_parser().parse_args(["tui", *argv]))


def live_opts(output: str | None = None, freeze_on: str | None = None) -> TuiOptions:
    argv = ["--demo"]
    if output:
        argv += ["-o", output]
    if freeze_on:
        argv += ["--freeze-on", freeze_on]
    return tui_opts(*argv)


def demo_app(
    rig, output: str | None = None, freeze_on: str | None = None, argv: tuple[str, ...] = ()
) -> Eg2ScopeApp:
    """The app ``eg2scope tui --demo`` makes, on ``rig``'s simulated buses."""
    opts = live_opts(output, freeze_on)
    if argv:
        opts = tui_opts(*(["--demo"] + (["-o", output] if output else []) + list(argv)))
    notes = Notes()
    extra = extra_listeners(opts, live=True, notes=notes)
    plan = live_plan(opts, rig.taps, rig.protocols, rig.run_hosts, extra)
    plan.notes = notes
    return Eg2ScopeApp(plan)


def capture_app(path: Path, *argv: str, speed: float | None = None) -> Eg2ScopeApp:
    """The app ``eg2scope tui PATH ARGV`` makes (the command's own plan: its options are
    converted as the command converts them)."""
    if speed is not None:
        argv = (*argv, "--speed", f"{speed:g}")
    opts = tui_opts(str(path), *argv)
    notes = Notes()
    plan = capture_plan(opts, _readers, capture_listeners(opts, notes))
    plan.notes = notes
    return Eg2ScopeApp(plan)


@pytest.fixture(scope="session", autouse=True)
def _close_readers() -> Any:
    yield
    _readers.close()


@asynccontextmanager
async def driving(app: Eg2ScopeApp, size: tuple[int, int] = SIZE) -> AsyncIterator[Any]:
    """``app.run_test`` that always stops the session, even when the test fails inside."""
    try:
        async with app.run_test(size=size) as pilot:
            yield pilot
    finally:
        if app.session is not None:
            app.session.stop()


async def until(pilot, condition: Callable[[], bool], timeout: float = 15.0) -> None:
    """Let the app run until ``condition()`` holds (fails after ``timeout`` seconds)."""
    waited = 0.0
    while not condition():
        if waited >= timeout:
            pytest.fail(f"timed out after {timeout} s waiting for {condition}")
        await pilot.pause(0.1)
        waited += 0.1


def eg2scope(*argv: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "analyzer", *argv],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


@pytest.fixture(scope="session")
def tour(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The scenario ``tour`` (every grip outcome, a stall, a dropped answer, a bus-off) recorded
    by real ``eg2scope record --demo --scenario tour`` processes, at once: on the three buses
    ("mixed") and on CAN alone ("can", which the native engine decodes); each folder holds
    ``tour.mcap`` and the simulator's truth, ``tour.truth.jsonl``."""
    from scenario_capture import record_argv  # tests/: not on the benchmarks' path

    folders = {"mixed": None, "can": "can"}
    made = {kind: tmp_path_factory.mktemp(f"tour-{kind}") for kind in folders}
    procs = [
        subprocess.Popen(record_argv("tour", made[kind], buses), cwd=ROOT, text=True,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        for kind, buses in folders.items()
    ]  # fmt: skip
    for proc in procs:
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 0, err
    return {kind: folder / "tour.mcap" for kind, folder in made.items()}


@pytest.fixture(scope="session")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Every kind of input, made the way a user makes it."""
    folder = tmp_path_factory.mktemp("inputs")
    found = {
        "serial dump": CAPTURES / "serial_session.bin",
        "modbus dump": CAPTURES / "modbus_session.bin",
        "candump log": CAPTURES / "can_pick_place.log",
    }
    for suffix in (".asc", ".blf"):
        out = folder / f"pick_place{suffix}"
        with can.LogReader(found["candump log"]) as reader, can.Logger(out) as writer:
            for msg in reader:
                writer.on_message_received(msg)
        found[suffix] = out
    for name, buses in (("demo recording", "serial,modbus,can"), ("can recording", "can")):
        out = folder / f"{name.split()[0]}.mcap"
        done = eg2scope("record", "--demo", "--buses", buses, "-o", str(out), "--duration", "3")
        assert done.returncode == 0, done.stderr
        found[name] = out
    return found
