"""How a grip cycle's outcome looks wherever it is shown (Rerun's cycle lanes and logs; a panel
can read the same): one colour and one severity per outcome, in one table.

Good ends are green, a miss or a slip amber, a fault, refusal or silence red, a cycle whose end
was not seen grey. A gripped cycle that slipped is shown as ``slip``: it held the part, not well.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from .model import (
    CLOSED_EMPTY,
    FAULTED,
    GRIPPED,
    OPENED,
    OUTCOMES,
    POSITIONED,
    REFUSED,
    SLIP,
    STOPPED,
    UNANSWERED,
    UNFINISHED,
    UNKNOWN,
    Cycle,
)

# severities, the least serious first
GOOD: Final = "good"  # the command did what it asked
NOTICE: Final = "notice"  # done, but not as hoped (a missed part, a slip, a stop)
BAD: Final = "bad"  # the gripper faulted, refused or never answered
OPEN: Final = "open"  # the end was not seen


@dataclass(frozen=True)
class Look:
    """How one outcome is shown: ``label`` in words, ``color`` as 0xRRGGBBAA, ``severity``."""

    label: str
    color: int
    severity: str


LOOKS: Final = {
    GRIPPED: Look("gripped", 0x2CA02CFF, GOOD),
    OPENED: Look("opened", 0x98DF8AFF, GOOD),
    POSITIONED: Look("positioned", 0x17BECFFF, GOOD),
    CLOSED_EMPTY: Look("closed empty", 0xFFB000FF, NOTICE),
    SLIP: Look("gripped, slipped", 0xFF8C00FF, NOTICE),
    STOPPED: Look("stopped", 0xBCBD22FF, NOTICE),
    FAULTED: Look("faulted", 0xE3000BFF, BAD),
    REFUSED: Look("refused", 0xD62728FF, BAD),
    UNANSWERED: Look("unanswered", 0xA50F15FF, BAD),
    UNFINISHED: Look("unfinished", 0x8C8C8CFF, OPEN),
    UNKNOWN: Look("unknown", 0xC7C7C7FF, OPEN),
}
assert set(OUTCOMES) <= set(LOOKS), "every outcome has a look"


def shown_as(cycle: Cycle) -> str:
    """The key of ``LOOKS`` a cycle is shown as: its outcome, or ``slip`` for a grip that
    slipped."""
    if cycle.outcome == GRIPPED and SLIP in cycle.warnings:
        return SLIP
    return cycle.outcome
