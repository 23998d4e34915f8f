"""What a cycle saw, and the rules that decide its outcome (docs/contracts.md, "Grip cycles").

A ``Watch`` is handed the cycle's command, its copies and answers, its stop, and every reading
of the gripper (state, opening, force, fault) until the cycle ends; ``Watch.cycle`` then decides,
in this order:

1. ``faulted``: a reading showed fault bits;
2. ``refused``: every copy of the command was answered with a refusal (serial ``55``, a Modbus
   exception); ``unanswered``: none was answered and no reading showed the gripper carry it out
   (where one did, the rules below decide, with the warning ``unanswered``); ``unfinished``: the
   capture was stopped before an answer could come;
3. ``stopped``: a stop command came before a reading showed the motion finished;
4. the first state the gripper reported standing still that fits the command: 6 ``gripped``,
   2 ``closed_empty``, 1 ``opened``, 3 ``positioned`` at the target of a move (within
   ``AT_TARGET`` of it), else ``stopped`` short of it. A standing state that cannot be the end
   of this command (fully open after a catch, closed or gripping after a release, still the
   "stopped" it was in before it moved) is the gripper not having started yet, and is passed;
5. where the host reads no state in the cycle: the opening alone, where it proves the outcome
   (a move at its target: ``positioned``; an opening at the open limit after a release or an
   open move: ``opened``);
6. ``unfinished``: the readings showed the gripper still moving, or the capture ended before a
   reading of the state came from a host that had been reading it; else ``unknown``, and
   ``unknown`` names what the host never read in the cycle.

Contact is the first reading of state 6, or of a measured force at half the force setting or
more, while closing; the width is the opening read with it (or the first read after it: the
jaws stand on the part). ``slip``: an opening more than ``SLIP_MARGIN`` below that width
afterwards, or the state leaving 6 while the cycle holds.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Final

from decoders.registers import fault_text, opening_mm

from .commands import ANSWERED, CATCH, NOBODY, RELEASE, STOPPED_FIRST, Command
from .model import (
    CLOSED_EMPTY,
    FAULTED,
    FORCE,
    GRIPPED,
    NOT_ANSWERED,
    OPENED,
    OPENING,
    POSITIONED,
    REFUSED,
    SLIP,
    STATE,
    STOPPED,
    TIME,
    UNANSWERED,
    UNFINISHED,
    UNKNOWN,
    Cycle,
)

AT_TARGET: Final = 10  # of 1000 (0.7 mm): an opening this close to the target has reached it
SLIP_MARGIN: Final = 10  # of 1000: an opening this far below the width at contact is a slip
CONTACT_FORCE: Final = 0.5  # of the force setting: a measured force this high is contact

# run states (docs/protocol.md, section 1.3): standing still; 4 and 5 are moving
FULLY_OPEN: Final = 1
FULLY_CLOSED: Final = 2
STOPPED_IDLE: Final = 3
GRIPPING: Final = 6
STANDING: Final = frozenset({FULLY_OPEN, FULLY_CLOSED, STOPPED_IDLE, GRIPPING})

# what a command aims at
CLOSE: Final = "close"
OPEN: Final = "open"
GO_TO: Final = "go to"


@dataclass(slots=True)
class Context:
    """What is known of a gripper when a command comes: its last readings and settings."""

    state: int | None = None
    opening: int | None = None
    force_setting: int | None = None
    max_opening: int = 1000
    min_opening: int = 0
    state_read: bool = False  # the host has read this gripper's state


@dataclass(slots=True)
class Mark:
    """A reading that decided something: its seq and time."""

    seq: int
    t: float | None


@dataclass(slots=True)
class Watch:
    """Everything one cycle saw, in the order it came."""

    command: Command
    device: int
    aim: str
    target: int  # the opening aimed at, 0-1000
    before: Context
    reach: tuple[float, float] = (1.0, 0.0)  # openings that reach the target (none: lo > hi)
    copies: list[int] = field(default_factory=list)
    accepted: int = 0  # copies answered with no refusal
    answered: int = 0  # copies answered at all
    cut_off: bool = False
    refusals: list[int] = field(default_factory=list)
    answers: list[int] = field(default_factory=list)
    seen: set[str] = field(default_factory=set)  # what the cycle's readings carried
    moved: bool = False
    opening: int | None = None  # the last opening read in the cycle
    contact: Mark | None = None
    width: int | None = None
    width_pending: bool = False
    final: Mark | None = None
    final_state: int | None = None
    final_opening: int | None = None
    final_pending: bool = False
    at_target: Mark | None = None
    last_state: int | None = None  # the seq of the first reading of the last state seen
    last_state_value: int | None = None  # that state
    faults: int = 0
    fault_mark: Mark | None = None
    force_peak: int | None = None
    slip: Mark | None = None
    stop: Mark | None = None
    end: Mark | None = None  # the last frame the cycle saw (the segmenter says)

    # -- what comes in -----------------------------------------------------------------------

    def copy(self, cmd: Command) -> None:
        """A copy of the command (the first one too): its fate as pairing left it."""
        self.copies.append(cmd.seq)
        if cmd.fate in (ANSWERED, NOBODY):
            self.answered += 1
            self.accepted += 1
        elif cmd.fate == STOPPED_FIRST:
            self.cut_off = True

    def answer(self, seq: int, t: float | None, refused: bool, garbled: bool) -> None:
        """The response to a copy (counted answered and accepted when the copy came)."""
        self.answers.append(seq)
        if refused or garbled:
            self.accepted -= 1
        if refused:
            self.refusals.append(seq)

    def accepts_retry(self, cmd: Command) -> bool:
        """Whether ``cmd`` is this command sent again (not a new cycle): the same bytes, as a
        retransmission, after no copy was accepted yet, or before any reading came."""
        if cmd.same != self.command.same:
            return False
        return cmd.retransmission or self.accepted <= 0 or not self.seen

    def stopped(self, seq: int, t: float | None) -> Mark:
        """A stop command: the cycle ends here."""
        self.stop = Mark(seq, t)
        return self.stop

    def reading(
        self,
        seq: int,
        t: float | None,
        state: int | None,
        opening: int | None,
        force: int | None,
        fault: int | None,
        force_setting: int | None,
    ) -> None:
        """One reading of the gripper (None: not in this frame). Called for every reading
        of a cycle still undecided: its common path stays in this one call."""
        if fault:
            self._fault(seq, t, fault)
        if opening is not None:
            self._opening(seq, t, opening)
        if force is not None:
            self.seen.add(FORCE)
            peak = self.force_peak
            if peak is None or force > peak:
                self.force_peak = force
            if self.contact is None and force_setting and force >= CONTACT_FORCE * force_setting:
                self._touch(seq, t, opening)
        if state is not None:
            self._state(seq, t, state, opening)

    # -- the readings ------------------------------------------------------------------------

    def _fault(self, seq: int, t: float | None, bits: int) -> None:
        self.faults |= bits
        if self.fault_mark is None:
            self.fault_mark = Mark(seq, t)

    def _opening(self, seq: int, t: float | None, opening: int) -> None:
        self.seen.add(OPENING)
        self.opening = opening
        before = self.before.opening
        if before is not None and abs(opening - before) > AT_TARGET:
            self.moved = True
        if self.width_pending:
            self.width, self.width_pending = opening, False
        elif self.width is not None and self.slip is None and opening < self.width - SLIP_MARGIN:
            self.slip = Mark(seq, t)
        if self.final_pending:
            self.final_opening, self.final_pending = opening, False
        if self.at_target is None and self.reach[0] <= opening <= self.reach[1]:
            self.at_target = Mark(seq, t)

    def _state(self, seq: int, t: float | None, state: int, opening: int | None) -> None:
        self.seen.add(STATE)
        if self.last_state is None or state != self.last_state_value:
            self.last_state, self.last_state_value = seq, state
        if state not in STANDING:
            self.moved = True
        if self.final is None:
            if state in STANDING and self._fits(state):
                self.final, self.final_state = Mark(seq, t), state
                self.final_opening = opening if opening is not None else self.opening
                self.final_pending = opening is None
        elif self.final_state == GRIPPING and state != GRIPPING and self.slip is None:
            self.slip = Mark(seq, t)  # the state left 6 while holding
        if state == GRIPPING and self.contact is None:
            self._touch(seq, t, opening)

    def _touch(self, seq: int, t: float | None, opening: int | None) -> None:
        """A sign of contact: counted while the command may close the jaws."""
        if self._may_close():
            self._contact(seq, t, opening)

    def _contact(self, seq: int, t: float | None, opening: int | None) -> None:
        """The jaws met the part: the width is the opening read with it, or the first read
        after it (the last one before it until then)."""
        self.contact = Mark(seq, t)
        self.width = opening if opening is not None else self.opening
        self.width_pending = opening is None

    def _fits(self, state: int) -> bool:
        """Whether a standing state can be the end of this command (else: not started yet)."""
        closing, opening = self._direction()
        if closing and state == FULLY_OPEN:
            return False
        if opening and state in (FULLY_CLOSED, GRIPPING):
            return False
        return not (state == STOPPED_IDLE == self.before.state and not self.moved)

    def _may_close(self) -> bool:
        """Whether this command may close the jaws (contact means something)."""
        return not self._direction()[1]

    def _direction(self) -> tuple[bool, bool]:
        """(closing, opening): which way the command moves the jaws, where that is known."""
        if self.aim == CLOSE:
            return True, False
        if self.aim == OPEN:
            return False, True
        now = self.before.opening
        if now is None:
            return False, False
        return self.target < now - AT_TARGET, self.target > now + AT_TARGET

    # -- the decision ------------------------------------------------------------------------

    def cycle(self, ended_at: Mark | None) -> Cycle:
        """The cycle as it ended: at the frame ``ended_at`` (the next motion command to the
        gripper), or at the end of the capture (None: at the last frame the cycle saw)."""
        outcome, evidence = self._outcome(ended_by_capture=ended_at is None)
        cmd = self.command
        end = ended_at or self.end or Mark(cmd.seq, cmd.t)
        contact, settled = self.contact, self._settled(outcome)
        return build_cycle(
            cmd,
            self.device,
            self.target,
            outcome,
            end.seq,
            end.t,
            self.width,
            self.force_peak,
            None if contact is None else contact.t,
            None if settled is None else settled.t,
            len(self.copies) - 1,
            self.faults,
            self._warnings(outcome),
            self._unknown(),
            sorted(set(evidence)),
        )

    def _outcome(self, ended_by_capture: bool) -> tuple[str, list[int]]:
        asked = [*self.copies, *self.answers]
        if self.faults and self.fault_mark is not None:
            return FAULTED, [*asked, self.fault_mark.seq]
        if self.accepted <= 0 and self.refusals:
            return REFUSED, asked
        if self.answered == 0 and (self.cut_off or not self._carried_out()):
            return (UNFINISHED if self.cut_off else UNANSWERED), asked
        if self.stop is not None and self.final is None:
            return STOPPED, [*asked, self.stop.seq]
        if self.final is not None:
            return self._standing(), [*asked, *self._marks(self.final, self.contact, self.slip)]
        if STATE not in self.seen and self.at_target is not None:
            return (OPENED if self.aim == OPEN else POSITIONED), [*asked, self.at_target.seq]
        if STATE in self.seen and self.last_state is not None:
            return UNFINISHED, [*asked, self.last_state]
        if ended_by_capture and self.before.state_read:
            return UNFINISHED, asked  # the capture ended before the next reading of the state
        return UNKNOWN, asked

    def _carried_out(self) -> bool:
        """Whether a reading showed the gripper carry the command out (an answer lost on the
        way, or missed by the tap, does not make a grip that happened unanswered): moving, or
        standing at an end that fits it."""
        return self.moved or self.final is not None

    def _warnings(self, outcome: str) -> list[str]:
        found = [SLIP] if self.slip is not None and self.contact is not None else []
        if self.answered == 0 and outcome not in (UNANSWERED, UNFINISHED):
            found.append(NOT_ANSWERED)
        return found

    def _standing(self) -> str:
        state = self.final_state
        if state == GRIPPING:
            return GRIPPED
        if state == FULLY_CLOSED:
            return CLOSED_EMPTY
        if state == FULLY_OPEN:
            return OPENED
        if self.aim != GO_TO:
            return STOPPED
        if self.final_opening is None:
            return UNKNOWN  # stopped, but where: the host reads no opening
        return POSITIONED if abs(self.final_opening - self.target) <= AT_TARGET else STOPPED

    def _settled(self, outcome: str) -> Mark | None:
        if outcome in (GRIPPED, CLOSED_EMPTY, OPENED, POSITIONED):
            return self.final or self.at_target
        return self.final if outcome == STOPPED and self.stop is None else None

    def _unknown(self) -> list[str]:
        missing = [q for q in (STATE, OPENING, FORCE) if q not in self.seen]
        return missing + ([TIME] if self.command.t is None else [])

    @staticmethod
    def _marks(*marks: Mark | None) -> list[int]:
        return [m.seq for m in marks if m is not None]


def build_cycle(
    cmd: Command,
    device: int,
    target: int,
    outcome: str,
    end_seq: int,
    end_t: float | None,
    width: int | None,
    force_peak: int | None,
    contact_t: float | None,
    settle_t: float | None,
    retries: int,
    faults: int,
    warnings: list[str],
    unknown: list[str],
    evidence: list[int],
) -> Cycle:
    """A decided cycle as the outputs write it: openings in mm, times from the command in ms
    (``_native.CycleSegmenter`` makes its cycles the same way)."""
    return Cycle(
        bus=cmd.bus,
        device=device,
        start_t=cmd.t,
        end_t=end_t,
        start_seq=cmd.seq,
        end_seq=end_seq,
        command=cmd.words,
        target_mm=opening_mm(target),
        outcome=outcome,
        width_mm=None if width is None else opening_mm(width),
        force_peak=force_peak,
        time_to_contact_ms=_ms(cmd.t, contact_t),
        settle_ms=_ms(cmd.t, settle_t),
        retries=retries,
        faults=fault_text(faults),
        warnings=warnings,
        unknown=unknown,
        evidence=evidence,
    )


def _ms(start: float | None, t: float | None) -> float | None:
    if t is None or start is None:
        return None
    return round((t - start) * 1000.0, 3)


def aim_of(cmd: Command, ctx: Context) -> tuple[str, int]:
    """What a command aims at (close, open, or go to an opening) and the opening it aims at:
    a catch closes to the lower limit, a release opens to the upper one, a move to a limit
    closes or opens."""
    if cmd.kind == CATCH:
        return CLOSE, ctx.min_opening
    if cmd.kind == RELEASE:
        return OPEN, ctx.max_opening
    target = cmd.target if cmd.target is not None else ctx.min_opening
    if target <= ctx.min_opening:
        return CLOSE, target
    if target >= ctx.max_opening:
        return OPEN, target
    return GO_TO, target


def watch(cmd: Command, device: int, ctx: Context) -> Watch:
    """A new cycle's watch, for ``device`` (a broadcast's grippers each get one)."""
    aim, target = aim_of(cmd, ctx)
    before = Context(
        ctx.state, ctx.opening, ctx.force_setting, ctx.max_opening, ctx.min_opening, ctx.state_read
    )
    w = Watch(cmd, device, aim, target, before, _reach(aim, target, ctx))
    w.copy(cmd)
    return w


def _reach(aim: str, target: int, ctx: Context) -> tuple[float, float]:
    """The openings that show a command reached its end where no state is read: the upper
    limit after an open, the target of a move (a close: none, the opening never proves it)."""
    if aim == OPEN:
        return ctx.max_opening - AT_TARGET, float("inf")
    if aim == GO_TO:
        return target - AT_TARGET, target + AT_TARGET
    return 1.0, 0.0
