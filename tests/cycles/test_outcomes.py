"""The segmenter and the outcome rules on scripted buses (``cycle_script``: frames made by
decoders/build.py), on all three protocols, through a real session on each engine (the native
one for CAN): every outcome, the measurements, the evidence, and what a cycle says it could
not know (docs/contracts.md, "Grip cycles")."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from cycle_script import BROADCAST, PROTOCOLS, Script
from native_core import require_native

from analyzer.cycles.model import Cycle
from decoders.model import EG2_CAN, EG2_SERIAL
from decoders.registers import opening_mm

CASES = [(p, "python") for p in PROTOCOLS] + [(EG2_CAN, "native")]


@pytest.fixture(params=CASES, ids=lambda c: f"{c[0]}-{c[1]}")
def case(request: pytest.FixtureRequest) -> tuple[str, str]:
    if request.param[1] == "native":
        require_native()
    return request.param  # type: ignore[no-any-return]


@pytest.fixture
def script(case: tuple[str, str]) -> Script:
    return Script(case[0])


def run(script: Script, case: tuple[str, str], size: int = 7) -> list[Cycle]:
    return script.cycles(case[1], size)


def only(cycles: list[Cycle]) -> Cycle:
    assert len(cycles) == 1, [c.to_dict() for c in cycles]
    return cycles[0]


def at_rest(s: Script, opening: int = 1000, state: int = 1) -> None:
    s.poll(state=state, opening=opening, force=0)


# -- the outcomes -----------------------------------------------------------------------------


def test_gripped(script: Script, case: tuple[str, str]) -> None:
    at_rest(script)
    start = script.catch()
    script.poll(state=1, opening=1000, force=0)  # not started yet: the last state still
    script.poll(state=4, opening=700, force=0)
    script.poll(state=4, opening=450, force=10)
    final = script.poll(state=6, opening=420, force=100)
    script.poll(state=6, opening=420, force=100)
    end = script.release()
    cycle = run(script, case)[0]
    assert cycle.outcome == "gripped"
    assert (cycle.start_seq, cycle.end_seq) == (start, end)  # ends at the next command
    assert cycle.width_mm == opening_mm(420)
    assert cycle.force_peak == 100
    assert cycle.warnings == [] and cycle.faults == [] and cycle.unknown == []
    assert cycle.time_to_contact_ms is not None and cycle.settle_ms is not None
    assert 0 < cycle.time_to_contact_ms <= cycle.settle_ms
    assert cycle.duration_ms is not None and cycle.duration_ms > cycle.settle_ms
    assert start in cycle.evidence and final in cycle.evidence
    assert start + 1 in cycle.evidence  # its answer
    assert cycle.target_mm == 0.0
    words = "catch speed=500 force=100 g" if case[0] == EG2_SERIAL else "move to 0.0 mm"
    assert cycle.command.startswith(words)


def test_closed_empty(script: Script, case: tuple[str, str]) -> None:
    at_rest(script)
    script.catch()
    script.poll(state=4, opening=500, force=0)
    final = script.poll(state=2, opening=0, force=0)
    cycle = only(run(script, case))
    assert cycle.outcome == "closed_empty"
    assert cycle.width_mm is None and cycle.time_to_contact_ms is None
    assert final in cycle.evidence and cycle.settle_ms is not None


def test_opened(script: Script, case: tuple[str, str]) -> None:
    at_rest(script, opening=420, state=6)
    script.release()
    script.poll(state=6, opening=420, force=100)  # still holding: not started yet
    script.poll(state=5, opening=700, force=0)
    final = script.poll(state=1, opening=1000, force=0)
    cycle = only(run(script, case))
    assert cycle.outcome == "opened" and final in cycle.evidence
    assert cycle.width_mm is None and cycle.target_mm == 70.0


def test_positioned(script: Script, case: tuple[str, str]) -> None:
    at_rest(script)
    script.seek(500)
    script.poll(state=4, opening=700, force=0)
    final = script.poll(state=3, opening=500, force=0)
    cycle = only(run(script, case))
    assert cycle.outcome == "positioned" and final in cycle.evidence
    assert cycle.target_mm == 35.0


def test_a_seek_that_closes_on_a_part_grips_it(script: Script, case: tuple[str, str]) -> None:
    at_rest(script)
    script.seek(200)
    script.poll(state=4, opening=600, force=0)
    script.poll(state=6, opening=550, force=100)
    cycle = only(run(script, case))
    assert cycle.outcome == "gripped" and cycle.width_mm == opening_mm(550)


def test_stopped_by_a_stop_command(script: Script, case: tuple[str, str]) -> None:
    at_rest(script)
    script.catch()
    script.poll(state=4, opening=700, force=0)
    stop = script.stop()
    script.poll(state=3, opening=690, force=0)  # after the cycle: no cycle's
    cycle = only(run(script, case))
    assert cycle.outcome == "stopped"
    assert cycle.end_seq == stop and stop in cycle.evidence
    assert cycle.settle_ms is None


def test_stopped_short_of_the_target(script: Script, case: tuple[str, str]) -> None:
    at_rest(script)
    script.seek(300)
    script.poll(state=4, opening=700, force=0)
    final = script.poll(state=3, opening=650, force=0)
    cycle = only(run(script, case))
    assert cycle.outcome == "stopped" and final in cycle.evidence


def test_a_stop_after_the_grip_keeps_the_grip(script: Script, case: tuple[str, str]) -> None:
    at_rest(script)
    script.catch()
    script.poll(state=6, opening=420, force=100)
    stop = script.stop()
    cycle = only(run(script, case))
    assert cycle.outcome == "gripped" and cycle.end_seq == stop


def test_faulted(script: Script, case: tuple[str, str]) -> None:
    at_rest(script)
    script.catch()
    script.poll(state=4, opening=700, force=0)
    fault = script.poll(state=3, opening=690, force=0, fault=0b101)
    cycle = only(run(script, case))
    assert cycle.outcome == "faulted"
    assert cycle.faults == ["stall", "over-current"]
    assert fault in cycle.evidence


def test_refused(script: Script, case: tuple[str, str]) -> None:
    if case[0] == EG2_CAN:
        pytest.skip("a CAN write is answered with its length: there is no refusal")
    at_rest(script)
    start = script.catch(answer="refused")
    cycle = only(run(script, case))
    assert cycle.outcome == "refused"
    assert cycle.evidence == [start, start + 1]


def test_refused_then_resent_and_accepted_is_one_cycle(
    script: Script, case: tuple[str, str]
) -> None:
    if case[0] == EG2_CAN:
        pytest.skip("a CAN write is answered with its length: there is no refusal")
    at_rest(script)
    first = script.catch(answer="refused")
    again = script.catch()
    script.poll(state=6, opening=420, force=100)
    cycle = only(run(script, case))
    assert (cycle.outcome, cycle.retries, cycle.start_seq) == ("gripped", 1, first)
    assert {first, again} <= set(cycle.evidence)


def test_unanswered(script: Script, case: tuple[str, str]) -> None:
    at_rest(script)
    start = script.catch(answer="none")
    cycle = only(run(script, case))
    assert cycle.outcome == "unanswered" and cycle.evidence == [start]


def test_unanswered_yet_carried_out_says_what_happened(
    script: Script, case: tuple[str, str]
) -> None:
    """The answer was lost (or the tap missed it), but the readings show the grip: the cycle
    says what happened, and warns that the command was never answered."""
    at_rest(script)
    script.catch(answer="none")
    script.poll(state=4, opening=700, force=0)
    script.poll(state=6, opening=420, force=100)
    cycle = only(run(script, case))
    assert (cycle.outcome, cycle.warnings) == ("gripped", ["unanswered"])


def test_unanswered_and_nothing_moved_is_unanswered(script: Script, case: tuple[str, str]) -> None:
    at_rest(script)
    start = script.catch(answer="none")
    for _ in range(3):
        script.poll(state=1, opening=1000, force=0)  # still open: it never got the command
    cycle = only(run(script, case))
    assert (cycle.outcome, cycle.warnings, cycle.evidence) == ("unanswered", [], [start])


def test_the_same_command_again_before_any_reading_is_a_retry(
    script: Script, case: tuple[str, str]
) -> None:
    at_rest(script)
    first = script.catch()
    script.catch()
    script.poll(state=6, opening=420, force=100)
    cycle = only(run(script, case))
    assert (cycle.outcome, cycle.retries, cycle.start_seq) == ("gripped", 1, first)


@pytest.mark.parametrize("wait_s", [0.03, 0.6], ids=["retransmission", "after-unanswered"])
def test_resent_and_answered_is_one_cycle(
    script: Script, case: tuple[str, str], wait_s: float
) -> None:
    """Sent again before pairing gave up on the first (flagged ``retransmission``), or after
    it did (the first flagged ``unanswered``): a retry either way."""
    at_rest(script)
    first = script.catch(answer="none")
    script.wait(wait_s)
    again = script.catch()
    script.poll(state=2, opening=0, force=0)
    cycle = only(run(script, case))
    assert (cycle.outcome, cycle.retries, cycle.start_seq) == ("closed_empty", 1, first)
    assert {first, again} <= set(cycle.evidence)


def test_the_same_command_once_accepted_starts_a_new_cycle(
    script: Script, case: tuple[str, str]
) -> None:
    at_rest(script)
    script.catch()
    script.poll(state=6, opening=420, force=100)
    again = script.catch()
    first, second = run(script, case)
    assert (first.outcome, first.retries, second.start_seq) == ("gripped", 0, again)


def test_unfinished_at_the_end_of_the_capture(script: Script, case: tuple[str, str]) -> None:
    at_rest(script)
    script.catch()
    last = script.poll(state=4, opening=700, force=0)
    cycle = only(run(script, case))
    assert cycle.outcome == "unfinished" and last in cycle.evidence
    assert cycle.end_seq == script.seq - 1  # the gripper's last frame


def test_unfinished_when_the_next_command_comes_first(
    script: Script, case: tuple[str, str]
) -> None:
    at_rest(script)
    script.catch()
    script.poll(state=4, opening=700, force=0)
    release = script.release()
    first, second = run(script, case)
    assert first.outcome == "unfinished" and first.end_seq == release
    assert second.start_seq == release


@pytest.mark.parametrize("opening", [None, 700])
def test_the_capture_ends_before_a_reading_of_a_host_that_reads_state(
    script: Script, case: tuple[str, str], opening: int | None
) -> None:
    at_rest(script)
    script.catch()
    if opening is not None:
        script.poll(opening=opening)  # the state's poll would have come next
    assert only(run(script, case)).outcome == "unfinished"


# -- what a cycle could not know ----------------------------------------------------------------


def test_no_state_read_is_unknown_and_says_so(script: Script, case: tuple[str, str]) -> None:
    script.catch()
    script.poll(opening=700)
    script.poll(opening=600)
    script.release()
    first, second = run(script, case)
    assert first.outcome == "unknown"
    assert first.unknown == ["state", "force"]  # the opening was read
    assert first.width_mm is None and first.settle_ms is None
    assert second.outcome == "unknown"
    assert second.unknown == ["state", "opening", "force"]  # nothing read at all


def test_the_opening_alone_proves_a_position(script: Script, case: tuple[str, str]) -> None:
    script.poll(opening=1000)
    script.seek(500)
    script.poll(opening=800)
    final = script.poll(opening=505)  # within 0.7 mm
    cycle = only(run(script, case))
    assert cycle.outcome == "positioned" and final in cycle.evidence
    assert cycle.unknown == ["state", "force"] and cycle.settle_ms is not None


def test_the_opening_alone_proves_a_release(script: Script, case: tuple[str, str]) -> None:
    script.poll(opening=420)
    script.release()
    script.poll(opening=1000)
    assert only(run(script, case)).outcome == "opened"


def test_the_opening_alone_never_proves_a_grip(script: Script, case: tuple[str, str]) -> None:
    script.poll(opening=1000)
    script.catch()
    script.poll(opening=420)
    script.poll(opening=420)
    cycle = only(run(script, case))
    assert cycle.outcome == "unknown" and "state" in cycle.unknown


def test_a_stopped_move_without_its_opening_is_unknown(
    script: Script, case: tuple[str, str]
) -> None:
    if case[0] == EG2_SERIAL:
        pytest.skip("the serial run state always carries the opening")
    script.seek(500)
    script.poll(state=3)
    cycle = only(run(script, case))
    assert cycle.outcome == "unknown" and "opening" in cycle.unknown


def test_no_force_read_leaves_force_peak_null(script: Script, case: tuple[str, str]) -> None:
    script.poll(state=1, opening=1000)
    script.catch()
    script.poll(state=6, opening=420)
    cycle = only(run(script, case))
    assert cycle.outcome == "gripped" and cycle.force_peak is None
    assert cycle.unknown == ["force"] and cycle.width_mm == opening_mm(420)


# -- warnings, broadcasts, batches ------------------------------------------------------------


def test_slip_when_the_opening_keeps_closing(script: Script, case: tuple[str, str]) -> None:
    at_rest(script)
    script.catch()
    script.poll(state=6, opening=420, force=100)
    before = script.seq
    slip = script.poll(state=6, opening=380, force=100)
    cycle = only(run(script, case))
    assert cycle.outcome == "gripped" and cycle.warnings == ["slip"]
    assert any(before <= seq <= slip for seq in cycle.evidence)


def test_slip_when_the_state_leaves_6(script: Script, case: tuple[str, str]) -> None:
    at_rest(script)
    script.catch()
    script.poll(state=6, opening=420, force=100)
    script.poll(state=6, opening=420, force=100)
    slip = script.poll(state=3, opening=420, force=0)
    cycle = only(run(script, case))
    assert cycle.outcome == "gripped" and cycle.warnings == ["slip"]
    assert slip in cycle.evidence


def test_a_steady_grip_has_no_slip(script: Script, case: tuple[str, str]) -> None:
    at_rest(script)
    script.catch()
    for _ in range(5):
        script.poll(state=6, opening=420, force=100)
    assert only(run(script, case)).warnings == []


def test_a_broadcast_stop_stops_every_gripper(script: Script, case: tuple[str, str]) -> None:
    for device in (1, 2):
        at_rest_of(script, device)
    for device in (1, 2):
        script.catch(device=device)
    for device in (1, 2):
        script.poll(device=device, state=4, opening=700, force=0)
    stop = script.stop(device=BROADCAST[case[0]], answer="none")
    cycles = run(script, case)
    assert [(c.device, c.outcome, c.end_seq) for c in cycles] == [
        (1, "stopped", stop),
        (2, "stopped", stop),
    ]


def test_a_broadcast_catch_starts_a_cycle_on_every_gripper(
    script: Script, case: tuple[str, str]
) -> None:
    for device in (1, 2):
        at_rest_of(script, device)
    start = script.catch(device=BROADCAST[case[0]], answer="none")
    script.poll(device=1, state=6, opening=420, force=100)
    script.poll(device=2, state=2, opening=0, force=0)
    cycles = sorted(run(script, case), key=lambda c: c.device)
    assert [(c.device, c.start_seq, c.outcome) for c in cycles] == [
        (1, start, "gripped"),
        (2, start, "closed_empty"),
    ]


def at_rest_of(script: Script, device: int) -> None:
    script.poll(device=device, state=1, opening=1000, force=0)


Scenario = Callable[[Script], None]


def _pick_and_place(s: Script) -> None:
    for device in (1, 2):
        at_rest_of(s, device)
    for _ in range(3):
        for device in (1, 2):
            s.catch(device=device)
        for opening, state in ((700, 4), (420, 6), (420, 6)):
            for device in (1, 2):
                s.poll(device=device, state=state, opening=opening, force=100 * (state == 6))
        for device in (1, 2):
            s.release(device=device)
        for opening, state in ((700, 5), (1000, 1)):
            for device in (1, 2):
                s.poll(device=device, state=state, opening=opening, force=0)


@pytest.mark.parametrize("size", [1, 2, 3, 50, 10_000])
def test_batches_of_any_size_give_the_same_cycles(size: int, case: tuple[str, str]) -> None:
    """A command and its readings may come in different batches (a batch's commands wait for
    its samples, or the next batch)."""
    s = Script(case[0])
    _pick_and_place(s)
    expected = s.cycles("python", 7)
    assert [c.outcome for c in expected] == ["gripped", "gripped", "opened", "opened"] * 3
    assert s.cycles(case[1], size) == expected
