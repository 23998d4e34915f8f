"""The TUI on every input kind, as ``eg2scope tui CAPTURE`` builds it, driven headless with
Textual's Pilot on each session engine: the session thread ends without failing, and the
store holds decode's records, bus by bus, in stream order (the TUI may merge the buses by
capture time; each bus keeps its own order)."""

from __future__ import annotations

import asyncio
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import orjson
import pytest
from e2e_checks import force_session_engine, seq_names, skip_unless_native
from e2e_inputs import CAN_IDS, IDS
from textual.worker import Worker, WorkerState

from analyzer.cli import build_parser
from analyzer.commands.tui import tui_options
from analyzer.session.batches import RecordSequence
from analyzer.session.session import Session
from analyzer.tui.app import Eg2ScopeApp
from analyzer.tui.launch import capture_plan

SESSION_CELLS = [(k, "python") for k in IDS] + [(k, "native") for k in CAN_IDS]
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


async def replayed(path: Path) -> tuple[Eg2ScopeApp, list[Session], list[BaseException]]:
    """``eg2scope tui PATH``'s app, run until its session thread has ended (or failed)."""
    failures: list[BaseException] = []

    def watch(message: Any) -> None:
        if isinstance(message, Worker.StateChanged) and message.state == WorkerState.ERROR:
            failures.append(message.worker.error or RuntimeError("worker failed"))

    with ExitStack() as stack:
        plan = capture_plan(tui_options(build_parser().parse_args(["tui", str(path)])), stack)
        app = Eg2ScopeApp(plan)
        try:
            async with app.run_test(size=SIZE, message_hook=watch) as pilot:
                waited = 0.0
                while not failures and not app.done and waited < TIMEOUT_S:
                    await pilot.pause(0.1)
                    waited += 0.1
                await pilot.press("q")
        finally:
            if app.session is not None:
                app.session.stop()
    ended = [app.session] if app.done and app.session is not None else []
    return app, ended, failures


@pytest.mark.parametrize(("kind", "engine"), SESSION_CELLS)
def test_tui_store_holds_decodes_records(kind: str, engine: str, inputs, reference, monkeypatch):
    if engine == "native":
        skip_unless_native()
    force_session_engine(monkeypatch, engine)
    app, ended, failures = asyncio.run(replayed(inputs[kind]))
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
