"""The cycles panel (issue 20), driven with Textual's Pilot on real captures: the scenario
``tour`` recorded by real ``record --demo --scenario`` processes, whose truth the simulator
wrote. The panel lists the cycles ``eg2scope cycles`` finds (a real process) on each engine,
with the outcomes the simulator played; Enter on a cycle selects its command in the frame list
and marks the frames that decided it (] and [ step through them), at 80x24 and 200x50, also
when a display filter hides them; live, the demo's cycles appear as they end; the command
palette finds the panel."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

import pytest
from conftest import CAPTURES, SIZES, capture_app, demo_app, driving, eg2scope, until
from native_core import needs_native
from scenario_capture import read_truth
from textual.command import CommandList, CommandPalette
from textual.widgets import TabbedContent

from analyzer.cycles.model import CLOSED_EMPTY, GRIPPED, OPENED, UNFINISHED
from analyzer.sim.rig import DemoRig
from analyzer.tui.layout import cycle_layout
from analyzer.tui.rows import MARKER_EVIDENCE
from analyzer.tui.widgets.cycles import CyclesPanel, render_cycle

Cycle = dict[str, Any]


def cycles_of(path: Path, engine: str) -> list[Cycle]:
    """What ``eg2scope cycles PATH --format jsonl`` finds (a real process)."""
    done = eg2scope("cycles", str(path), "--format", "jsonl", "--engine", engine)
    assert done.returncode == 0, done.stderr
    return [json.loads(line) for line in done.stdout.splitlines()]


def by_start(cycles: list[Cycle]) -> list[Cycle]:
    return sorted(cycles, key=lambda c: (c["bus"], c["device"], c["start_seq"]))


def outcomes_against_truth(cycles: list[Cycle], truth: list[Cycle]) -> None:
    """Each gripper's outcomes, in the order its cycles began, are the truth's; the last one
    may be cut off by the recording's end (test_scenario_truth's rule)."""
    for bus, device in {(t["bus"], t["device"]) for t in truth}:
        told = [t["outcome"] for t in sorted(truth, key=lambda t: t["start_t"])
                if (t["bus"], t["device"]) == (bus, device)]  # fmt: skip
        seen = [c["outcome"] for c in by_start(cycles) if (c["bus"], c["device"]) == (bus, device)]
        if seen and seen[-1] == UNFINISHED:
            seen = seen[:-1]
            if len(told) == len(seen) + 1:
                told = told[:-1]
        assert seen == told, (bus, device)


async def panel_cycles(path: Path, *argv: str) -> tuple[list[Cycle], list[str]]:
    """The cycles panel's cycles once the capture is replayed, and its lines as drawn."""
    app = capture_app(path, *argv)
    async with driving(app, SIZES["200x50"]) as pilot:
        await until(pilot, lambda: app.done, timeout=60)
        await pilot.press("c")
        panel = app.query_one(CyclesPanel)
        outcomes = [c.outcome for c in panel.cycles]
        panel.move_to(outcomes.index(GRIPPED) if GRIPPED in outcomes else 0)  # into view
        await pilot.pause(0.3)
        lines = [line.text for line in (panel.render_line(y) for y in range(panel.size.height))]
        return [c.to_dict() for c in panel.cycles], lines


@pytest.mark.parametrize(("recording", "engine"), [("mixed", "python"), ("can", "python")])
def test_the_panel_lists_the_cycles_cycles_finds_with_their_true_outcomes(
    tour: dict[str, Path], recording: str, engine: str
) -> None:
    check_the_panel(tour[recording], engine)


@needs_native
def test_the_panel_lists_the_native_engines_cycles(tour: dict[str, Path]) -> None:
    check_the_panel(tour["can"], "native")


def check_the_panel(path: Path, engine: str) -> None:
    shown, lines = asyncio.run(panel_cycles(path, "--engine", engine))
    assert by_start(shown) == by_start(cycles_of(path, engine))
    outcomes_against_truth(shown, read_truth(path.parent, "tour"))
    assert {GRIPPED, CLOSED_EMPTY, OPENED} <= {c["outcome"] for c in shown}
    assert "outcome" in lines[0] and "command" in lines[0]  # the header
    assert any(GRIPPED in line and "29.4" in line for line in lines[1:]), lines  # the width


def test_enter_selects_the_cycles_command_and_marks_its_evidence(tour: dict[str, Path]) -> None:
    for size in ("80x24", "200x50"):
        asyncio.run(_enter_on_a_cycle(tour["mixed"], size))


async def _enter_on_a_cycle(path: Path, size: str) -> None:
    app = capture_app(path)
    async with driving(app, SIZES[size]) as pilot:
        await until(pilot, lambda: app.done, timeout=60)
        store, frames = app.store, app.frames
        await pilot.press("c")
        panel = app.query_one(CyclesPanel)
        assert panel.has_focus
        target = next(c for c in panel.cycles if (c.bus, c.outcome) == ("can0", CLOSED_EMPTY))
        panel.move_to(panel.cycles.index(target))
        await pilot.press("enter")
        await pilot.pause(0.3)
        assert frames.has_focus
        here = frames.selected
        assert here is not None
        assert (store.bus_of(here), store.seq[here]) == ("can0", target.start_seq)
        marked = {(store.bus_of(i), store.seq[i]) for i in frames.evidence}
        assert marked == {("can0", seq) for seq in target.evidence}
        drawn = frames.render_line(frames.cursor - frames.scroll_offset.y).text
        assert drawn.startswith(MARKER_EVIDENCE), drawn  # the gutter, as the list draws it
        for seq in sorted(target.evidence)[1:]:  # ] steps through them in order
            await pilot.press("right_square_bracket")
            assert store.seq[frames.selected] == seq
        await pilot.press("left_square_bracket")
        assert store.seq[frames.selected] == sorted(target.evidence)[-2]
        await pilot.press("q")


def test_enter_on_a_cycle_hidden_by_the_filter_clears_it_and_says_so(
    tour: dict[str, Path],
) -> None:
    async def scenario() -> None:
        app = capture_app(tour["mixed"])
        async with driving(app, SIZES["80x24"]) as pilot:
            await until(pilot, lambda: app.done, timeout=60)
            await pilot.press("slash", *"bus == rs232", "enter")
            assert app.frames.filter is not None
            await pilot.press("c")
            panel = app.query_one(CyclesPanel)
            target = next(c for c in panel.cycles if c.bus == "can0")
            panel.move_to(panel.cycles.index(target))
            await pilot.press("enter")
            await pilot.pause(0.3)
            assert app.frames.filter is None
            here = app.frames.selected
            assert (app.store.bus_of(here), app.store.seq[here]) == ("can0", target.start_seq)
            said = [n.message for n in app._notifications]
            assert any("hidden by the filter: filter cleared" in m for m in said), said
            await pilot.press("q")

    asyncio.run(scenario())


def test_the_demos_cycles_appear_live_as_they_end() -> None:
    """The demo's hosts close each gripper on its part and open it again, on every bus."""

    async def scenario() -> None:
        with DemoRig() as rig:
            app = demo_app(rig)
            async with driving(app, SIZES["80x24"]) as pilot:
                panel = app.query_one(CyclesPanel)
                buses = {"rs232", "rs485", "can0"}
                await until(pilot, lambda: {c.bus for c in panel.cycles} >= buses, timeout=30)
                assert {c.outcome for c in panel.cycles} <= {GRIPPED, OPENED}
                gripped = next(c for c in panel.cycles if c.outcome == GRIPPED)
                line = render_cycle(gripped, app.store.t0, cycle_layout(80)).plain
                assert GRIPPED in line and f"{gripped.width_mm:.1f}" in line, line
                await pilot.press("q")

    asyncio.run(scenario())


def test_the_command_palette_opens_the_cycles_panel() -> None:
    async def scenario() -> None:
        app = capture_app(CAPTURES / "can_pick_place.log")
        async with driving(app, SIZES["80x24"]) as pilot:
            await until(pilot, lambda: app.done)
            await pilot.press("ctrl+p")
            await until(pilot, lambda: isinstance(app.screen, CommandPalette))
            await pilot.pause(0.3)
            await pilot.press(*"grip cycles")
            await pilot.pause(0.5)
            hits = app.screen.query_one(CommandList)
            text = [str(hits.get_option_at_index(i).prompt) for i in range(hits.option_count)]
            assert any("Grip cycles" in t and "[c]" in t for t in text), text
            chosen = next(i for i, t in enumerate(text) if "[c]" in t)
            hits.highlighted = chosen
            await pilot.press("enter")
            await until(pilot, lambda: app.query_one(CyclesPanel).has_focus)
            assert app.query_one(TabbedContent).active == "cycles"
            await pilot.press("q")

    asyncio.run(scenario())
