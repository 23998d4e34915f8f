"""The TUI on every input kind, as ``eg2scope tui CAPTURE`` builds it, driven headless with
Textual's Pilot on each session engine: the session thread ends without failing, and the
store holds decode's records, bus by bus, in stream order (the TUI may merge the buses by
capture time; each bus keeps its own order); the cycles panel holds the cycles ``eg2scope
cycles --format jsonl`` finds, and the health lines end on the figures ``eg2scope stats
--format json`` gives each bus (real processes)."""

from __future__ import annotations

import asyncio
from contextlib import ExitStack
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import orjson
import pytest
from e2e_checks import (
    GIVEN_RATES,
    RATES_KINDS,
    check_given_rates,
    eg2scope,
    force_session_engine,
    seq_names,
    skip_unless_native,
)
from e2e_inputs import IDS, NATIVE_IDS
from textual.worker import Worker, WorkerState

from analyzer.cli import build_parser
from analyzer.commands.tui import tui_options
from analyzer.session.batches import RecordSequence
from analyzer.session.session import Session
from analyzer.tui.app import Eg2ScopeApp
from analyzer.tui.launch import capture_plan
from analyzer.tui.widgets.cycles import CyclesPanel
from analyzer.tui.widgets.health import HealthLines

SESSION_CELLS = [(k, "python") for k in IDS] + [(k, "native") for k in NATIVE_IDS]
SIZE = (200, 50)
TIMEOUT_S = 30.0


def stored_by_bus(app: Eg2ScopeApp) -> dict[str, list[dict[str, Any]]]:
    """The store's records as their JSONL objects, per bus, in the store's order."""
    store = app.store
    buses: dict[str, list[dict[str, Any]]] = {}
    records = RecordSequence(store.records(range(store.count)))
    for record, line in zip(records, records.messages(), strict=True):
        buses.setdefault(record.bus, []).append(orjson.loads(line))
    return buses


@dataclass
class Replayed:
    """``eg2scope tui PATH``'s app once its session has ended: the session (None: it never
    ended), what its threads raised, the cycles panel's cycles and each bus's health line's
    figures of the whole capture."""

    app: Eg2ScopeApp
    ended: list[Session]
    failures: list[BaseException]
    cycles: list[dict[str, Any]]
    health: dict[str, dict[str, Any] | None]


_REPLAYED: dict[tuple[str, str], Replayed] = {}


def replayed_on(kind: str, engine: str, inputs: Any) -> Replayed:
    """The TUI of ``kind`` on ``engine`` (the caller forces it), run once per cell."""
    if (kind, engine) not in _REPLAYED:
        _REPLAYED[kind, engine] = asyncio.run(replayed(inputs[kind]))
    return _REPLAYED[kind, engine]


@cache
def command_json(command: str, path: Path, *argv: str) -> bytes:
    """``eg2scope COMMAND PATH ARGV`` as a real process: ``cycles`` in JSONL, ``stats`` in
    JSON."""
    fmt = "jsonl" if command == "cycles" else "json"
    proc = eg2scope(command, str(path), "--format", fmt, *argv, cwd=path.parent)
    assert proc.returncode == 0, proc.stderr.decode()
    return proc.stdout


async def replayed(path: Path, *argv: str) -> Replayed:
    """``eg2scope tui PATH ARGV``'s app, run until its session thread has ended (or
    failed)."""
    failures: list[BaseException] = []

    def watch(message: Any) -> None:
        if isinstance(message, Worker.StateChanged) and message.state == WorkerState.ERROR:
            failures.append(message.worker.error or RuntimeError("worker failed"))

    with ExitStack() as stack:
        opts = tui_options(build_parser().parse_args(["tui", str(path), *argv]))
        plan = capture_plan(opts, stack)
        app = Eg2ScopeApp(plan)
        try:
            async with app.run_test(size=SIZE, message_hook=watch) as pilot:
                waited = 0.0
                while not failures and not app.done and waited < TIMEOUT_S:
                    await pilot.pause(0.1)
                    waited += 0.1
                await pilot.pause(0.2)  # the last updates land
                cycles = [c.to_dict() for c in app.query_one(CyclesPanel).cycles]
                lines = app.query_one(HealthLines).lines
                health = {bus: line.whole for bus, line in lines.items()}
                await pilot.press("q")
        finally:
            if app.session is not None:
                app.session.stop()
    ended = [app.session] if app.done and app.session is not None else []
    return Replayed(app, ended, failures, cycles, health)


def by_start(cycles: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return sorted(cycles, key=lambda c: (c["bus"], c["device"], c["start_seq"]))


@pytest.mark.parametrize(("kind", "engine"), SESSION_CELLS)
def test_tui_store_holds_decodes_records(kind: str, engine: str, inputs, reference, monkeypatch):
    if engine == "native":
        skip_unless_native()
    force_session_engine(monkeypatch, engine)
    run = replayed_on(kind, engine, inputs)
    app, ended, failures = run.app, run.ended, run.failures
    assert not failures, f"the session thread failed: {failures[0]!r}"
    assert ended, f"the session never ended within {TIMEOUT_S} s"
    assert ended[0].options.engine == engine
    assert not ended[0].detached, f"a listener failed: {ended[0].detached}"
    expected = reference.decoded(kind).by_bus()
    stored = stored_by_bus(app)
    assert app.store.count == sum(map(len, expected.values()))
    assert {b: seq_names(r) for b, r in stored.items()} == {
        b: seq_names(r) for b, r in expected.items()
    }
    assert stored == expected


@pytest.mark.parametrize(("kind", "engine"), SESSION_CELLS)
def test_tui_cycles_and_health_are_the_commands(kind: str, engine: str, inputs, monkeypatch):
    """The cycles panel: ``cycles``'s cycles; each bus's health line at the end: ``stats``'s
    figures of the bus (a raw dump's: no timing)."""
    if engine == "native":
        skip_unless_native()
    force_session_engine(monkeypatch, engine)
    run = replayed_on(kind, engine, inputs)
    assert run.ended and not run.failures
    path = inputs[kind]
    expected = [orjson.loads(line) for line in command_json("cycles", path).splitlines()]
    assert expected, "no cycles in this input: nothing is checked"
    assert by_start(run.cycles) == by_start(expected)
    buses = orjson.loads(command_json("stats", path))["buses"]
    assert run.health == {b["bus"]: b for b in buses}


@pytest.mark.parametrize("kind", RATES_KINDS)
def test_tui_health_at_the_rates_given(kind: str, inputs) -> None:
    """``tui PATH -b 1000000 --baud 9600``: each bus's health line ends on ``stats``' figures
    at the same options, which count every bus at the rate given."""
    run = asyncio.run(replayed(inputs[kind], *GIVEN_RATES))
    assert run.ended and not run.failures
    buses = orjson.loads(command_json("stats", inputs[kind], *GIVEN_RATES))["buses"]
    check_given_rates(buses)
    assert run.health == {b["bus"]: b for b in buses}
