"""SVG snapshots (pytest-textual-snapshot) of the main screen at 80x24, 120x35 and 200x50,
the detail pane, the help screen, the command palette and the cycles panel, on fixed captures
replayed to their end: fixed data, and every age measured on the capture's own clock, so the
pictures are stable. Update with ``--snapshot-update`` (and look at what changed)."""

from __future__ import annotations

import pytest
from conftest import CAPTURES, SIZE, SIZES, capture_app, until
from textual.command import CommandPalette
from textual.widgets import Input

from analyzer.tui.widgets.detail import DetailTree
from analyzer.tui.widgets.devices import DevicePanel

pytest.importorskip("pytest_textual_snapshot")


async def replayed(pilot) -> None:
    app = pilot.app
    await until(pilot, lambda: app.done)
    # the detail pane follows the newest record a moment later (DETAIL_FOLLOW_S)
    await until(pilot, lambda: app.query_one(DetailTree).record is not None)
    await until(pilot, lambda: app.frames.known == app.store.count)
    await pilot.pause()  # following: the newest row is in view without help
    app.query_one(DevicePanel).changed_at.clear()  # highlights fade with wall time
    app.show_panels()
    await pilot.pause()


@pytest.mark.parametrize("size", list(SIZES))
@pytest.mark.parametrize("capture", ["can_pick_place.log", "serial_session.bin"])
def test_main_screen(snap_compare, capture: str, size: str) -> None:
    """Time, bus, direction, ID, name and the decoded values at every size; the detail pane
    shrinks (120) or goes (80); names and values cut to fit end in an ellipsis."""
    app = capture_app(CAPTURES / capture)
    assert snap_compare(app, terminal_size=SIZES[size], run_before=replayed)


def test_narrow_terminal_shows_the_detail_on_d(snap_compare) -> None:
    async def detail(pilot) -> None:
        await replayed(pilot)
        pilot.app.frames.move_to(7)
        await pilot.pause(0.3)
        await pilot.press("d")
        await pilot.pause(0.2)

    app = capture_app(CAPTURES / "modbus_session.bin")
    assert snap_compare(app, terminal_size=SIZES["80x24"], run_before=detail)


def test_detail_pane_and_hex_cross_highlighting(snap_compare) -> None:
    async def select(pilot) -> None:
        await replayed(pilot)
        app = pilot.app
        app.frames.move_to(5)
        await pilot.pause(0.3)
        await pilot.press("tab", "tab", "right", "right")  # the hex pane: byte 1
        await pilot.pause(0.2)

    app = capture_app(CAPTURES / "modbus_session.bin")
    assert snap_compare(app, terminal_size=SIZE, run_before=select)


@pytest.mark.parametrize("size", ["80x24", "200x50"])
def test_help_screen(snap_compare, size: str) -> None:
    async def help_(pilot) -> None:
        await replayed(pilot)
        await pilot.press("question_mark")

    app = capture_app(CAPTURES / "serial_session.bin")
    assert snap_compare(app, terminal_size=SIZES[size], run_before=help_)


def test_command_palette(snap_compare) -> None:
    async def palette(pilot) -> None:
        await replayed(pilot)
        await pilot.press("ctrl+p")
        await until(pilot, lambda: isinstance(pilot.app.screen, CommandPalette))
        pilot.app.screen.query_one(Input).cursor_blink = False  # a steady picture
        await pilot.press(*"filter")
        await pilot.pause(0.5)

    app = capture_app(CAPTURES / "serial_session.bin")
    assert snap_compare(app, terminal_size=SIZES["80x24"], run_before=palette)


@pytest.mark.parametrize("size", ["80x24", "200x50"])
def test_cycles_panel_and_a_chosen_cycles_frames(snap_compare, size: str) -> None:
    """The cycles panel (c) under the frame list and the health line; Enter on the second
    cycle selects its command and marks the frames that decided it (◆)."""

    async def chosen(pilot) -> None:
        await replayed(pilot)
        await pilot.press("c", "up", "enter")
        await pilot.pause(0.3)
        pilot.app.clear_notifications()  # the toast would hide the panel's right end
        await pilot.pause()

    app = capture_app(CAPTURES / "can_pick_place.log")
    assert snap_compare(app, terminal_size=SIZES[size], run_before=chosen)
