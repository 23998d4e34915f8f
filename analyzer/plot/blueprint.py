"""The default Rerun blueprint of a session: a view only for what the session carries.

Per gripper, two pages: force (with its limit and the fault marks), opening (with its target)
and the lanes (its grip cycles, run state, faults); then current and temperature. Per bus: the
error log, the commands, the cycles' log. The bus health of every bus together, a view per unit:
the loads (%), the rates (frames, errors, unanswered requests per second), the CAN controllers'
state lanes, the latencies (ms). Above four grippers, one tab per bus (and one for the bus
health). A view exists only when
an entity it shows has rows (``Layout.paths``), so no plot is empty: an RS232 dump has no
measured force or current, a CAN demo polls no current, a gripper that never answered has no
column.

Every plot's time axis is linked to the viewer's shared one, and that one is set: a capture
shows its whole span on every plot (first to last record on the timeline the layout uses, so
a raw dump's plots all run over the same ``frame`` numbers); live, the last 10 s before the
time cursor. Plots with several series keep the top of their y range free, so the legend in
that corner covers no data; a plot of one series names it in its title and has no legend.

``Layout`` is what the blueprint depends on; the listener sends a new blueprint whenever it
changes (a gripper, a bus or a quantity appears, a force outgrows its plot's range).
"""

from __future__ import annotations

import math
import uuid
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Any, Final

import rerun as rr
import rerun.blueprint as rrb

from . import entities as ent

MAX_COLUMNS: Final = 4  # above this many grippers, a tab per bus
LIVE_WINDOW_S: Final = 10.0
# The viewer keeps the time range that linked axes share on a view of this id, which no
# container shows (re_viewer_context's GLOBAL_VIEW_ID in Rerun 0.41): setting it there is
# how a blueprint sets the x range of every linked plot at once.
SHARED_AXIS_VIEW: Final = uuid.UUID("5c0dca6a-e63f-9cf7-f657-2602590474cc")
LEGEND_ROOM: Final = 0.7  # plots with a legend: the data fills at most this much of the height
OPENING_MM: Final = (0.0, 70.0)  # the stroke: opening 0-1000 is 0-70 mm

MOTION_PAGE: Final = "force, opening, state"
ELECTRIC_PAGE: Final = "current, temperature"
HEALTH_PAGE: Final = "bus health"
# the y ranges of the health views that show every bus (keys of ``Layout.ceilings``)
LOAD_PLOT: Final = "health: load"
RATES_PLOT: Final = "health: rates"
LATENCY_PLOT: Final = "health: latency"


@dataclass(frozen=True)
class Layout:
    """What the blueprint shows: buses and grippers in the order first seen, the entities
    that have rows, and how the plots' axes are set."""

    live: bool = False
    buses: tuple[str, ...] = ()
    grippers: tuple[tuple[str, int], ...] = ()  # grippers with readings or settings
    paths: frozenset[str] = frozenset()  # entity paths with rows
    timeline: str = ent.CAPTURE_TIME
    span: tuple[int, int] | None = None  # a capture's first and last on ``timeline``
    ceilings: tuple[tuple[str, float], ...] = ()  # (plot origin, highest value seen, rounded)

    def with_bus(self, bus: str) -> Layout:
        return self if bus in self.buses else replace(self, buses=(*self.buses, bus))

    def with_gripper(self, bus: str, device: int) -> Layout:
        key = (bus, device)
        if key in self.grippers:
            return self
        return replace(self.with_bus(bus), grippers=tuple(sorted((*self.grippers, key))))

    def with_paths(self, paths: Iterable[str]) -> Layout:
        new = self.paths.union(paths)
        return self if new == self.paths else replace(self, paths=new)

    def with_timeline(self, timeline: str) -> Layout:
        return self if timeline == self.timeline else replace(self, timeline=timeline)

    def with_span(self, first: int, last: int) -> Layout:
        span = (first, last)
        return self if span == self.span else replace(self, span=span)

    def with_ceiling(self, origin: str, highest: float) -> Layout:
        """Room for values up to ``highest`` on the plot at ``origin`` (rounded up to 1, 2 or
        5 times a power of ten, so a growing value changes the layout rarely)."""
        ceiling = nice_ceiling(highest)
        ceilings = dict(self.ceilings)
        if ceilings.get(origin, 0.0) >= ceiling:
            return self
        ceilings[origin] = ceiling
        return replace(self, ceilings=tuple(sorted(ceilings.items())))

    def has(self, path: str) -> bool:
        return path in self.paths


def nice_ceiling(value: float) -> float:
    """The smallest of 1, 2, 5 x 10^k at or above ``value`` (1 for anything up to 1)."""
    if not value > 1:
        return 1.0
    power = 10.0 ** math.floor(math.log10(value))
    return next(m * power for m in (1, 2, 5, 10) if m * power >= value)


def blueprint(layout: Layout) -> rrb.Blueprint:
    """The blueprint of ``layout`` (sent as the default blueprint and on every change)."""
    time_panel = rrb.TimePanel(
        timeline=layout.timeline,
        state="collapsed",
        play_state="following" if layout.live else None,
    )
    panels = (rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"))
    root: Any = None
    if len(layout.grippers) > MAX_COLUMNS:
        pages = [p for p in (_page(layout, [bus], bus, health=False) for bus in layout.buses) if p]
        if len(pages) > 1:
            health = _health(layout, list(layout.buses))
            if health is not None:
                pages.append(health)
            if ent.SESSION_ERRORS in layout.paths:
                pages.append(_session_log())
            root = rrb.Tabs(*pages, name="buses")
    if root is None:
        root = _page(layout, list(layout.buses), "grippers", session=True)
    if root is None:  # nothing with rows yet: no view (and the viewer makes none of its own)
        return _SharedAxisBlueprint(layout, time_panel, *panels, auto_views=False)
    return _SharedAxisBlueprint(layout, root, time_panel, *panels, auto_views=False)


class _SharedAxisBlueprint(rrb.Blueprint):
    """A blueprint that also sets the shared time axis of the linked plots (see
    ``SHARED_AXIS_VIEW``): the span of a capture, the last 10 s live."""

    def __init__(self, layout: Layout, *parts: Any, auto_views: bool) -> None:
        super().__init__(*parts, auto_views=auto_views, auto_layout=False)
        self.shared_range = _shared_range(layout)

    def _log_to_stream(self, stream: rr.RecordingStream) -> None:
        super()._log_to_stream(stream)
        if self.shared_range is not None:
            axis = rrb.TimeAxis(view_range=self.shared_range)
            stream.log(f"view/{SHARED_AXIS_VIEW}/TimeAxis", axis)


def _shared_range(layout: Layout) -> rr.TimeRange | None:
    boundary = rrb.TimeRangeBoundary
    if layout.live:
        return rr.TimeRange(
            start=boundary.cursor_relative(seconds=-LIVE_WINDOW_S), end=boundary.cursor_relative()
        )
    if layout.span is None:
        return None
    first, last = layout.span
    if layout.timeline == ent.FRAME:
        return rr.TimeRange(start=boundary.absolute(seq=first), end=boundary.absolute(seq=last))
    return rr.TimeRange(start=boundary.absolute(nanos=first), end=boundary.absolute(nanos=last))


# -- pages ---------------------------------------------------------------------------------------


def _page(
    layout: Layout, buses: list[str], name: str, session: bool = False, health: bool = True
) -> Any | None:
    """The grippers of ``buses`` above their logs and (``health``) their bus health (and the
    session's log, if asked); None when there is nothing to show."""
    grippers = [key for key in layout.grippers if key[0] in buses]
    tops = [
        (page, [c for c in (make(layout, *key) for key in grippers) if c is not None])
        for page, make in ((MOTION_PAGE, _motion_column), (ELECTRIC_PAGE, _electric_column))
    ]
    pages = [rrb.Horizontal(*columns, name=page) for page, columns in tops if columns]
    logs: list[Any] = [t for t in (_bus_logs(layout, bus) for bus in buses) if t is not None]
    views = _health(layout, buses) if health else None
    if views is not None:
        logs.append(views)
    if session and ent.SESSION_ERRORS in layout.paths:
        logs.append(_session_log())
    parts: list[Any] = []
    if pages:
        parts.append(pages[0] if len(pages) == 1 else rrb.Tabs(*pages))
    if logs:
        parts.append(rrb.Horizontal(*logs))
    if not parts:
        return None
    shares = [3.0, 1.0] if len(parts) == 2 else None
    return rrb.Vertical(*parts, row_shares=shares, name=name)


def _session_log() -> rrb.TextLogView:
    return rrb.TextLogView(origin=ent.SESSION_ERRORS, name="session")


def _motion_column(layout: Layout, bus: str, device: int) -> rrb.Vertical | None:
    base = ent.gripper_path(bus, device)
    title = f"{bus} ID {device}"
    views: list[Any] = []
    shares: list[float] = []
    force = _present(layout, base, ent.FORCE_ENTITIES)
    if set(force) - {f"{base}/{ent.FAULT_MARKS}"}:  # marks alone make no force plot
        views.append(_plot(layout, force, f"{base}/{ent.FORCE}", f"{title}: force", legend=True))
        shares.append(2.0)
    opening = _present(layout, base, ent.OPENING_ENTITIES)
    if opening:
        origin = f"{base}/{ent.OPENING}"
        views.append(_plot(layout, opening, origin, f"{title}: opening (mm)", legend=True))
        shares.append(2.0)
    lanes = _present(layout, base, (ent.CYCLES, *ent.LANES.values()))
    if lanes:
        views.append(_lanes(layout, lanes, base, f"{title}: cycles, state"))
        shares.append(1.0 if views[:-1] else 2.0)
    if not views:
        return None
    return rrb.Vertical(*views, row_shares=shares, name=title)


def _electric_column(layout: Layout, bus: str, device: int) -> rrb.Vertical | None:
    base = ent.gripper_path(bus, device)
    title = f"{bus} ID {device}"
    views = [
        _plot(layout, [f"{base}/{entity}"], f"{base}/{entity}", f"{title}: {label}")
        for entity, label in ((ent.CURRENT, "current"), (ent.TEMPERATURE, "temperature (°C)"))
        if layout.has(f"{base}/{entity}")
    ]
    return rrb.Vertical(*views, name=title) if views else None


def _bus_logs(layout: Layout, bus: str) -> rrb.Tabs | None:
    base = ent.bus_path(bus)
    views: list[Any] = []
    errors = f"{base}/{ent.ERRORS}"
    if layout.has(errors):
        views.append(rrb.TextLogView(origin=errors, name=f"{bus} errors"))
    commands = sorted(
        p for p in layout.paths if p.startswith(f"{base}/") and p.endswith(f"/{ent.COMMANDS}")
    )
    if commands:
        views.append(rrb.TextLogView(origin=base, contents=commands, name=f"{bus} commands"))
    cycles = sorted(
        p for p in layout.paths if p.startswith(f"{base}/") and p.endswith(f"/{ent.CYCLE_LOG}")
    )
    if cycles:
        views.append(rrb.TextLogView(origin=base, contents=cycles, name=f"{bus} cycles"))
    return rrb.Tabs(*views, name=bus) if views else None


def _health(layout: Layout, buses: list[str]) -> rrb.Tabs | None:
    """The health of ``buses``, one view per unit, each showing every bus: the loads (%), the
    rates (per second), the CAN controllers' state lanes, the latencies (ms)."""
    bases = [f"{ent.bus_path(bus)}/{ent.HEALTH}" for bus in buses]

    def present(*names: str) -> list[str]:
        return [f"{b}/{n}" for n in names for b in bases if layout.has(f"{b}/{n}")]

    views: list[Any] = []
    load = present(ent.LOAD)
    if load:
        views.append(_plot(layout, load, "/", "bus load (%)", True, LOAD_PLOT))
    rates = present(*ent.RATES)
    if rates:
        name = "frames, errors, unanswered per s"
        views.append(_plot(layout, rates, "/", name, True, RATES_PLOT))
    states = present(ent.CONTROLLER)
    if states:
        views.append(_lanes(layout, states, "/", "CAN controller state"))
    latency = present(ent.LATENCY)
    if latency:
        views.append(_plot(layout, latency, "/", "latency (ms)", True, LATENCY_PLOT))
    return rrb.Tabs(*views, name=HEALTH_PAGE) if views else None


def _present(layout: Layout, base: str, entities: Iterable[str]) -> list[str]:
    return [f"{base}/{e}" for e in entities if layout.has(f"{base}/{e}")]


def _lanes(layout: Layout, contents: list[str], origin: str, name: str) -> rrb.StateTimelineView:
    return rrb.StateTimelineView(
        origin=origin,
        contents=contents,
        name=name,
        time_view=_time_axis(),
        time_ranges=_window(layout),
    )


def _plot(
    layout: Layout,
    contents: list[str],
    origin: str,
    name: str,
    legend: bool = False,
    ceiling: str | None = None,
) -> rrb.TimeSeriesView:
    """A time series of ``contents``: several series keep a legend (at the top left, above
    the data: their y range leaves room for it; ``ceiling``: the key of its highest value,
    by default its origin), one series is named by the title alone."""
    if not legend or len(contents) == 1:
        return rrb.TimeSeriesView(
            origin=origin,
            contents=contents,
            name=name,
            axis_x=_time_axis(),
            time_ranges=_window(layout),
            plot_legend=rrb.PlotLegend(visible=False),
        )
    return rrb.TimeSeriesView(
        origin=origin,
        contents=contents,
        name=name,
        axis_x=_time_axis(),
        axis_y=_room_for_legend(layout, ceiling or origin),
        time_ranges=_window(layout),
        plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.LeftTop, visible=True),
    )


def _room_for_legend(layout: Layout, origin: str) -> rrb.ScalarAxis | None:
    """A y range whose top ``1 - LEGEND_ROOM`` holds no data: the opening's stroke, or the
    highest value seen rounded up (None before any: Rerun's own range)."""
    if origin.endswith(f"/{ent.OPENING}"):
        low, high = OPENING_MM
    else:
        high = dict(layout.ceilings).get(origin, 0.0)
        if not high:
            return None
        low = 0.0
    low -= (high - low) * 0.03  # the zero line stays clear of the axis
    return rrb.ScalarAxis(range=(low, low + (high - low) / LEGEND_ROOM))


def _time_axis() -> rrb.TimeAxis:
    return rrb.TimeAxis(link="LinkToGlobal")


def _window(layout: Layout) -> rrb.VisibleTimeRange | None:
    """Live: the data of the last 10 s before the time cursor (which follows the newest)."""
    if not layout.live:
        return None
    return rrb.VisibleTimeRange(
        layout.timeline,
        start=rrb.TimeRangeBoundary.cursor_relative(seconds=-LIVE_WINDOW_S),
        end=rrb.TimeRangeBoundary.cursor_relative(),
    )
