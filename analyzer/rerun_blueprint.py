"""The default Rerun blueprint of a session: one column per gripper (force, opening, current,
temperature, the state lanes; time axes linked), each bus's error log, commands and health
below; above four grippers, one tab per bus. Live, the plots follow the last 10 s.

``Layout`` is what the blueprint depends on (the buses and grippers seen so far); the listener
sends a new blueprint whenever it changes.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Final

import rerun.blueprint as rrb

from . import rerun_entities as ent

MAX_COLUMNS: Final = 4  # above this many grippers, a tab per bus
LIVE_WINDOW_S: Final = 10.0


@dataclass(frozen=True)
class Layout:
    """What the blueprint shows: buses and grippers in the order first seen."""

    live: bool = False
    buses: tuple[str, ...] = ()
    grippers: tuple[tuple[str, int], ...] = ()  # grippers with readings or settings
    session_log: bool = False
    timeline: str = ent.CAPTURE_TIME

    def with_bus(self, bus: str) -> Layout:
        return self if bus in self.buses else replace(self, buses=(*self.buses, bus))

    def with_gripper(self, bus: str, device: int) -> Layout:
        key = (bus, device)
        if key in self.grippers:
            return self
        return replace(self.with_bus(bus), grippers=tuple(sorted((*self.grippers, key))))

    def with_session_log(self) -> Layout:
        return replace(self, session_log=True)

    def with_timeline(self, timeline: str) -> Layout:
        return self if timeline == self.timeline else replace(self, timeline=timeline)


def blueprint(layout: Layout) -> rrb.Blueprint:
    """The blueprint of ``layout`` (sent as the default blueprint and on every change)."""
    time_panel = rrb.TimePanel(
        timeline=layout.timeline, play_state="following" if layout.live else None
    )
    if not layout.buses:
        return rrb.Blueprint(rrb.TextLogView(origin="/", name="log"), time_panel)
    if len(layout.grippers) > MAX_COLUMNS:
        root: Any = rrb.Tabs(*[_bus_tab(layout, bus) for bus in layout.buses], name="buses")
    else:
        root = _page(layout, list(layout.buses), name="grippers")
    return rrb.Blueprint(root, time_panel, collapse_panels=False)


def _page(layout: Layout, buses: list[str], name: str) -> rrb.Vertical:
    grippers = [key for key in layout.grippers if key[0] in buses]
    bottom: list[Any] = [_bus_logs(layout, bus) for bus in buses]
    if layout.session_log:
        bottom.append(rrb.TextLogView(origin=f"/{ent.SESSION}/{ent.ERRORS}", name="session"))
    if not grippers:
        return rrb.Vertical(*bottom, name=name)
    columns = rrb.Horizontal(*[_gripper_column(layout, *key) for key in grippers])
    return rrb.Vertical(columns, rrb.Horizontal(*bottom), row_shares=[3, 1], name=name)


def _bus_tab(layout: Layout, bus: str) -> rrb.Vertical:
    return _page(layout, [bus], name=bus)


def _gripper_column(layout: Layout, bus: str, device: int) -> rrb.Vertical:
    base = ent.gripper_path(bus, device)
    title = f"{bus} ID {device}"
    plots = [
        _plot(layout, f"{base}/force", f"{title}: force"),
        _plot(layout, f"{base}/opening_mm", f"{title}: opening (mm)"),
        _plot(layout, f"{base}/current", f"{title}: current"),
        _plot(layout, f"{base}/temperature_c", f"{title}: temperature (°C)"),
    ]
    lanes = rrb.StateTimelineView(
        origin=base,
        contents=[f"{base}/{ent.STATE}", f"{base}/{ent.FAULT}"],
        name=f"{title}: state",
        time_view=_time_axis(),
        time_ranges=_window(layout),
    )
    return rrb.Vertical(*plots, lanes, name=title)


def _plot(layout: Layout, origin: str, name: str) -> rrb.TimeSeriesView:
    return rrb.TimeSeriesView(
        origin=origin,
        name=name,
        axis_x=_time_axis(),
        time_ranges=_window(layout),
        plot_legend=rrb.Corner2D.LeftTop,
    )


def _bus_logs(layout: Layout, bus: str) -> rrb.Tabs:
    base = ent.bus_path(bus)
    # the bus's text logs are its errors and its grippers' commands: all but the errors
    commands = ["+ $origin/**", f"- $origin/{ent.ERRORS}"]
    return rrb.Tabs(
        rrb.TextLogView(origin=f"{base}/{ent.ERRORS}", name=f"{bus} errors"),
        rrb.TextLogView(origin=base, contents=commands, name=f"{bus} commands"),
        _plot(layout, f"{base}/{ent.HEALTH}", f"{bus} health"),
        name=bus,
    )


def _time_axis() -> rrb.TimeAxis:
    return rrb.TimeAxis(link="LinkToGlobal")


def _window(layout: Layout) -> rrb.VisibleTimeRange | None:
    """Live: the last 10 s before the time cursor (which follows the newest data)."""
    if not layout.live:
        return None
    return rrb.VisibleTimeRange(
        layout.timeline,
        start=rrb.TimeRangeBoundary.cursor_relative(seconds=-LIVE_WINDOW_S),
        end=rrb.TimeRangeBoundary.cursor_relative(),
    )
