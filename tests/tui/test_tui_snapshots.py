"""SVG snapshots (pytest-textual-snapshot) of the main screen, the detail pane and the help
screen, on a fixed capture replayed to its end: fixed data, and every age measured on the
capture's own clock, so the pictures are stable. Update with ``--snapshot-update``."""

from __future__ import annotations

import pytest
from conftest import CAPTURES, SIZE, capture_app, until

from analyzer.tui.widgets.detail import DetailTree
from analyzer.tui.widgets.devices import DevicePanel

pytest.importorskip("pytest_textual_snapshot")


async def replayed(pilot) -> None:
    app = pilot.app
    await until(pilot, lambda: app.done)
    # the detail pane follows the newest record a moment later (DETAIL_FOLLOW_S)
    await until(pilot, lambda: app.query_one(DetailTree).record is not None)
    app.query_one(DevicePanel).changed_at.clear()  # highlights fade with wall time
    app.show_panels()
    await pilot.pause()


def test_main_screen(snap_compare) -> None:
    app = capture_app(CAPTURES / "can_pick_place.log")
    assert snap_compare(app, terminal_size=SIZE, run_before=replayed)


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


def test_help_screen(snap_compare) -> None:
    async def help_(pilot) -> None:
        await replayed(pilot)
        await pilot.press("question_mark")

    app = capture_app(CAPTURES / "serial_session.bin")
    assert snap_compare(app, terminal_size=SIZE, run_before=help_)
