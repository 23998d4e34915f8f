"""A grip cycle as the outputs write it: the cycles contract of docs/contracts.md.

A cycle begins at a motion command to one gripper and ends at its next motion command, a stop,
or the end of the capture. Everything here is plain data; ``rules.py`` decides the values.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Final

# outcomes (docs/contracts.md, "Grip cycles")
GRIPPED: Final = "gripped"
CLOSED_EMPTY: Final = "closed_empty"
OPENED: Final = "opened"
POSITIONED: Final = "positioned"
STOPPED: Final = "stopped"
FAULTED: Final = "faulted"
REFUSED: Final = "refused"
UNANSWERED: Final = "unanswered"
UNFINISHED: Final = "unfinished"
UNKNOWN: Final = "unknown"
OUTCOMES: Final = (
    GRIPPED,
    CLOSED_EMPTY,
    OPENED,
    POSITIONED,
    STOPPED,
    FAULTED,
    REFUSED,
    UNANSWERED,
    UNFINISHED,
    UNKNOWN,
)

# what a cycle may not know (its ``unknown`` list), in this order
STATE: Final = "state"
OPENING: Final = "opening"
FORCE: Final = "force"
TIME: Final = "time"
QUANTITIES: Final = (STATE, OPENING, FORCE, TIME)

# warnings
SLIP: Final = "slip"
NOT_ANSWERED: Final = "unanswered"  # never answered, yet the readings show it carried out


@dataclass(slots=True)
class Cycle:
    """One grip cycle; ``to_dict`` is its JSONL object, keys in the contract's order."""

    bus: str
    device: int
    start_t: float | None
    end_t: float | None
    start_seq: int
    end_seq: int
    command: str
    target_mm: float | None
    outcome: str
    width_mm: float | None = None
    force_peak: int | None = None
    time_to_contact_ms: float | None = None
    settle_ms: float | None = None
    retries: int = 0
    faults: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    unknown: list[str] = field(default_factory=list)
    evidence: list[int] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "bus": self.bus,
            "device": self.device,
            "start_t": self.start_t,
            "end_t": self.end_t,
            "start_seq": self.start_seq,
            "end_seq": self.end_seq,
            "command": self.command,
            "target_mm": self.target_mm,
            "outcome": self.outcome,
            "width_mm": self.width_mm,
            "force_peak": self.force_peak,
            "time_to_contact_ms": self.time_to_contact_ms,
            "settle_ms": self.settle_ms,
            "retries": self.retries,
            "faults": self.faults,
            "warnings": self.warnings,
            "unknown": self.unknown,
            "evidence": self.evidence,
        }

    @property
    def duration_ms(self) -> float | None:
        """From the command to the cycle's last frame (None without times)."""
        if self.start_t is None or self.end_t is None:
            return None
        return round((self.end_t - self.start_t) * 1000.0, 3)


#: one gripper's cycles among some, counted (``counts_of``): bus, device, each cycle's outcome,
#: and the cycle times and settle times known (``Cycle.duration_ms``, ``Cycle.settle_ms``)
CycleCounts = tuple[str, int, list[str], list[float], list[float]]


def counts_of(cycles: list[Cycle]) -> list[CycleCounts]:
    """The cycles counted per gripper, the grippers in the order they first appear (the native
    segmenter's ``counts`` give the same; all ``eg2scope stats`` needs of them)."""
    found: dict[tuple[str, int], CycleCounts] = {}
    for c in cycles:
        counts = found.get((c.bus, c.device))
        if counts is None:
            counts = found[(c.bus, c.device)] = (c.bus, c.device, [], [], [])
        counts[2].append(c.outcome)
        if (duration := c.duration_ms) is not None:
            counts[3].append(duration)
        if c.settle_ms is not None:
            counts[4].append(c.settle_ms)
    return list(found.values())


KEYS: Final = tuple(Cycle("", 0, None, None, 0, 0, "", None, "").to_dict())
