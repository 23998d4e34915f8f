"""Cycles counted per gripper, for ``eg2scope stats``: outcomes, and the percentiles of the
cycle time and the settle time, in constant memory (``stats.LatencyHistogram``)."""

from __future__ import annotations

from collections import Counter
from typing import Any

from ..stats import LatencyHistogram
from .model import OUTCOMES, Cycle
from .outputs import CycleOutput


class GripperCycles:
    """One gripper's cycles: how many, their outcomes, their times."""

    def __init__(self) -> None:
        self.cycles = 0
        self.outcomes: Counter[str] = Counter()
        self.duration = LatencyHistogram()  # command to the cycle's last frame
        self.settle = LatencyHistogram()  # command to standing still

    def add(self, cycle: Cycle) -> None:
        self.cycles += 1
        self.outcomes[cycle.outcome] += 1
        if cycle.duration_ms is not None:
            self.duration.add(cycle.duration_ms)
        if cycle.settle_ms is not None:
            self.settle.add(cycle.settle_ms)

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

    def __init__(self) -> None:
        self.grippers: dict[tuple[str, int], GripperCycles] = {}

    def write(self, cycles: list[Cycle]) -> None:
        for cycle in cycles:
            key = (cycle.bus, cycle.device)
            found = self.grippers.get(key)
            if found is None:
                found = self.grippers[key] = GripperCycles()
            found.add(cycle)

    def as_list(self) -> list[dict[str, Any]]:
        """One object per gripper, by bus and device."""
        return [
            {"bus": bus, "device": device, **g.as_dict()}
            for (bus, device), g in sorted(self.grippers.items())
        ]
