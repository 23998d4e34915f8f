"""The Rerun listener on real captures of every kind: each .rrd is read back with rerun-sdk's
own reader (``rerun.chunk.RrdReader``) and compared with what the same session decoded: every
entity of the contract (docs/rerun.md) for each gripper, every state sample with its time, seq
and value, the two timelines and no others, the blueprint, the error log, the commands, the
fault marks at the faulty records' times and the bus health."""

from __future__ import annotations

import math
import os
import threading
import time
import tty
from collections import Counter
from pathlib import Path
from typing import Any

import can
import pytest
from native_core import require_native
from plot_checks import check_bus_health
from rerun_inputs import CASES, INPUTS, TIMED, Collector
from rrd_helpers import Rrd, blueprint_text, read_rrd, shared_time_range, views

from analyzer.health.seconds import SecondLog
from analyzer.model import StateSample
from analyzer.plot.blueprint import ELECTRIC_PAGE, LEGEND_ROOM, MOTION_PAGE, Layout, blueprint
from analyzer.plot.health import BusHealthColumns
from analyzer.plot.listener import RerunListener
from analyzer.session.batches import RecordSequence, SampleSequence
from analyzer.session.capture import CaptureOptions, run_capture
from analyzer.session.listener import make_listener
from analyzer.session.session import live_session
from analyzer.sources.can_tap import CanTap
from analyzer.sources.serial_tap import SerialTap
from decoders import build as b
from decoders.eg2_serial import Cmd
from decoders.flags import DEVICE_FAULT, ESTIMATED_TIME, FOREIGN, UNANSWERED
from decoders.model import FRAME, REQUEST
from decoders.registers import opening_mm

# the contract: state field -> entity under /<bus>/<device>/ (docs/rerun.md)
SCALARS = {
    "opening": "opening_mm/measured",
    "target_opening": "opening_mm/target",
    "force": "force/measured",
    "force_setting": "force/limit",
    "current": "current",
    "temperature_c": "temperature_c",
}
LANES = {"state": "state", "fault": "fault"}
PLOTTED = set(SCALARS) | set(LANES)
CURRENT_TEMPERATURE = (": current", ": temperature (°C)")
MM = {"opening", "target_opening"}
READ_CODES = {
    "eg2-serial": {c.value for c in Cmd if c.name.startswith("READ_")},
    "modbus-rtu": {3},
    "eg2-can": {0},
}


def plot(path: Path, out: Path, engine: str = "python") -> tuple[Collector, Rrd]:
    collector = Collector()
    listener = RerunListener(str(out))
    opts = CaptureOptions(str(path), progress=False, engine=engine)
    session, _ = run_capture(opts, [collector, listener, collector.health])
    assert not session.detached
    return collector, read_rrd(out)


class Plotted:
    """Each input plotted once per engine (on first use), and what its session decoded."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.done: dict[tuple[str, str], tuple[Collector, Rrd]] = {}

    def __getitem__(self, key: str | tuple[str, str]) -> tuple[Collector, Rrd]:
        name, engine = (key, "python") if isinstance(key, str) else key
        if engine == "native":
            require_native()
        if (name, engine) not in self.done:
            capture = INPUTS[name](self.tmp)
            self.done[(name, engine)] = plot(capture, self.tmp / f"{name}-{engine}.rrd", engine)
        return self.done[(name, engine)]


@pytest.fixture(scope="module")
def plotted(tmp_path_factory: pytest.TempPathFactory) -> Plotted:
    return Plotted(tmp_path_factory.mktemp("rerun"))


CASE_IDS = [f"{name}-{engine}" for name, engine in CASES]
TIMED_CASES = [c for c in CASES if c[0] in TIMED]
TIMED_IDS = [f"{name}-{engine}" for name, engine in TIMED_CASES]


# -- expectations ------------------------------------------------------------------------------


def ns(t: float | None) -> int | None:
    return None if t is None else round(t * 1e9)


def same_time(got: int | None, t: float | None) -> bool:
    if t is None:
        return got is None
    return got is not None and abs(got / 1e9 - t) < 1e-6


def path_of(bus: str, device: int, entity: str) -> str:
    return f"/{bus}/{device}/{entity}"


def expected_series(samples: list[StateSample]) -> dict[str, list[tuple[float | None, int, Any]]]:
    out: dict[str, list[tuple[float | None, int, Any]]] = {}
    for s in samples:
        for field, value in s.changed.items():
            entity = SCALARS.get(field) or LANES.get(field)
            if entity is None or value is None:
                continue
            if field in MM:
                value = opening_mm(value)
            elif field in LANES:
                value = str(value)
            out.setdefault(path_of(s.bus, s.device, entity), []).append((s.t, s.seq, value))
    return out


def faulty(collector: Collector) -> dict[str, list[tuple[float | None, int]]]:
    """Where the red marks belong: records of a gripper with errors or a fault, and readings
    of fault bits."""
    out: dict[str, set[tuple[float | None, int]]] = {}
    for r in collector.records:
        if r.device is not None and (r.errors or DEVICE_FAULT in r.flags):
            out.setdefault(path_of(r.bus, r.device, "force/faults"), set()).add((r.t, r.seq))
    for s in collector.samples:
        if s.changed.get("fault"):
            out.setdefault(path_of(s.bus, s.device, "force/faults"), set()).add((s.t, s.seq))
    return {k: sorted(v, key=lambda x: x[1]) for k, v in out.items()}


# -- the tests ---------------------------------------------------------------------------------


@pytest.mark.parametrize(("name", "engine"), CASES, ids=CASE_IDS)
def test_every_state_sample_is_plotted_with_its_time_seq_and_value(
    plotted: Plotted, name: str, engine: str
) -> None:
    collector, rrd = plotted[name, engine]
    expected = expected_series(collector.samples)
    assert expected, "the capture has readings"
    for path, rows in expected.items():
        got = rrd[path].rows()
        assert len(got) == len(rows), path
        for (t_ns, frame, value), (t, seq, want) in zip(got, rows, strict=True):
            assert frame == seq, path
            assert same_time(t_ns, t), path
            if isinstance(want, float | int):
                assert value == pytest.approx(want, abs=1e-9), path
            else:
                assert value == want, path
    gripper_entities = {
        p
        for p, e in rrd.entities.items()
        if p.count("/") >= 3
        and p.split("/")[2].isdigit()
        and not p.endswith(("commands", "faults", "cycles", "cycles/log"))
        and e.values
    }
    assert gripper_entities == set(expected), "no entity without a sample behind it"


def test_each_gripper_of_a_can_capture_has_every_entity_of_the_contract(
    plotted: Plotted,
) -> None:
    _, rrd = plotted["candump"]
    for device in (1, 2):
        for entity in [*SCALARS.values(), *LANES.values(), "commands"]:
            assert rrd[path_of("can0", device, entity)].values, entity
    for entity in ("errors", "health/frames_per_s", "health/errors_per_s", "health/latency_ms"):
        assert rrd[f"/can0/{entity}"].values, entity


def test_opening_points_equal_the_opening_readings_in_the_decoded_records(
    plotted: Plotted,
) -> None:
    """Counted from the records themselves, not the tracker: no reading lost to batching."""
    collector, rrd = plotted["candump"]
    for device in (1, 2):
        readings = [
            r.fields["values"]["CMD_OPENLEN_ACT"]
            for r in collector.records
            if r.device == device
            and r.ok
            and "CMD_OPENLEN_ACT" in r.fields.get("values", {})
            and r.fields["values"]["CMD_OPENLEN_ACT"] <= 1000
        ]
        plotted_mm = rrd[path_of("can0", device, "opening_mm/measured")].values
        assert len(plotted_mm) == len(readings) > 5
        assert plotted_mm == pytest.approx([opening_mm(v) for v in readings])


@pytest.mark.parametrize(("name", "engine"), CASES, ids=CASE_IDS)
def test_two_timelines_and_no_sdk_timelines(plotted: Plotted, name: str, engine: str) -> None:
    _, rrd = plotted[name, engine]
    data = {p: e for p, e in rrd.entities.items() if e.values}
    if name in TIMED:
        assert rrd.timelines() == {"capture_time", "frame"}
        for path, e in data.items():
            seconds = "/health/" in path and not path.endswith("latency_ms")  # per second
            want = {"capture_time"} if seconds else {"capture_time", "frame"}
            assert e.timelines == want, path
    else:  # a raw dump carries no time: the frame timeline only
        assert rrd.timelines() == {"frame"}
    assert rrd.recordings == 1


@pytest.mark.parametrize(("name", "engine"), CASES, ids=CASE_IDS)
def test_every_view_of_the_blueprint_has_data(plotted: Plotted, name: str, engine: str) -> None:
    """The blueprint is read back from the file and each view's query resolved against the
    recording: every view shows at least one entity with rows of what it draws, and every
    entity it names has them."""
    _, rrd = plotted[name, engine]
    assert rrd.blueprints, "a default blueprint in every .rrd"
    shown = views(rrd)
    assert shown
    for view in shown:
        assert view.entities, f"{view.name} is empty"
        named = [q for q in view.query if q.startswith("/")]
        assert set(named) <= set(view.entities), view.name


@pytest.mark.parametrize(("name", "engine"), CASES, ids=CASE_IDS)
def test_a_view_for_every_quantity_the_capture_carries_and_none_other(
    plotted: Plotted, name: str, engine: str
) -> None:
    """The plots and lanes show exactly the entities the tracker gave samples for: a column
    per gripper with readings or settings, a plot per quantity it has."""
    collector, rrd = plotted[name, engine]
    shown = views(rrd)
    drawn = {e for v in shown if v.kind != "TextLog" for e in v.entities}
    gripper_rows = {
        e
        for e in drawn
        if e.split("/")[2].isdigit() and "faults" not in e and not e.endswith("/cycles")
    }
    assert gripper_rows == set(expected_series(collector.samples))
    grippers = {(s.bus, s.device) for s in collector.samples if set(s.changed) & PLOTTED}
    titled = {v.name.split(":")[0] for v in shown if v.kind != "TextLog" and " ID " in v.name}
    assert titled == {f"{bus} ID {device}" for bus, device in grippers}
    for path, e in rrd.entities.items():  # every log and health entity with rows has a view
        if e.values and not path.split("/")[2].isdigit():
            assert any(path in v.entities for v in shown), path


def test_no_plot_for_what_the_capture_does_not_carry(plotted: Plotted) -> None:
    """The issue's cases: RS232 run-state polls carry no current; the CAN demo polls no
    current or temperature; a gripper that never answered (serial ID 2) gets no column."""
    names = {v.name for v in views(plotted["serial"][1])}
    assert "serial ID 1: current" not in names
    assert not any(n.startswith("serial ID 2") for n in names)
    assert "serial ID 1: opening (mm)" in names
    names = {v.name for v in views(plotted["mixed"][1])}
    for device in (1, 2):
        assert f"can0 ID {device}: force" in names
        assert f"can0 ID {device}: current" not in names
        assert f"can0 ID {device}: temperature (°C)" not in names
        assert f"rs485 ID {device}: current" in names


@pytest.mark.parametrize(("name", "engine"), CASES, ids=CASE_IDS)
def test_every_plot_spans_the_whole_capture_on_one_axis(
    plotted: Plotted, name: str, engine: str
) -> None:
    """Plots are linked to the viewer's shared time axis, which is set to the capture's first
    and last record (seq for a raw dump, time otherwise); no row lies outside it."""
    collector, rrd = plotted[name, engine]
    timed = name in TIMED
    if timed:
        stamps = [ns(r.t) for r in collector.records if r.t is not None]
        first, last = min(stamps), max(stamps)
    else:
        first = min(r.seq for r in collector.records)
        last = max(r.seq for r in collector.records)
    span = shared_time_range(rrd)
    assert span is not None
    assert abs(span["start"] - first) <= 1000 and abs(span["end"] - last) <= 1000  # t * 1e9
    for view in views(rrd):
        if view.kind != "TextLog":
            assert view.properties["TimeAxis:link"] == [2], view.name  # LinkToGlobal
            assert "TimeAxis:view_range" not in view.properties, view.name
    timeline = "capture_time" if timed else "frame"
    text = blueprint_text(rrd)
    assert f"'TimePanelBlueprint:timeline': [['{timeline}']]" in text
    assert "VisibleTimeRanges" not in text  # a capture shows all of itself
    for path, e in rrd.entities.items():
        at = [x for x in (e.capture_time if timed else e.frame) if x is not None]
        assert all(span["start"] <= x <= span["end"] for x in at), path


@pytest.mark.parametrize(("name", "engine"), CASES, ids=CASE_IDS)
def test_plots_are_readable(plotted: Plotted, name: str, engine: str) -> None:
    """Per gripper, force, opening and the lanes on one page, current and temperature on
    another; a plot of several series keeps its legend above the data (its y range leaves
    the top free), a plot of one series has none; rates and milliseconds apart."""
    _, rrd = plotted[name, engine]
    for view in views(rrd):
        if view.kind == "TextLog":
            continue
        if " ID " in view.name:
            electric = view.name.endswith(CURRENT_TEMPERATURE)
            assert (ELECTRIC_PAGE if electric else MOTION_PAGE) in view.containers, view.name
        if view.kind != "TimeSeries":
            continue
        assert not (
            any(e.endswith("latency_ms") for e in view.entities)
            and any(e.endswith("_per_s") for e in view.entities)
        )
        if len(view.entities) == 1:
            assert view.properties["PlotLegend:visible"] == [False], view.name
            continue
        assert view.properties["PlotLegend:visible"] == [True], view.name
        (low, high), *_ = view.properties["ScalarAxis:range"]
        values = [v for e in view.entities for v in rrd[e].values]
        assert low <= min(values), view.name
        assert max(values) <= low + (high - low) * LEGEND_ROOM + 1e-9, view.name


@pytest.mark.parametrize(("name", "engine"), CASES, ids=CASE_IDS)
def test_fault_marks_at_the_times_of_the_faulty_records(
    plotted: Plotted, name: str, engine: str
) -> None:
    collector, rrd = plotted[name, engine]
    want = faulty(collector)
    got = {p: e for p, e in rrd.entities.items() if p.endswith("/force/faults") and e.values}
    assert set(got) == set(want)
    for path, rows in want.items():
        marks = sorted(zip(rrd[path].frame, rrd[path].capture_time, strict=True))
        assert [m[0] for m in marks] == [seq for _, seq in rows]
        for (_, t_ns), (t, _) in zip(marks, rows, strict=True):
            assert same_time(t_ns, t)
        assert rrd[path].static["SeriesPoints:colors"] == [[0xE3000BFF]]  # red


def test_fault_marks_cover_fault_readings_and_checksum_errors(
    plotted: Plotted,
) -> None:
    """The synthetic captures: a CAN fault reading (3: stall, over-temperature) marked once,
    at the force last read; the serial run state with faults and the catch with a bad sum."""
    _, rrd = plotted["faults_can"]
    marks = rrd["/can0/1/force/faults"]
    assert marks.frame == [3] and marks.values == [0]  # no force read yet
    assert rrd["/can0/1/fault"].values == ["0", "3", "0"]
    labels = rrd["/can0/1/fault"].static["StateConfiguration:labels"][0]
    assert labels[0] == "no fault" and labels[3] == "stall, over-temperature"
    _, rrd = plotted["faults_serial"]
    assert len(rrd["/serial/1/force/faults"].values) == 2
    assert rrd["/serial/1/commands"].values == ["catch speed=500 force=100 g"]


@pytest.mark.parametrize(("name", "engine"), CASES, ids=CASE_IDS)
def test_error_log_has_every_problem_with_its_level(
    plotted: Plotted, name: str, engine: str
) -> None:
    collector, rrd = plotted[name, engine]
    quiet = {FOREIGN, ESTIMATED_TIME}
    want: dict[str, list[tuple[int, str]]] = {}
    for r in collector.records:
        if r.errors:
            level = "ERROR"
        elif r.warnings and not (r.flags and quiet.issuperset(r.flags)):
            level = "WARN"
        else:
            continue
        want.setdefault(f"/{r.bus}/errors", []).append((r.seq, level))
    for path, rows in want.items():
        log = rrd[path]
        assert sorted(zip(log.frame, log.levels, strict=True)) == sorted(rows)
        assert all(": " in text for text in log.values)


@pytest.mark.parametrize(("name", "engine"), CASES, ids=CASE_IDS)
def test_commands_in_words_without_the_polls(plotted: Plotted, name: str, engine: str) -> None:
    collector, rrd = plotted[name, engine]
    want: dict[str, list[tuple[int, str]]] = {}
    for r in collector.records:
        polls = READ_CODES.get(r.protocol, set())
        command = r.direction == REQUEST and r.kind == FRAME and r.code not in polls
        if command and r.device is not None and not r.errors:
            path = path_of(r.bus, r.device, "commands")
            want.setdefault(path, []).append((r.seq, r.summary))
    got = {p: e for p, e in rrd.entities.items() if p.endswith("/commands")}
    assert set(got) == set(want)
    for path, rows in want.items():
        assert sorted(zip(got[path].frame, got[path].values, strict=True)) == rows


@pytest.mark.parametrize(("name", "engine"), TIMED_CASES, ids=TIMED_IDS)
def test_bus_health_counts_every_frame_error_and_latency(
    plotted: Plotted, name: str, engine: str
) -> None:
    """Frames, errors and the load per second are the bus health's (what ``stats`` reports);
    unanswered requests and latencies come from the records."""
    collector, rrd = plotted[name, engine]
    buses = collector.health.buses()
    assert {b["bus"] for b in buses} == {r.bus for r in collector.records if r.t is not None}
    for figures in buses:
        check_bus_health(rrd, figures)
    for bus in {r.bus for r in collector.records if r.t is not None}:
        timed = [r for r in collector.records if r.t is not None and r.bus == bus]
        frames = rrd[f"/{bus}/health/frames_per_s"]
        unanswered = sum(1 for r in timed if UNANSWERED in r.flags)
        assert sum(rrd[f"/{bus}/health/unanswered_per_s"].values) == unanswered
        seconds = sorted({math.floor(r.t) for r in timed if r.kind == FRAME and not r.errors})
        ends = [t / 1e9 for t, v in zip(frames.capture_time, frames.values, strict=True) if v]
        last = max(r.t for r in timed if r.t is not None)
        # a point at the end of each second with frames; the last, partial one at the last
        # record. A frame decided after its second was handed out counts in the first second
        # still open (health/seconds.py; check_bus_health found every frame counted once), so
        # its second may have no point of its own, but no point is anywhere else
        expected = [min(s + 1, last) for s in seconds]
        assert ends
        assert all(min(abs(end - at) for at in expected) <= 1e-6 for end in ends), ends
        latencies = [r.latency_ms for r in timed if r.latency_ms is not None]
        assert rrd[f"/{bus}/health/latency_ms"].values == pytest.approx(latencies)


def test_health_drops_to_zero_over_a_silent_stretch(
    plotted: Plotted,
) -> None:
    """faults.log: six frames in second 0, two in second 3: seconds 1 and 2 count zero; the
    last second's point is at the last record (3.501 s), not past the capture."""
    _, rrd = plotted["faults_can"]
    frames = rrd["/can0/health/frames_per_s"]
    t0 = 1_763_700_100
    points = sorted(zip(frames.capture_time, frames.values, strict=True))
    assert [v for _, v in points] == [6, 0, 0, 2]
    at = [(t0 + 1) * 10**9, (t0 + 2) * 10**9, (t0 + 3) * 10**9, (t0 + 3) * 10**9 + 501_000_000]
    assert [t for t, _ in points] == pytest.approx(at, abs=1000)  # the float t's nanoseconds


def test_series_are_named_and_coloured_once_as_static(
    plotted: Plotted,
) -> None:
    _, rrd = plotted["candump"]
    names = {
        "opening_mm/measured": "opening (mm)",
        "opening_mm/target": "target (mm)",
        "force/measured": "force",
        "force/limit": "force limit",
        "current": "current",
        "temperature_c": "temperature (°C)",
    }
    for entity, name in names.items():
        static = rrd[path_of("can0", 1, entity)].static
        assert static["SeriesLines:names"] == [[name]]
        assert len(static["SeriesLines:colors"][0]) == 1
    state = rrd[path_of("can0", 1, "state")].static
    assert state["StateConfiguration:values"] == [["1", "2", "3", "4", "5", "6"]]
    assert state["StateConfiguration:labels"][0][5] == "stopped by the force limit while closing"


# -- the blueprint's shape -----------------------------------------------------------------------


def containers(bp: Any) -> list[str]:
    """Kinds of the blueprint's containers, outermost first."""
    out = []
    stack = [bp.root_container]
    while stack:
        c = stack.pop(0)
        if hasattr(c, "kind"):
            out.append(str(c.kind))
            stack += list(c.contents)
    return out


@pytest.mark.parametrize(
    ("grippers", "tabs"),
    [(1, False), (4, False), (5, True), (8, True)],
)
def test_above_four_grippers_a_tab_per_bus(grippers: int, tabs: bool) -> None:
    layout = Layout()
    for i in range(grippers):
        bus = ("can0", "rs485")[i % 2]
        layout = layout.with_gripper(bus, i + 1).with_paths([f"/{bus}/{i + 1}/force/measured"])
    bp = blueprint(layout)
    kinds = containers(bp)
    assert (kinds[0] == "Tabs") is tabs
    if tabs:
        names = [str(c.name) for c in bp.root_container.contents]
        assert names == ["can0", "rs485"]


def test_a_layout_without_rows_has_no_view() -> None:
    """A gripper seen but with nothing plotted yet (a live session's start): no view, and
    the viewer is told to make none of its own."""
    bp = blueprint(Layout(live=True).with_gripper("can0", 1))
    assert not hasattr(bp, "root_container")
    assert bp.auto_views is False


def test_live_plots_follow_a_ten_second_window() -> None:
    layout = Layout(live=True).with_gripper("can0", 1).with_paths(["/can0/1/force/measured"])
    live = blueprint(layout)
    force = live.root_container.contents[0].contents[0].contents[0]  # page, column, plot
    ranges = force.properties["VisibleTimeRanges"]
    assert "capture_time" in repr(ranges) and "-10000000000" in repr(ranges)
    assert live.time_panel.play_state is not None
    shared = repr(live.shared_range)  # the shared x axis: the last 10 s
    assert "cursor_relative" in shared and "-10000000000" in shared


def test_the_listener_is_registered_by_name(tmp_path: Path) -> None:
    listener = make_listener("rerun", str(tmp_path / "x.rrd"))
    assert isinstance(listener, RerunListener)
    listener.close()
    assert read_rrd(tmp_path / "x.rrd").blueprints


# -- live sessions -----------------------------------------------------------------------------


def run_live(
    taps: list[Any], out: Path, feed: Any, engine: str = "auto"
) -> tuple[Collector, Rrd, RerunListener]:
    collector = Collector()
    listener = RerunListener(str(out), live=True)
    session = live_session(taps, [collector, listener], engine=engine)
    thread = threading.Thread(target=session.run, daemon=True)
    thread.start()
    time.sleep(0.3)  # the taps open
    feed()
    time.sleep(0.5)
    session.stop()
    thread.join(10)
    assert not thread.is_alive() and not session.detached
    return collector, read_rrd(out), listener


@pytest.mark.parametrize("engine", ["python", "native"])
def test_live_on_the_virtual_can_bus(tmp_path: Path, engine: str) -> None:
    channel = f"eg2-rerun-{os.getpid()}-{time.monotonic_ns()}"

    def feed() -> None:
        with can.Bus(interface="virtual", channel=channel) as sender:
            for f in (  # a motion command: the target opening written
                b.can_write_request(1, 1020, b.u16le(410)),
                b.can_write_response(1, 1020, 2),
            ):
                sender.send(can.Message(arbitration_id=f.arbitration_id, data=f.data))
            for i in range(60):
                opening = 1000 - 10 * i
                for f in (
                    b.can_read_request(1, 1120, 8),
                    b.can_read_response(1, 1120, b.u16le(20, opening, 300, 35)),
                ):
                    msg = can.Message(arbitration_id=f.arbitration_id, data=f.data)
                    sender.send(msg)
                time.sleep(0.01)

    taps = [CanTap("can0", "virtual", channel)]
    collector, rrd, _ = run_live(taps, tmp_path / "l.rrd", feed, engine)
    opening = rrd["/can0/1/opening_mm/measured"]
    assert opening.values == pytest.approx([opening_mm(1000 - 10 * i) for i in range(60)])
    expected = expected_series(collector.samples)
    for path, rows in expected.items():
        assert len(rrd[path].values) == len(rows), path
    assert rrd.timelines() == {"capture_time", "frame"}
    assert "VisibleTimeRanges" in blueprint_text(rrd)  # live: the sliding window
    assert len(rrd["/can0/1/opening_mm/measured"].frame) == 60
    shown = views(rrd)  # the blueprint grew with the data: a view for each quantity polled
    assert all(v.entities for v in shown)
    assert {v.name for v in shown} >= {"can0 ID 1: force", "can0 ID 1: current"}
    lanes = {v.name: v.entities for v in shown if v.kind == "StateTimeline"}
    assert lanes["can0 ID 1: cycles, state"] == ["/can0/1/cycles"]  # 1128 was never polled
    # the bus health, as each second ended: one view per unit
    health = {v.name: v.entities for v in shown if "bus health" in v.containers}
    assert health["bus load (%)"] == ["/can0/health/load_pct"]
    assert health["CAN controller state"] == ["/can0/health/state"]
    assert rrd["/can0/health/state"].values == ["error_active"]
    # the grip cycle the write began, on its gripper's lane at the write's seq, as it ended
    (write,) = [r for r in collector.records if r.direction == REQUEST and r.code == 1]
    lane = rrd["/can0/1/cycles"]
    assert lane.frame[0] == write.seq and lane.values[0]
    assert rrd["/can0/1/cycles/log"].values[0].startswith("move to 28.7 mm: ")


def test_live_on_a_serial_pty(tmp_path: Path) -> None:
    master, slave = os.openpty()
    tty.setraw(slave)
    port = os.ttyname(slave)
    s = b.serial_frame

    def feed() -> None:
        for pos in range(1000, 400, -50):
            os.write(master, s(1, Cmd.READ_ACTPOS))
            time.sleep(0.003)
            os.write(master, s(1, Cmd.READ_ACTPOS, b.u16le(pos), response=True))
            time.sleep(0.01)

    try:
        collector, rrd, _ = run_live([SerialTap("rs232", port)], tmp_path / "s.rrd", feed)
    finally:
        os.close(master)
        os.close(slave)
    opening = rrd["/rs232/1/opening_mm/measured"]
    assert opening.values == pytest.approx([opening_mm(p) for p in range(1000, 400, -50)])
    assert all(t is not None for t in opening.capture_time)
    shown = views(rrd)
    names = {v.name for v in shown}
    # only the opening was read: no other plot of the gripper (a loaded machine may split a
    # frame, so the error log may or may not be there)
    assert {n for n in names if n.startswith("rs232 ID 1")} == {"rs232 ID 1: opening (mm)"}
    assert {"frames, errors, unanswered per s", "latency (ms)"} <= names
    assert all(v.entities for v in shown)
    assert Counter(s.bus for s in collector.samples) == Counter({"rs232": 24})


# -- the listener's own paths ------------------------------------------------------------------


def sample(seq: int, **changed: Any) -> StateSample:
    return StateSample(1_763_700_000.0 + seq / 10, "can0", 1, "eg2-can", seq, changed, {})


def test_a_sample_with_a_value_that_is_not_a_number_is_plotted_field_by_field(
    tmp_path: Path,
) -> None:
    """Samples are filed by the fields they changed; one whose value is None (named without a
    value) or not a number goes field by field: nothing lost, nothing invented."""
    listener = RerunListener(str(tmp_path / "odd.rrd"))
    listener.on_states(
        SampleSequence(
            [
                sample(1, force=10, opening=500, state=4),
                sample(2, force=None, opening=510, state=4),
                sample(3, force=12, opening=520, state="closing"),
                sample(4, force=13, opening=530, state=6),
            ]
        )
    )
    listener.close()
    rrd = read_rrd(tmp_path / "odd.rrd")
    force = rrd["/can0/1/force/measured"].rows()
    assert [(frame, value) for _, frame, value in force] == [(1, 10), (3, 12), (4, 13)]
    opening = rrd["/can0/1/opening_mm/measured"].rows()
    assert [v for _, _, v in opening] == pytest.approx(
        [opening_mm(v) for v in (500, 510, 520, 530)]
    )
    assert [v for _, _, v in rrd["/can0/1/state"].rows()] == ["4", "4", "closing", "6"]
    for entity in ("force/measured", "opening_mm/measured", "state"):
        for t_ns, frame, _ in rrd[f"/can0/1/{entity}"].rows():
            assert same_time(t_ns, 1_763_700_000.0 + frame / 10)


def test_a_live_listener_flushes_on_its_timer_while_the_session_is_busy(tmp_path: Path) -> None:
    """No tick comes (the session is decoding a long batch): the timer thread flushes; never
    between a batch's records and its samples."""
    listener = RerunListener(str(tmp_path / "timer.rrd"), live=True)
    flushes: list[str] = []
    flush = listener.flush

    def counted(final: bool = False) -> None:
        flushes.append(threading.current_thread().name)
        flush(final)

    listener.flush = counted  # type: ignore[method-assign]
    listener.on_states(SampleSequence([sample(1, force=10)]))
    deadline = time.monotonic() + 5
    while not flushes and time.monotonic() < deadline:
        time.sleep(0.01)
    assert flushes == ["rerun-flush"]
    listener.on_records(RecordSequence())  # a batch's records: its samples come next
    time.sleep(0.3)
    assert flushes == ["rerun-flush"]  # due, but the batch is not complete
    listener.on_states(SampleSequence([sample(2, force=11)]))
    deadline = time.monotonic() + 5
    while len(flushes) < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    listener.close()
    assert flushes[1] == "rerun-flush"
    rows = read_rrd(tmp_path / "timer.rrd")["/can0/1/force/measured"].rows()
    assert [(frame, value) for _, frame, value in rows] == [(1, 10), (2, 11)]


def test_a_serial_second_counted_from_reads_then_records_is_plotted_once() -> None:
    """A serial line's second counted from its reads, then from records that came later: the
    bus health hands it out once the records have passed it, and it is one point."""
    log = SecondLog("rs485", "serial", 115_200, None)
    columns = BusHealthColumns("rs485", 0)
    log.read(100, 300)
    log.frames(100, 3, 0)
    columns.add(log.take(), 100.0, 100.9)  # the records are still in second 100
    assert not columns.series["frames_per_s"].values
    log.read(101, 100)
    log.frames(100, 2, 0)
    log.error(100, ("bad_checksum",))
    log.frames(101, 1, 0)
    columns.add(log.take(), 100.0, 101.2)
    assert list(columns.series["frames_per_s"].values) == [5.0]
    assert list(columns.series["errors_per_s"].values) == [1.0]
    assert list(columns.series["load_pct"].values) == [round(300 / 1152, 3)]
    assert list(columns.series["load_pct"].t) == [101.0]
