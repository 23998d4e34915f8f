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
from rerun_inputs import INPUTS, TIMED, Collector
from rrd_helpers import Rrd, blueprint_text, read_rrd

from analyzer.commands.common import CaptureOptions, run_capture
from analyzer.listener import make_listener
from analyzer.model import StateSample
from analyzer.rerun_blueprint import Layout, blueprint
from analyzer.session import live_session
from analyzer.sinks.rerun import RerunListener
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
MM = {"opening", "target_opening"}
READ_CODES = {
    "eg2-serial": {c.value for c in Cmd if c.name.startswith("READ_")},
    "modbus-rtu": {3},
    "eg2-can": {0},
}


def plot(path: Path, out: Path) -> tuple[Collector, Rrd]:
    collector = Collector()
    listener = RerunListener(str(out))
    session, _ = run_capture(CaptureOptions(str(path), progress=False), [collector, listener])
    assert not session.detached
    return collector, read_rrd(out)


@pytest.fixture(scope="module")
def plotted(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Collector, Rrd]]:
    tmp = tmp_path_factory.mktemp("rerun")
    return {name: plot(make(tmp), tmp / f"{name}.rrd") for name, make in INPUTS.items()}


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


@pytest.mark.parametrize("name", list(INPUTS))
def test_every_state_sample_is_plotted_with_its_time_seq_and_value(
    plotted: dict[str, tuple[Collector, Rrd]], name: str
) -> None:
    collector, rrd = plotted[name]
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
        and not p.endswith(("commands", "faults"))
        and e.values
    }
    assert gripper_entities == set(expected), "no entity without a sample behind it"


def test_each_gripper_of_a_can_capture_has_every_entity_of_the_contract(
    plotted: dict[str, tuple[Collector, Rrd]],
) -> None:
    _, rrd = plotted["candump"]
    for device in (1, 2):
        for entity in [*SCALARS.values(), *LANES.values(), "commands"]:
            assert rrd[path_of("can0", device, entity)].values, entity
    for entity in ("errors", "health/frames_per_s", "health/errors_per_s", "health/latency_ms"):
        assert rrd[f"/can0/{entity}"].values, entity


def test_opening_points_equal_the_opening_readings_in_the_decoded_records(
    plotted: dict[str, tuple[Collector, Rrd]],
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


@pytest.mark.parametrize("name", list(INPUTS))
def test_two_timelines_and_no_sdk_timelines(
    plotted: dict[str, tuple[Collector, Rrd]], name: str
) -> None:
    _, rrd = plotted[name]
    data = {p: e for p, e in rrd.entities.items() if e.values}
    if name in TIMED:
        assert rrd.timelines() == {"capture_time", "frame"}
        for path, e in data.items():
            want = {"capture_time"} if "_per_s" in path else {"capture_time", "frame"}
            assert e.timelines == want, path
    else:  # a raw dump carries no time: the frame timeline only
        assert rrd.timelines() == {"frame"}
    assert rrd.recordings == 1


@pytest.mark.parametrize("name", list(INPUTS))
def test_the_blueprint_is_in_the_file_with_a_column_per_gripper(
    plotted: dict[str, tuple[Collector, Rrd]], name: str
) -> None:
    collector, rrd = plotted[name]
    assert rrd.blueprints, "a default blueprint in every .rrd"
    text = blueprint_text(rrd)
    grippers = {(s.bus, s.device) for s in collector.samples if set(s.changed) - {"last_command"}}
    assert grippers
    for bus, device in grippers:
        for origin in ("force", "opening_mm", "current", "temperature_c"):
            assert f"'/{bus}/{device}/{origin}'" in text, (bus, device, origin)
        assert f"'{bus} ID {device}'" in text
    for bus in {s.bus for s in collector.samples}:
        assert f"'/{bus}/errors'" in text
    assert "'TimeAxis:link': [[2]]" in text  # linked x axes
    timeline = "capture_time" if name in TIMED else "frame"
    assert f"'TimePanelBlueprint:timeline': [['{timeline}']]" in text
    assert "VisibleTimeRanges" not in text  # a capture shows all of itself


@pytest.mark.parametrize("name", list(INPUTS))
def test_fault_marks_at_the_times_of_the_faulty_records(
    plotted: dict[str, tuple[Collector, Rrd]], name: str
) -> None:
    collector, rrd = plotted[name]
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
    plotted: dict[str, tuple[Collector, Rrd]],
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


@pytest.mark.parametrize("name", list(INPUTS))
def test_error_log_has_every_problem_with_its_level(
    plotted: dict[str, tuple[Collector, Rrd]], name: str
) -> None:
    collector, rrd = plotted[name]
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


@pytest.mark.parametrize("name", list(INPUTS))
def test_commands_in_words_without_the_polls(
    plotted: dict[str, tuple[Collector, Rrd]], name: str
) -> None:
    collector, rrd = plotted[name]
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


@pytest.mark.parametrize("name", sorted(TIMED))
def test_bus_health_counts_every_frame_error_and_latency(
    plotted: dict[str, tuple[Collector, Rrd]], name: str
) -> None:
    collector, rrd = plotted[name]
    timed = [r for r in collector.records if r.t is not None]
    bus = timed[0].bus
    frames = rrd[f"/{bus}/health/frames_per_s"]
    assert sum(frames.values) == sum(1 for r in timed if r.kind == FRAME)
    assert sum(rrd[f"/{bus}/health/errors_per_s"].values) == sum(1 for r in timed if r.errors)
    unanswered = sum(1 for r in timed if UNANSWERED in r.flags)
    assert sum(rrd[f"/{bus}/health/unanswered_per_s"].values) == unanswered
    seconds = sorted({math.floor(r.t) for r in timed if r.t is not None})
    ends = [t / 1e9 for t, v in zip(frames.capture_time, frames.values, strict=True) if v]
    assert ends == [s + 1 for s in seconds]  # one point at the end of each second
    latencies = [r.latency_ms for r in timed if r.latency_ms is not None]
    assert rrd[f"/{bus}/health/latency_ms"].values == pytest.approx(latencies)


def test_health_drops_to_zero_over_a_silent_stretch(
    plotted: dict[str, tuple[Collector, Rrd]],
) -> None:
    """faults.log: six frames in second 0, two in second 3: seconds 1 and 2 count zero."""
    _, rrd = plotted["faults_can"]
    frames = rrd["/can0/health/frames_per_s"]
    t0 = 1_763_700_100
    assert sorted(zip(frames.capture_time, frames.values, strict=True)) == [
        ((t0 + 1) * 10**9, 6),
        ((t0 + 2) * 10**9, 0),
        ((t0 + 3) * 10**9, 0),
        ((t0 + 4) * 10**9, 2),
    ]


def test_series_are_named_and_coloured_once_as_static(
    plotted: dict[str, tuple[Collector, Rrd]],
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
        layout = layout.with_gripper(("can0", "rs485")[i % 2], i + 1)
    bp = blueprint(layout)
    kinds = containers(bp)
    assert (kinds[0] == "Tabs") is tabs
    if tabs:
        names = [str(c.name) for c in bp.root_container.contents]
        assert names == ["can0", "rs485"]


def test_live_plots_follow_a_ten_second_window() -> None:
    live = blueprint(Layout(live=True).with_gripper("can0", 1))
    view = live.root_container.contents[0].contents[0].contents[0]  # the force plot
    ranges = view.properties["VisibleTimeRanges"]
    assert "capture_time" in repr(ranges) and "-10000000000" in repr(ranges)
    assert live.time_panel.play_state is not None


def test_the_listener_is_registered_by_name(tmp_path: Path) -> None:
    listener = make_listener("rerun", str(tmp_path / "x.rrd"))
    assert isinstance(listener, RerunListener)
    listener.close()
    assert read_rrd(tmp_path / "x.rrd").blueprints


# -- live sessions -----------------------------------------------------------------------------


def run_live(taps: list[Any], out: Path, feed: Any) -> tuple[Collector, Rrd, RerunListener]:
    collector = Collector()
    listener = RerunListener(str(out), live=True)
    session = live_session(taps, [collector, listener])
    thread = threading.Thread(target=session.run, daemon=True)
    thread.start()
    time.sleep(0.3)  # the taps open
    feed()
    time.sleep(0.5)
    session.stop()
    thread.join(10)
    assert not thread.is_alive() and not session.detached
    return collector, read_rrd(out), listener


def test_live_on_the_virtual_can_bus(tmp_path: Path) -> None:
    channel = f"eg2-rerun-{os.getpid()}-{time.monotonic_ns()}"

    def feed() -> None:
        with can.Bus(interface="virtual", channel=channel) as sender:
            for i in range(60):
                opening = 1000 - 10 * i
                for f in (
                    b.can_read_request(1, 1120, 8),
                    b.can_read_response(1, 1120, b.u16le(20, opening, 300, 35)),
                ):
                    msg = can.Message(arbitration_id=f.arbitration_id, data=f.data)
                    sender.send(msg)
                time.sleep(0.01)

    collector, rrd, _ = run_live([CanTap("can0", "virtual", channel)], tmp_path / "l.rrd", feed)
    opening = rrd["/can0/1/opening_mm/measured"]
    assert opening.values == pytest.approx([opening_mm(1000 - 10 * i) for i in range(60)])
    expected = expected_series(collector.samples)
    for path, rows in expected.items():
        assert len(rrd[path].values) == len(rows), path
    assert rrd.timelines() == {"capture_time", "frame"}
    assert "VisibleTimeRanges" in blueprint_text(rrd)  # live: the sliding window
    assert len(rrd["/can0/1/opening_mm/measured"].frame) == 60


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
        [
            sample(1, force=10, opening=500, state=4),
            sample(2, force=None, opening=510, state=4),
            sample(3, force=12, opening=520, state="closing"),
            sample(4, force=13, opening=530, state=6),
        ]
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
    listener.on_states([sample(1, force=10)])
    deadline = time.monotonic() + 5
    while not flushes and time.monotonic() < deadline:
        time.sleep(0.01)
    assert flushes == ["rerun-flush"]
    listener.on_records([])  # a batch's records: its samples come next
    time.sleep(0.3)
    assert flushes == ["rerun-flush"]  # due, but the batch is not complete
    listener.on_states([sample(2, force=11)])
    deadline = time.monotonic() + 5
    while len(flushes) < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    listener.close()
    assert flushes[1] == "rerun-flush"
    rows = read_rrd(tmp_path / "timer.rrd")["/can0/1/force/measured"].rows()
    assert [(frame, value) for _, frame, value in rows] == [(1, 10), (2, 11)]
