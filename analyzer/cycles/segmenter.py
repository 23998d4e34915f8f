"""Each gripper's timeline cut into cycles: commands, answers and readings in, cycles out.

A cycle starts at a motion command to a gripper (a broadcast one starts a cycle on every gripper
of its bus heard so far) and ends at the next motion command to it, at a stop (which the cycle
keeps), or at the end of the capture. A command sent again (a retransmission, a copy after
the first went unanswered or was refused, or one before any reading came) is a retry of the
cycle, not a new one. Readings come
from the Tracker's state samples, so every protocol's frames mean here what they mean in the
device state (``analyzer/session/tracker.py``).

Events must come in stream order per bus (the session's order): ``Segmenter.feed`` takes a
batch's events and puts each gripper's in order by ``seq`` (a command before the sample of its
own record). A reading that repeats the last one of its kind (a poll of a gripper standing
still) tells a cycle nothing once it is decided, and is passed over: most of a capture's
readings are such.
"""

from __future__ import annotations

from operator import attrgetter, itemgetter
from typing import Any, Final

from .commands import STOP, Answer, Command
from .model import Cycle
from .rules import Context, Mark, Watch, watch

# an event: (seq, kind, t, what). A reading's ``what`` is the values of ``listener.FIELDS``
# (state, opening, force, fault, force_setting, max_opening, min_opening; None where the frame
# did not carry one), followed by the holder of the last values of its kind (``holder``); a
# command's or an answer's is the Command or Answer
READING: Final = 1
COMMAND: Final = 0
Event = tuple[Any, ...]
_SEQ: Final = itemgetter(0)
# a broadcast's cycles begin and may end together: then by gripper, whatever the batches
_START: Final = attrgetter("start_seq", "bus", "device")
_ENDED: Final = attrgetter("end_seq", "start_seq", "bus", "device")


class Gripper:
    """One gripper: what is known of it, and its cycle in progress."""

    __slots__ = ("bus", "context", "device", "heard", "holders", "watch")

    def __init__(self, bus: str, device: int) -> None:
        self.bus = bus
        self.device = device
        self.context = Context()
        self.watch: Watch | None = None
        self.heard = False  # it answered with a reading: a gripper, not a broadcast address
        # the last values of each kind of reading (which fields it carries): [values]
        self.holders: dict[tuple[str, ...], list[Any]] = {}


class Segmenter:
    """Cuts every gripper's events into cycles; ``cycles`` holds those that ended, until taken."""

    def __init__(self) -> None:
        self.grippers: dict[tuple[str, int], Gripper] = {}
        self.cycles: list[Cycle] = []

    def holder(self, key: tuple[str, int], names: tuple[str, ...]) -> list[Any]:
        """Where a gripper's readings of ``names`` keep their last values."""
        holders = self._gripper(key).holders
        found = holders.get(names)
        if found is None:
            found = holders[names] = [None]
        return found

    def feed(
        self, readings: dict[tuple[str, int], list[Event]], commands: list[tuple[str, int, Event]]
    ) -> None:
        """One batch: ``readings`` per gripper (each list in seq order, or runs of it), and the
        ``(bus, device, event)`` of its commands and answers. Each gripper's events are run in
        seq order, a command before the sample of its own record; a broadcast command goes to
        every gripper of its bus. ``readings`` is the caller's no more."""
        per: dict[tuple[str, int], list[Event]] = {}
        for bus, device, event in commands:
            if type(event[3]) is Command and event[3].broadcast:
                heard = {key for key, g in self.grippers.items() if g.bus == bus and g.heard}
                keys = sorted(heard | {key for key in readings if key[0] == bus})
            else:
                keys = [(bus, device)]
            for key in keys:
                per.setdefault(key, []).append(event)
        for key, events in per.items():
            events += readings.pop(key, ())  # commands first: a stable sort keeps them first
            events.sort(key=_SEQ)
            self._run(key, events)
        for key, events in readings.items():
            events.sort(key=_SEQ)
            self._run(key, events)

    def take(self) -> list[Cycle]:
        """The cycles that ended since the last call, in the order they ended (the frames
        that ended them; then began; then by gripper): the same whatever the batches."""
        done, self.cycles = self.cycles, []
        return sorted(done, key=_ENDED) if len(done) > 1 else done

    def finish(self) -> list[Cycle]:
        """The end of the capture: every cycle in progress ends here (in the order they
        began, then by gripper)."""
        for gripper in self.grippers.values():
            self._end(gripper, None)
        done, self.cycles = self.cycles, []
        return sorted(done, key=_START)

    # -- one gripper's events -----------------------------------------------------------------

    def _gripper(self, key: tuple[str, int]) -> Gripper:
        gripper = self.grippers.get(key)
        if gripper is None:
            gripper = self.grippers[key] = Gripper(*key)
        return gripper

    def _run(self, key: tuple[str, int], events: list[Event]) -> None:
        gripper = self._gripper(key)
        ctx = gripper.context
        for event in events:
            if event[1] != READING:
                if type(event[3]) is Command:
                    self._command(gripper, event[3])
                else:
                    self._answer(gripper, event[3])
                continue
            values, holder = event[3], event[4]
            w = gripper.watch
            if values == holder[0] and (w is None or w.final is not None):
                continue  # the same again: nothing new for a cycle already decided
            holder[0] = values
            state, opening, force, fault, force_setting, max_opening, min_opening = values
            if force_setting is not None or max_opening is not None or min_opening is not None:
                _settings(ctx, force_setting, max_opening, min_opening)
            if state is None and opening is None and force is None and fault is None:
                continue  # a setting: no reading
            gripper.heard = True
            if w is not None:
                w.reading(event[0], event[2], state, opening, force, fault, ctx.force_setting)
            if state is not None:
                ctx.state, ctx.state_read = state, True
            if opening is not None:
                ctx.opening = opening
        w = gripper.watch
        if w is not None and events:
            w.end = Mark(events[-1][0], events[-1][2])

    def _command(self, gripper: Gripper, cmd: Command) -> None:
        """A command to this gripper, or a broadcast one (to a gripper heard so far)."""
        if not cmd.broadcast or gripper.heard:
            self._start(gripper, cmd)

    def _start(self, gripper: Gripper, cmd: Command) -> None:
        w = gripper.watch
        if cmd.kind == STOP:
            if w is not None:
                self._end(gripper, w.stopped(cmd.seq, cmd.t))
            return
        if w is not None and w.accepts_retry(cmd):
            w.copy(cmd)
            return
        self._end(gripper, Mark(cmd.seq, cmd.t))
        gripper.watch = watch(cmd, gripper.device, gripper.context)
        for holder in gripper.holders.values():
            holder[0] = None  # a new cycle reads everything again

    def _answer(self, gripper: Gripper, answer: Answer) -> None:
        w = gripper.watch
        if w is not None and answer.request in w.copies:
            w.answer(answer.seq, answer.t, answer.refused, answer.garbled)

    def _end(self, gripper: Gripper, ended_at: Mark | None) -> None:
        """The gripper's cycle ends at the frame ``ended_at`` (None: the capture ended)."""
        w = gripper.watch
        if w is not None:
            self.cycles.append(w.cycle(ended_at))
            gripper.watch = None


def _settings(
    ctx: Context, force_setting: int | None, max_opening: int | None, min_opening: int | None
) -> None:
    """A gripper's settings, as a frame set or read them."""
    if force_setting is not None:
        ctx.force_setting = force_setting
    if max_opening is not None:
        ctx.max_opening = max_opening
    if min_opening is not None:
        ctx.min_opening = min_opening
