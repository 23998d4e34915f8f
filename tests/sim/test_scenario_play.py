"""Every scenario, played for real on all three buses and held against its truth.

Each scenario is recorded by a real ``eg2scope record --demo --scenario NAME`` process (the
simulated grippers on two pty lines and python-can's virtual bus, watched by the real passive
taps) and the recording decoded by a real ``eg2scope decode`` process. For every step the
simulator says it played, the gripper's own answers in the capture must show that outcome:
state 6 at the part's width, state 2 with no contact, fault bits, a motion command flagged
unanswered, error frames on CAN while the node is bus-off.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import pytest
from scenario_capture import Capture, Reading, is_motion, readings, record_all, within

from analyzer.sim.scenarios import NAMES, SCENARIOS
from decoders import build

PROTOCOLS = ("serial", "modbus", "can")
Step = dict[str, Any]


@pytest.fixture(scope="module")
def captures(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Capture]]:
    yield record_all(list(NAMES), tmp_path_factory.mktemp("scenarios"))


def _gripped(step: Step, seen: list[Reading], frames: list[Step]) -> None:
    contact = step["contact"]
    held = [r.t for r in seen if r.state == 6 and r.opening == contact]
    assert held, f"no state 6 at {contact}: {seen}"
    assert all(r.opening >= contact for r in seen if r.t < held[0])
    assert not any(r.fault for r in seen)
    if step["slip_to"] is not None:  # the opening keeps closing after contact: held again
        again = [r for r in seen if r.t > held[0] and r.state == 6]
        assert again and again[-1].opening == step["slip_to"], seen
    else:
        assert seen[-1].state == 6 and seen[-1].opening == contact


def _closed_empty(step: Step, seen: list[Reading], frames: list[Step]) -> None:
    assert seen[-1].state == 2 and seen[-1].opening == 0
    assert not any(r.state == 6 for r in seen)


def _opened(step: Step, seen: list[Reading], frames: list[Step]) -> None:
    assert seen[-1].state == 1 and seen[-1].opening == 1000


def _positioned(step: Step, seen: list[Reading], frames: list[Step]) -> None:
    assert seen[-1].state == 3 and seen[-1].opening == step["position"]


def _stopped(step: Step, seen: list[Reading], frames: list[Step]) -> None:
    stops = [r for r in frames if r.get("name") in ("CMD_MC_MOVE_STOPHERE", "CMD_STOP")]
    assert any(r["direction"] == "response" for r in stops), "the stop was not answered"
    assert seen[-1].state == 3 and 0 < seen[-1].opening <= step["stop_at"]


def _faulted(step: Step, seen: list[Reading], frames: list[Step]) -> None:
    faulty = [r for r in seen if r.fault & step["faults"]]
    assert faulty, f"no fault {step['faults']}: {seen}"
    assert faulty[0].state == 3 and faulty[0].opening == step["jam_at"]


def _unanswered(step: Step, seen: list[Reading], frames: list[Step]) -> None:
    motions = [r for r in frames if is_motion(r)]
    assert motions, "the motion command is not in the capture"
    assert all("unanswered" in r["flags"] for r in motions), motions
    assert all(r.state == 1 and r.opening == 1000 for r in seen)  # it never moved


CHECKS: dict[str, Callable[[Step, list[Reading], list[Step]], None]] = {
    "gripped": _gripped,
    "closed_empty": _closed_empty,
    "opened": _opened,
    "positioned": _positioned,
    "stopped": _stopped,
    "faulted": _faulted,
    "unanswered": _unanswered,
}


def _error_classes(frames: list[Step]) -> list[tuple[int, str]]:
    """(class bits, data) of every CAN error frame."""
    return [
        (r["fields"]["error_class"], r["fields"]["data"])
        for r in frames
        if "can_error_frame" in r["flags"]
    ]


def _bus_off(frames: list[Step]) -> None:
    """The node's way down and back, as SocketCAN reports it."""
    errors = _error_classes(frames)
    classes = [c for c, _ in errors]
    passive = [
        c for c, data in errors if c & build.CAN_ERR_CRTL and data.split()[1] == "20"
    ]  # data[1]: CAN_ERR_CRTL_TX_PASSIVE
    assert passive and build.CAN_ERR_BUSOFF in classes and build.CAN_ERR_RESTARTED in classes
    assert classes.index(build.CAN_ERR_BUSOFF) < classes.index(build.CAN_ERR_RESTARTED)


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("name", NAMES)
def test_the_capture_shows_every_step_as_the_truth_says(
    captures: dict[str, Capture], name: str, protocol: str
) -> None:
    capture = captures[name]
    frames, truth = capture.on(protocol)
    script = SCENARIOS[name].script(protocol)
    assert len(truth) >= len(script), capture.stderr  # the whole script played
    for played, step in zip(truth, script, strict=False):
        assert played["outcome"] == step.outcome and played["command"] == step.command
        assert played["answered"] == (not step.drop)
        window = within(frames, played)
        seen = readings(window)
        assert seen, f"step {played['index']}: no poll answered"
        CHECKS[step.outcome](played, seen, window)
        if step.bus_off:
            _bus_off(window)
    if protocol != "can" or not any(s.bus_off for s in script):
        assert _error_classes(frames) == []  # trouble only where a scenario makes it


def test_the_tour_plays_every_outcome(captures: dict[str, Capture]) -> None:
    outcomes = {t["outcome"] for t in captures["tour"].truth}
    assert outcomes == set(CHECKS)
    buses = {t["protocol"] for t in captures["tour"].truth if t["bus_off"]}
    assert buses == {"can"}  # the bus-off step plays without its bus-off elsewhere


def test_the_truth_gives_the_width_at_contact_in_mm(captures: dict[str, Capture]) -> None:
    first = captures["grip"].truth[0]
    assert first["contact"] == 420 and first["contact_mm"] == pytest.approx(29.4)
    assert first["command_words"] == "catch" and first["warnings"] == []
    slip = captures["slip"].truth[0]
    assert slip["warnings"] == ["slip"] and slip["slip_to"] == 252


def test_scenario_runs_are_quick(captures: dict[str, Capture]) -> None:
    """A scenario plays out in a second or two at the tests' time scale."""
    for name in NAMES:
        truth = captures[name].truth
        script = SCENARIOS[name].script("can")
        can = [t for t in truth if t["protocol"] == "can"][: len(script)]
        assert can[-1]["end_t"] - can[0]["start_t"] < 5.0, name
