"""The real TUI driven with Textual's Pilot against the simulator: grippers on real ptys
(regular serial, Modbus RTU) and on python-can's virtual CAN bus (issue 8, "Tests")."""

from __future__ import annotations

import asyncio
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import demo_app, driving, until

from analyzer.model import derived
from analyzer.recording.layout import MARKS
from analyzer.recording.reader import read_metadata
from analyzer.sim.rig import DemoRig
from analyzer.tui.rows import STYLE_ERROR, row_style
from analyzer.tui.widgets.devices import STATE_WIDTH, DevicePanel, state_words
from analyzer.tui.widgets.problems import ProblemsPanel
from decoders import flags as F

pytestmark = pytest.mark.slow
GRIPPERS = {(bus, dev) for bus in ("rs232", "rs485", "can0") for dev in (1, 2)}


def test_device_panel_shows_both_grippers_with_their_states() -> None:
    async def scenario() -> None:
        with DemoRig(noise=0.0) as rig:
            app = demo_app(rig)
            async with driving(app) as pilot:
                panel = app.query_one(DevicePanel)

                def all_known() -> bool:
                    rows = {(r.bus, r.device): r for r in panel.rows}
                    return set(rows) == GRIPPERS and all(
                        r.values["state"] is not None and r.values["opening"] is not None
                        for r in rows.values()
                    )

                await until(pilot, all_known)
                states = app.session.tracker.states
                panel.redraw()
                lines = [line.plain for line in panel.lines[1:]]  # after the heading
                for row, line in zip(panel.rows, lines, strict=True):
                    tracked = states[(row.bus, row.device)].to_dict()
                    assert row.values["frames"] <= tracked["frames"]
                    assert line.startswith(f"{row.bus:6} {row.device:<5} ")
                    # the state in words, abbreviated where the manual's do not fit: the state
                    # the panel was given (the live tracker may have moved on since)
                    shown = derived(dict(row.values))
                    assert shown["state"] is not None
                    assert state_words(shown["state"], shown["state_text"], STATE_WIDTH) in line
                await pilot.press("q")

    asyncio.run(scenario())


def test_filter_narrows_the_list_and_p_jumps_to_the_pair() -> None:
    async def scenario() -> None:
        with DemoRig(noise=0.0) as rig:
            app = demo_app(rig)
            async with driving(app) as pilot:
                await until(pilot, lambda: app.store.count > 200)
                app.query_one("#filter").value = "dev == 1 and bus == can0"
                app.action_filter()
                await pilot.press("enter")
                frames = app.frames
                store = app.store
                assert 0 < frames.row_count < store.count
                shown = [frames.index_at(p) for p in range(frames.row_count)]
                assert all(store.device_of(i) == 1 and store.bus_of(i) == "can0" for i in shown)
                # a response with its request: p goes to the request and back
                response = next(
                    i
                    for i in reversed(shown)
                    if store.pair_of(i) is not None and store.direction[i] == 2
                )
                frames.jump_to_index(response)
                await pilot.press("p")
                request = frames.selected
                assert request is not None and store.seq[request] == store.pair_of(response)
                assert store.direction[request] == 1
                await pilot.press("p")
                assert frames.selected == response
                await pilot.press("q")

    asyncio.run(scenario())


def test_a_live_session_keeps_the_newest_records_and_the_list_still_works() -> None:
    """``--keep 1000``: the oldest go as the session runs on, the status says so, the rows
    left keep their index; Home, the detail pane, the filter and p work on what is kept, and
    a frame no longer kept is said so."""

    async def scenario() -> None:
        with DemoRig(noise=0.0) as rig:
            app = demo_app(rig, argv=("--keep", "1000"))
            async with driving(app) as pilot:
                frames, store = app.frames, app.store
                await until(pilot, lambda: frames.first > 0, timeout=30)
                assert store.keep == 1000 and frames.first == store.first
                assert 1000 <= frames.row_count == frames.known - frames.first < 1600
                assert "keeping the last 1,000" in app.status_text()
                await pilot.press("home")
                assert frames.selected == frames.first and not frames.follow
                shown = frames.selected
                app._show_detail(shown)  # the detail pane of the oldest kept
                assert frames.render_line(0).text.strip()
                await until(pilot, lambda: store.first > shown, timeout=30)
                await pilot.pause(0.3)
                assert frames.selected == frames.first  # its record gone: the oldest kept
                app.go_to_index(0)
                await pilot.pause()
                assert any("no longer kept" in n.message for n in app._notifications)
                app.query_one("#filter").value = "dev == 1 and bus == can0"
                app.action_filter()
                await pilot.press("enter")
                first = frames.first
                await until(pilot, lambda: frames.first > first, timeout=30)
                view = [frames.index_at(p) for p in range(frames.row_count)]
                assert view and min(view) >= frames.first
                assert all(store.device_of(i) == 1 and store.bus_of(i) == "can0" for i in view)
                assert f"of {frames.known - frames.first:,} shown" in app.status_text()
                # the newest response and its request, picked again if the session dropped
                # them (1,000 records go by in well under a second) before p got there
                for _ in range(20):  # a loaded machine may take longer than 1,000 records
                    view = [frames.index_at(p) for p in range(frames.row_count)]
                    response = next(
                        i
                        for i in reversed(view)
                        if store.pair_of(i) is not None and store.direction[i] == 2
                    )
                    assert frames.jump_to_index(response)
                    await pilot.press("p")
                    request = None  # the request is dropped before its response
                    if store.first <= response:
                        request = store.index_of_seq(store.pair_of(response))
                    if request is not None:  # kept: p went to it
                        break
                assert request is not None and store.direction[request] == 1
                assert frames.selected == request
                await pilot.press("q")
        assert app.return_code == 0

    asyncio.run(scenario())


def test_bad_checksum_is_red_in_the_list_and_in_the_problems_panel_and_trigger_freezes() -> None:
    async def scenario() -> None:
        with DemoRig(noise=0.3) as rig:
            app = demo_app(rig, freeze_on="error")
            async with driving(app) as pilot:
                store = app.store
                await until(pilot, lambda: app.frozen_on is not None)
                frozen = app.frozen_on
                assert store.severity[frozen] == 2
                assert app.frames.selected == frozen and not app.frames.follow
                # capture goes on while the view is frozen
                count = store.count
                await until(pilot, lambda: store.count > count + 50)
                assert app.frames.selected == frozen
                bad = next(
                    i
                    for i in range(store.count)
                    if store.flags[i] & store.flag_bits.get(F.BAD_CHECKSUM)
                )
                assert row_style(store, bad)[0] == STYLE_ERROR
                await pilot.press("2")
                problems = app.query_one(ProblemsPanel)
                await until(pilot, lambda: any(g.code == F.BAD_CHECKSUM for g in problems.groups))
                group = next(g for g in problems.groups if g.code == F.BAD_CHECKSUM)
                assert group.level == "error" and group.count >= 1
                assert store.flags[group.first] & store.flag_bits.get(F.BAD_CHECKSUM)
                # Enter on a group jumps to its first occurrence (the groups go on updating while
                # the bus runs: the row under the cursor may be another group's by then)
                problems.focus()
                problems.move_cursor(row=problems.groups.index(group))
                await pilot.press("enter")
                assert app.frames.selected in {g.first for g in problems.groups}
                await pilot.press("q")

    asyncio.run(scenario())


def test_pause_keeps_capturing_and_marks_go_into_the_recording(tmp_path: Path) -> None:
    out = tmp_path / "run.mcap"

    async def scenario() -> None:
        with DemoRig(noise=0.0) as rig:
            app = demo_app(rig, output=str(out))
            async with driving(app) as pilot:
                await until(pilot, lambda: app.store.count > 100)
                await pilot.press("space")
                frames = app.frames
                assert not frames.follow
                paused_at, count = frames.selected, app.store.count
                await until(pilot, lambda: app.store.count > count + 100)
                assert frames.selected == paused_at and frames.new_while_paused > 0
                assert "paused" in app.status_text()
                await pilot.press("m", "a")
                assert frames.marks == {"a": paused_at}
                await pilot.press("end")
                assert frames.follow
                await pilot.press("q")
            return paused_at, app.store.seq[paused_at]

    _, seq = asyncio.run(scenario())
    from mcap.reader import make_reader

    with out.open("rb") as f:
        marks = [json.loads(m.data) for _, c, m in make_reader(f).iter_messages(topics=[MARKS])]
    assert marks and marks[0]["name"] == "a" and marks[0]["seq"] == seq
    assert read_metadata(out)["tool"] == "eg2scope"


def test_export_writes_a_file_decode_reads_back_to_the_same_records(tmp_path: Path) -> None:
    out = tmp_path / "can0.mcap"

    async def scenario() -> list[dict]:
        with DemoRig(("can",), noise=0.0) as rig:
            app = demo_app(rig)
            async with driving(app) as pilot:
                await until(pilot, lambda: app.store.count > 100)
                app.query_one("#filter").value = "bus == can0"
                app.action_filter()
                await pilot.press("enter")
                await pilot.press("space")  # the view stops: the shown records are fixed
                indices = list(app.export_indices())
                app.run_export(str(out), indices)
                await until(pilot, lambda: out.exists())
                exported = [app.store.record(i).to_dict() for i in indices]
                await pilot.press("q")
            return exported

    exported = asyncio.run(scenario())
    decoded = subprocess.run(
        [sys.executable, "-m", "analyzer", "decode", str(out), "--format", "jsonl", "-j", "1"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.splitlines()
    again = [json.loads(line) for line in decoded]
    keys = ("t", "bus", "protocol", "kind", "direction", "device", "code", "name", "fields", "raw")
    assert len(again) == len(exported)
    assert [{k: r[k] for k in keys} for r in again] == [{k: r[k] for k in keys} for r in exported]


def test_live_rows_of_all_buses_are_in_time_order() -> None:
    """The demo's three buses merged by capture time: a serial frame finished after CAN frames
    captured meanwhile is put back in its place; each bus keeps its stream order."""

    async def scenario() -> None:
        with DemoRig(noise=0.01) as rig:
            app = demo_app(rig)
            async with driving(app) as pilot:
                await until(pilot, lambda: app.store.count > 1500, timeout=60)
                store = app.store
                n = store.count
                times = [t for t in store.t[:n] if not math.isnan(t)]
                assert times == sorted(times)
                assert {store.bus_of(i) for i in range(n)} == {"rs232", "rs485", "can0"}
                for bus in ("rs232", "rs485", "can0"):  # live seq: the session's running number
                    seqs = [store.seq[i] for i in range(n) if store.bus_of(i) == bus]
                    assert seqs == sorted(seqs), bus
                await pilot.press("q")

    asyncio.run(scenario())
