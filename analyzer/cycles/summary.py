"""Cycles counted per gripper, for ``eg2scope stats``: outcomes, and the percentiles of the
cycle time and the settle time, in constant memory (``stats.LatencyHistogram``)."""

from __future__ import annotations

from collections import Counter
from typing import Any

from ..stats import LatencyHistogram
from .model import OUTCOMES, Cycle, CycleCounts, counts_of
from .outputs import CycleOutput

_COUNT_AT = 4096  # cycles


class GripperCycles:
    """One gripper's cycles: how many, their outcomes, their times."""

    def __init__(self) -> None:
        self.cycles = 0
        self.outcomes: Counter[str] = Counter()
        self.duration = LatencyHistogram()  # command to the cycle's last frame
        self.settle = LatencyHistogram()  # command to standing still

    def add(self, outcomes: list[str], durations: list[float], settles: list[float]) -> None:
        """Some of this gripper's cycles: their outcomes and times (those known)."""
        self.cycles += len(outcomes)
        self.outcomes.update(outcomes)
        self.duration.add_many(durations)
        self.settle.add_many(settles)

    def as_dict(self) -> dict[str, Any]:
        return {
            "cycles": self.cycles,
            "outcomes": {o: self.outcomes[o] for o in OUTCOMES if self.outcomes[o]},
            "duration": self.duration.summary(),
            "settle": self.settle.summary(),
        }


class CycleSummary(CycleOutput):
    """The cycles of every gripper counted (``stats --format json``'s ``cycles``)."""

    label = "cycle statistics"
    counts_only = True

    def __init__(self) -> None:
        self.grippers: dict[tuple[str, int], GripperCycles] = {}
        # what is not counted yet, a few thousand cycles at most: counted in bulk, which
        # costs a fraction of counting a batch's few cycles of each gripper as they come
        self._pending: dict[tuple[str, int], tuple[list[str], list[float], list[float]]] = {}
        self._pending_cycles = 0

    def write(self, cycles: list[Cycle]) -> None:
        self.write_counts(counts_of(cycles))

    def write_counts(self, counts: list[CycleCounts]) -> None:
        pending = self._pending
        for bus, device, outcomes, durations, settles in counts:
            found = pending.get((bus, device))
            if found is None:
                pending[(bus, device)] = (outcomes, durations, settles)
            else:
                found[0].extend(outcomes)
                found[1].extend(durations)
                found[2].extend(settles)
            self._pending_cycles += len(outcomes)
        if self._pending_cycles >= _COUNT_AT:
            self._count()

    def _count(self) -> None:
        for key, (outcomes, durations, settles) in self._pending.items():
            gripper = self.grippers.get(key)
            if gripper is None:
                gripper = self.grippers[key] = GripperCycles()
            gripper.add(outcomes, durations, settles)
        self._pending, self._pending_cycles = {}, 0

    def as_list(self) -> list[dict[str, Any]]:
        """One object per gripper, by bus and device."""
        self._count()
        return [
            {"bus": bus, "device": device, **g.as_dict()}
            for (bus, device), g in sorted(self.grippers.items())
        ]
