"""The app's own behaviour (issue 17), driven with Textual's Pilot: a session thread that
raises is shown at once and makes ``eg2scope tui`` exit 1; an exception in the app stops the
session and exits non-zero; the command palette opens; marks take the very next key; the
status line and the panels say what they show."""

from __future__ import annotations

import asyncio
import gzip
import io
import random
from pathlib import Path

import pytest
from conftest import CAPTURES, SIZES, capture_app, demo_app, driving, tui_opts, until
from rich.console import Console
from textual.command import CommandList, CommandPalette
from textual.widgets import Input, RichLog, Static
from textual.widgets._footer import FooterKey

from analyzer.session.batches import RecordSequence
from analyzer.session.capture import CaptureOptions, open_reader
from analyzer.session.session import Session, SessionOptions
from analyzer.sim.rig import DemoRig
from analyzer.tui.aggregates import LATENCY_KEEP, Aggregates
from analyzer.tui.app import Eg2ScopeApp, SessionPlan
from analyzer.tui.launch import finish, summary_line
from analyzer.tui.layout import row_layout
from analyzer.tui.notes import Notes
from analyzer.tui.replay import ReplaySource
from analyzer.tui.rows import ELLIPSIS, MARKERS, cut_at, plain_row
from analyzer.tui.screens import HelpScreen
from analyzer.tui.store import LIVE_KEEP
from analyzer.tui.widgets.detail import DetailTree
from analyzer.tui.widgets.devices import DevicePanel
from analyzer.tui.widgets.event_log import EMPTY as EVENTS_EMPTY
from analyzer.tui.widgets.latency import LatencyPanel
from decoders.model import REQUEST, RESPONSE, Record


def failing_app(path: Path) -> Eg2ScopeApp:
    """The TUI as it was before issue 17's fix: the command line's protocol name "auto"
    handed to the session unconverted, so its decoding raises KeyError on the first bytes (the
    Python decoding's: the native one refuses the name when it is made)."""
    reader = open_reader(CaptureOptions(str(path)))
    source = ReplaySource(reader)

    def build(tui) -> Session:
        return Session(source, tui, SessionOptions(protocol="auto", engine="python"))

    return Eg2ScopeApp(SessionPlan(build, live=False, replay=source, title=path.name))


def status(app: Eg2ScopeApp) -> str:
    return str(app.query_one("#status", Static).render())


def test_a_failed_session_is_shown_at_once_printed_on_exit_and_exits_1(capsys) -> None:
    path = CAPTURES / "serial_session.bin"

    async def scenario() -> Eg2ScopeApp:
        app = failing_app(path)
        async with driving(app) as pilot:
            await until(pilot, lambda: app.failure is not None)
            await pilot.pause(0.3)
            assert isinstance(app.failure, KeyError)
            assert "SESSION FAILED" in status(app)
            shown = [n.message for n in app._notifications]
            assert any("the session failed: KeyError: 'auto'" in m for m in shown), shown
            await pilot.press("5")  # the events tab (a log draws once it is shown)
            await pilot.pause(0.3)
            log = app.query_one("#event-log", RichLog)
            assert any("KeyError" in line.text for line in log.lines)
            await pilot.press("q")
        return app

    app = asyncio.run(scenario())
    assert finish(tui_opts(str(path)), app, Notes()) == 1
    err = capsys.readouterr().err
    assert "eg2scope: error: the session failed: KeyError: 'auto' (at " in err


def test_the_protocol_names_of_the_command_line_reach_the_session_converted() -> None:
    for argv in ((), ("--protocol", "auto"), ("--protocol", "serial"), ("-p", "rs232")):
        app = capture_app(CAPTURES / "serial_session.bin", *argv)
        assert app.session.options.protocol in (None, "eg2-serial")


def test_keep_bounds_a_live_session_and_a_capture_keeps_everything_unless_told() -> None:
    capture = str(CAPTURES / "serial_session.bin")
    assert tui_opts("--demo").keep == LIVE_KEEP
    assert tui_opts(capture).keep is None
    assert tui_opts("--demo", "--keep", "all").keep is None
    assert tui_opts(capture, "--keep", "5000").keep == 5000
    assert capture_app(CAPTURES / "serial_session.bin", "--keep", "300").store.keep == 300
    for bad in ("0", "-3", "many"):
        with pytest.raises(SystemExit) as exc:
            tui_opts("--demo", "--keep", bad)
        assert exc.value.code == 2


def test_an_exception_in_the_app_stops_the_session_and_exits_non_zero(capsys) -> None:
    """An unhandled exception ends a Textual app with return code 1; the live session (the
    demo's taps) must end with it, not keep the process alive."""

    async def scenario() -> Eg2ScopeApp:
        with DemoRig(noise=0.0) as rig:
            app = demo_app(rig)
            with pytest.raises(ZeroDivisionError):
                async with driving(app) as pilot:
                    await until(pilot, lambda: app.store.count > 20)
                    app.call_later(lambda: 1 / 0)
                    await pilot.pause(0.5)
            for worker in app.workers:
                await worker.wait()
        return app

    app = asyncio.run(scenario())
    assert app.return_code == 1
    assert app.session._closed  # every listener closed: the session ended
    assert finish(tui_opts("--demo"), app, Notes()) == 1
    assert "the TUI failed" in capsys.readouterr().err


def test_the_command_palette_opens_and_shows_the_keys_as_they_are() -> None:
    async def scenario() -> None:
        app = capture_app(CAPTURES / "serial_session.bin")
        async with driving(app, SIZES["80x24"]) as pilot:
            await until(pilot, lambda: app.done)
            await pilot.press("ctrl+p")
            await until(pilot, lambda: isinstance(app.screen, CommandPalette))
            await pilot.pause(0.3)
            await pilot.press(*"filter")
            await pilot.pause(0.5)
            hits = app.screen.query_one(CommandList)
            text = [str(hits.get_option_at_index(i).prompt) for i in range(hits.option_count)]
            assert any("Display filter" in t and "[/ f]" in t for t in text), text
            await pilot.press("escape")
            await until(pilot, lambda: not isinstance(app.screen, CommandPalette))
            assert app.failure is None and app.is_running
            await pilot.press("q")
        assert app.return_code == 0

    asyncio.run(scenario())


def test_marks_take_the_very_next_key() -> None:
    async def scenario() -> None:
        app = capture_app(CAPTURES / "can_pick_place.log")
        async with driving(app) as pilot:
            await until(pilot, lambda: app.done)
            frames = app.frames
            frames.move_to(3)
            await pilot.press("m", "a")  # no pause between them
            assert frames.marks == {"a": frames.index_at(3)}
            frames.move_to(10)
            await pilot.press("m", "b", "apostrophe", "a")
            assert frames.selected == frames.index_at(3)
            assert "marks ab" in app.status_text()
            await pilot.press("m", "escape")  # anything but a letter cancels
            assert set(frames.marks) == {"a", "b"}
            # in the filter box, m is a letter of the filter
            await pilot.press("slash", "m")
            assert app.query_one("#filter", Input).value == "m"
            assert app.awaiting_letter is None
            await pilot.press("escape")

    asyncio.run(scenario())


def test_the_status_says_what_is_shown_and_an_invalid_filter_is_not_applied() -> None:
    async def scenario() -> None:
        app = capture_app(CAPTURES / "can_pick_place.log")
        async with driving(app) as pilot:
            await until(pilot, lambda: app.done)
            frames = app.frames
            assert f"| {frames.known:,} records |" in app.status_text()
            assert " shown" not in app.status_text()
            box = app.query_one("#filter", Input)
            error = app.query_one("#filter-error", Static)
            app.action_filter()
            await pilot.press(*"dev ==", "enter")
            assert "not applied; everything is shown" in str(error.render())
            assert frames.filter is None
            box.value = "dev == 1"
            await pilot.press("enter")
            shown = frames.row_count
            assert 0 < shown < frames.known
            assert f"{shown:,} of {frames.known:,} shown (filter: dev == 1)" in app.status_text()
            app.action_filter()
            box.value = "dev == 1 and"
            await pilot.press("enter")
            await pilot.pause()
            assert "not applied; still applied: dev == 1" in str(error.render())
            assert frames.filter is not None and frames.filter.text == "dev == 1"
            assert any("not applied" in n.message for n in app._notifications)

    asyncio.run(scenario())


def test_devices_never_read_show_a_dash_and_the_help_explains_the_gutter() -> None:
    async def scenario() -> None:
        app = capture_app(CAPTURES / "serial_session.bin")
        async with driving(app) as pilot:
            await until(pilot, lambda: app.done)
            panel = app.query_one(DevicePanel)
            panel.redraw()
            rows = {line.plain.split()[1]: line.plain for line in panel.lines[1:]}
            assert set(rows) == {"1", "2", "255"}  # 2 never answered; 255 is the broadcast
            for device in ("2", "255"):
                assert " none " not in rows[device], rows[device]
            assert " none " in rows["1"]  # its run state was read: no fault
            await pilot.press("q")
        app = capture_app(CAPTURES / "can_pick_place.log")
        async with driving(app) as pilot:
            await until(pilot, lambda: app.done)
            panel = app.query_one(DevicePanel)
            panel.redraw()
            rows = {line.plain.split()[1]: line.plain for line in panel.lines[1:]}
            for device in ("3", "16383"):  # asked, never answering; the broadcast ID
                assert rows[device].rstrip().endswith("never"), rows[device]
                assert " none " not in rows[device]
            assert not rows["1"].rstrip().endswith("never")
            await pilot.press("question_mark")
            await until(pilot, lambda: isinstance(app.screen, HelpScreen))
            console = Console(record=True, width=100, file=io.StringIO())
            for widget in app.screen.query(Static):
                console.print(widget.content)
            text = console.export_text()
            for mark, _ in MARKERS:
                assert mark in text

    asyncio.run(scenario())


def test_latency_figures_say_how_many_answers_they_are_of() -> None:
    agg = Aggregates()
    n = LATENCY_KEEP + 500
    records = RecordSequence()
    for k in range(n):
        for direction, latency in ((REQUEST, None), (RESPONSE, 1.0 + k % 7)):
            records.append(
                Record(
                    float(k),
                    "can0",
                    "eg2-can",
                    "frame",
                    1,
                    b"\x00",
                    direction=direction,
                    device=1,
                    name="CMD_FORCE_ACT..CMD_TEMP",
                    latency_ms=latency,
                )
            )
    agg.add(records, 0)
    stats = agg.snapshot().latency_by_command["CMD_FORCE_ACT..CMD_TEMP"]
    assert stats.count == LATENCY_KEEP and stats.total == n
    assert stats.samples_text() == f"last {LATENCY_KEEP:,} of {n:,}"
    assert agg.snapshot().latency_by_device[("can0", 1)].samples_text().startswith("last ")
    # a response without a manual name is listed under its protocol, as the frame list does
    unnamed = Record(0.0, "can0", "eg2-can", "frame", 1, b"\x00", direction=RESPONSE, device=1)
    unnamed.latency_ms = 0.5
    agg.add(RecordSequence([unnamed]), n * 2)
    assert set(agg.snapshot().latency_by_command) == {"CMD_FORCE_ACT..CMD_TEMP", "eg2-can"}


def test_notes_of_outputs_are_shown_and_kept_for_the_end() -> None:
    notes = Notes()
    shown: list[str] = []
    notes.show = shown.append
    notes.write("eg2scope: Rerun recording written to x.rrd; ")
    notes.write("open it with: rerun x.rrd\nsecond")
    assert shown == ["eg2scope: Rerun recording written to x.rrd; open it with: rerun x.rrd"]
    out = io.StringIO()
    notes.print(out)
    assert out.getvalue().splitlines() == [shown[0], "second"]


def damaged_captures(folder: Path, inputs: dict[str, Path]) -> dict[str, Path]:
    """Damaged inputs of every reader: random bytes named .log, a candump log and a recording
    cut mid-record, a gzip raw dump cut short."""
    made = {"random.log": folder / "random.log", "cut.log": folder / "cut.log"}
    made["random.log"].write_bytes(random.Random(7).randbytes(3000))
    log = (CAPTURES / "can_pick_place.log").read_bytes()
    made["cut.log"].write_bytes(log[:1000])  # ends in the middle of a line
    data = inputs["demo recording"].read_bytes()
    made["cut.mcap"] = folder / "cut.mcap"
    made["cut.mcap"].write_bytes(data[: len(data) * 2 // 3])
    made["cut.bin.gz"] = folder / "cut.bin.gz"
    packed = gzip.compress((CAPTURES / "serial_session.bin").read_bytes())
    made["cut.bin.gz"].write_bytes(packed[: len(packed) - 12])
    return made


DAMAGED = [
    ("random.log", ()),
    ("cut.log", ()),
    ("cut.log", ("--engine", "python")),
    ("cut.mcap", ()),
    ("cut.bin.gz", ()),
]


@pytest.mark.parametrize(("name", "argv"), DAMAGED, ids=[f"{n} {' '.join(a)}" for n, a in DAMAGED])
def test_damage_is_shown_in_the_tui_at_once_and_printed_on_exit(
    tmp_path: Path, inputs: dict[str, Path], capsys, name: str, argv: tuple[str, ...]
) -> None:
    """What the reader found wrong is a notification, an Events line and the status line as
    soon as the replay has ended, not only after q; still printed on exit, exit 3."""
    path = damaged_captures(tmp_path, inputs)[name]

    async def scenario() -> Eg2ScopeApp:
        app = capture_app(path, *argv)
        async with driving(app, SIZES["80x24"]) as pilot:
            await until(pilot, lambda: app.done)
            await pilot.pause(0.2)
            errors = app.session.source.errors
            assert errors, "the reader found no damage"
            shown = [n.message for n in app._notifications]
            assert errors[0] in shown, shown
            assert "INPUT DAMAGED (see Events)" in status(app)
            await pilot.press("5")
            await pilot.pause(0.3)
            lines = [line.text for line in app.query_one("#event-log", RichLog).lines]
            assert any(errors[0][:60] in line for line in lines), lines
            await pilot.press("q")
        return app

    app = asyncio.run(scenario())
    assert finish(tui_opts(str(path), *argv), app, Notes()) == 3
    err = capsys.readouterr().err
    assert app.session.source.errors[0] in err


def test_empty_panels_say_so_once_a_capture_has_ended(tmp_path: Path) -> None:
    """A capture with no gripper, no answer and no event: each panel says there were none in
    the capture (not "yet"); a gripper heard in a capture without times is "heard", not
    "never"; the exit line says what was read of the file."""
    path = tmp_path / "random.log"
    path.write_bytes(random.Random(7).randbytes(3000))

    async def scenario() -> None:
        app = capture_app(path)
        async with driving(app, SIZES["80x24"]) as pilot:
            await until(pilot, lambda: app.done)
            await pilot.pause(0.2)
            assert app.query_one(DevicePanel).lines[0].plain == "no gripper heard in this capture"
            await pilot.press("4")
            await pilot.pause(0.2)
            latency = str(app.query_one(LatencyPanel).render())
            assert latency == "no answered requests in this capture"
            await pilot.press("q")

    asyncio.run(scenario())

    async def events_and_ages() -> Eg2ScopeApp:
        app = capture_app(CAPTURES / "serial_session.bin")
        async with driving(app, SIZES["80x24"]) as pilot:
            log = app.query_one("#event-log", RichLog)
            await pilot.press("5")
            await pilot.pause(0.2)
            assert [line.text for line in log.lines] == [EVENTS_EMPTY] or app.done
            await until(pilot, lambda: app.done)
            await pilot.pause(0.2)
            assert [line.text.strip() for line in log.lines] == ["no events in this capture"]
            panel = app.query_one(DevicePanel)
            panel.redraw()
            rows = {line.plain.split()[1]: line.plain.rstrip() for line in panel.lines[1:]}
            assert rows["1"].endswith("heard") and rows["2"].endswith("never"), rows
            await pilot.press("q")
        return app

    app = asyncio.run(events_and_ages())
    line = summary_line(tui_opts(str(CAPTURES / "serial_session.bin")), app)
    assert line.endswith("serial_session.bin: read to its end, 27 records decoded, 3 with errors")


def test_untimed_rows_show_their_number_where_the_list_has_no_number_column() -> None:
    async def scenario() -> None:
        app = capture_app(CAPTURES / "serial_session.bin")
        async with driving(app, SIZES["80x24"]) as pilot:
            await until(pilot, lambda: app.done)
            store = app.store
            width = app.frames.scrollable_content_region.width
            assert row_layout(width).seq == 0  # 80 columns: no number column
            for i in range(store.count):
                row = plain_row(store, i, width=width)
                assert row[1:13].strip() == f"#{store.seq[i]}", row
            wide = plain_row(store, 0, width=200)  # the number has its own column there
            assert wide.split()[0] == str(store.seq[0]) and wide.split()[1] == "-"
            await pilot.press("q")

    asyncio.run(scenario())


def shown_line(widget, y: int = 0) -> str:
    """Line ``y`` of ``widget`` as the screen shows it (the screen's own composition)."""
    strips = widget.screen._compositor.render_strips()
    region = widget.scrollable_content_region
    return strips[region.y + y].crop(region.x, region.right).text


@pytest.mark.parametrize(
    ("text", "width", "shown"),
    [
        ("regs: CMD_FORCE_ACT, CMD_TEMP, CMD_STATUS", 36, "regs: CMD_FORCE_ACT, CMD_TEMP, …"),
        (
            "regs: CMD_FORCE_ACT, CMD_TEMP, CMD_STATUS",
            40,
            "regs: CMD_FORCE_ACT, CMD_TEMP, CMD_STAT…",
        ),
        ("CMD_ERRORCODE..CMD_STATUS", 20, "CMD_ERRORCODE..CMD_…"),  # a range keeps its stub
        ("measured_opening", 8, "measure…"),  # one word: cut inside it
        ("a CMDXYZW", 8, "a CMDXY…"),  # the earlier word ends too early to cut there
    ],
)
def test_a_cut_drops_a_word_rather_than_leave_a_stub_of_it(text: str, width: int, shown: str):
    """The detail tree's cut (a field's list of register names)."""
    assert text[: cut_at(text, width)] + ELLIPSIS == shown


@pytest.mark.parametrize("size", list(SIZES))
def test_whatever_is_cut_ends_in_an_ellipsis(size: str) -> None:
    """The detail tree, the status line, the filter's error line and the footer: nothing runs
    past its pane or is cut without a mark, at 80x24, 120x35 and 200x50."""

    async def scenario() -> None:
        app = capture_app(CAPTURES / "can_pick_place.log")
        async with driving(app, SIZES[size]) as pilot:
            await until(pilot, lambda: app.done)
            frames, store = app.frames, app.store
            if size == "80x24":
                await pilot.press("d")  # the detail pane instead of the list
            tree = app.query_one(DetailTree)
            await until(pilot, lambda: tree.size.width > 0)  # the pane is laid out
            for i in range(store.count):  # the error frame, the pairs, everything
                app._show_detail(i)
                await pilot.pause()
                room = tree.scrollable_content_region.width
                assert tree.virtual_size.width <= room  # nothing past the pane's edge
                for y in range(min(tree.last_line + 1, tree.size.height)):
                    node = tree.get_node_at_line(y + tree.scroll_offset.y)
                    full = node.label.plain if node is not None else ""
                    line = shown_line(tree, y).rstrip()
                    if full and not line.endswith(full):
                        assert line.endswith("…"), (line, full)
                        assert not line.endswith("CMD_…"), (line, full)  # a stub says nothing
            if size == "80x24":
                await pilot.press("d")
            frames.focus()
            footer_keys = list(app.query(FooterKey))
            palette = next(k for k in footer_keys if k.has_class("-command-palette"))
            for key in footer_keys:
                if key is not palette:
                    assert key.region.right <= palette.region.x, key.description
            app.action_filter()
            box = app.query_one("#filter", Input)
            box.value = "dev == 1"
            await pilot.press("enter")
            box.value = "dev == 1 and bus == can0 and name ~ CMD_FORCE_ACT and latency > 500 or"
            await pilot.pause(0.3)
            for name in ("#status", "#filter-error"):
                widget = app.query_one(name, Static)
                text = str(widget.render())
                line = shown_line(widget).strip()
                assert line == text or line.endswith("…"), (name, line, text)
            await pilot.press("escape", "q")

    asyncio.run(scenario())
