"""Grip cycles in Rerun: the ``CycleOutput`` the plot's ``CyclesListener`` writes to (the cycle
rules are ``analyzer/cycles/``'s alone). Per gripper, under ``/<bus>/<device>/``:

- ``cycles``: a ``StateChange`` lane, one span per cycle from its command (``start_t``,
  ``start_seq``) to the frame it ended at, named and coloured by its outcome
  (``analyzer/cycles/looks.py``). A span ends with an empty state, a gap in the lane, where no
  cycle begins at the same frame (after a stop, at the end of the capture); that is known once
  the gripper's next cycle ends, or at the end. (A cycle ended at its own command, cut off
  there by the end of the capture, gets no gap: it would hide the cycle.) Two rows of one
  entity never share a frame, so what the lane shows never rests on the order of equal times;
- ``cycles/log``: a ``TextLog`` line at the command (the command, the outcome and every figure
  of the cycle) and one at its end, at the level of the outcome's severity.

The rows go on both timelines, ``capture_time`` and ``frame``, as the gripper's others (a capture
without times: ``frame`` only). Cycles are written as they end (a live viewer shows each one
then); the rows wait in ``Columns`` for the listener's next flush.
"""

from __future__ import annotations

from typing import Final

from ..cycles.looks import BAD, GOOD, LOOKS, NOTICE, OPEN, shown_as
from ..cycles.model import Cycle
from ..cycles.outputs import CycleOutput, details
from . import entities as ent
from .columns import LANE, TEXT, Columns

# a TextLog level per severity
LEVELS: Final = {GOOD: "INFO", NOTICE: "WARN", BAD: "ERROR", OPEN: "DEBUG"}
GAP: Final = ""  # the empty state: Rerun's lane shows no state until the next


class GripperCycles:
    """One gripper's cycle lane and log; ``end``: the (t, seq) its last cycle ended at, whose
    gap waits for the next cycle (which may begin there); None: no gap to come."""

    __slots__ = ("end", "lane", "log")

    def __init__(self, bus: str, device: int) -> None:
        base = ent.gripper_path(bus, device)
        self.lane = Columns(f"{base}/{ent.CYCLES}", LANE, ent.cycles_configuration())
        self.log = Columns(f"{base}/{ent.CYCLE_LOG}", TEXT)
        self.end: tuple[float | None, int] | None = None

    def add(self, c: Cycle) -> None:
        if self.end is not None and self.end[1] != c.start_seq:
            self.lane.add(*self.end, GAP)
        shown = shown_as(c)
        label, level = LOOKS[shown].label, LEVELS[LOOKS[shown].severity]
        self.lane.add(c.start_t, c.start_seq, shown)
        self.log.add(c.start_t, c.start_seq, start_text(c, label), level)
        self.log.add(c.end_t, c.end_seq, end_text(c, label), level)
        self.end = (c.end_t, c.end_seq) if c.end_seq != c.start_seq else None

    def close(self) -> None:
        if self.end is not None:
            self.lane.add(*self.end, GAP)
            self.end = None


class RerunCycles(CycleOutput):
    """The cycles of a session as lanes and logs per gripper (``grippers``: by (bus, device),
    in the order their first cycle ended)."""

    label = "Rerun cycles"

    def __init__(self) -> None:
        self.grippers: dict[tuple[str, int], GripperCycles] = {}

    def write(self, cycles: list[Cycle]) -> None:
        for c in cycles:
            key = (c.bus, c.device)
            g = self.grippers.get(key)
            if g is None:
                g = self.grippers[key] = GripperCycles(c.bus, c.device)
            g.add(c)

    def close(self) -> None:
        for g in self.grippers.values():
            g.close()

    def columns(self) -> list[Columns]:
        return [c for g in self.grippers.values() for c in (g.lane, g.log)]


def start_text(c: Cycle, label: str) -> str:
    """The line at a cycle's command: what was asked, how it ended (``label``), what was
    measured."""
    return f"{c.command}: {label} [{', '.join(details(c))}]"


def end_text(c: Cycle, label: str) -> str:
    """The line at the frame a cycle ended at."""
    took = "" if c.duration_ms is None else f" after {c.duration_ms:.1f} ms"
    return f"end of cycle: {label}{took} ({c.command})"
