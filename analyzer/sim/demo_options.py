"""What a command's ``--demo`` asks of the demo rig (sim/rig.py): its own light module, so a
command parses and checks its options without importing the rig (python-can, the simulator)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .scenarios import Scenario

BUSES = ("serial", "modbus", "can")


@dataclass(frozen=True)
class DemoOptions:
    """The demo a command asks for: which of ``BUSES`` to simulate, the probability of a
    corrupted, garbled or dropped response, the scenario to play (None: the pick-and-place
    cycles on grippers 1 and 2), the jaw's speed-up ``pace``, and the file the scenario's truth
    goes to (None: none)."""

    buses: tuple[str, ...]
    noise: float
    scenario: Scenario | None = None
    pace: float = 1.0
    truth: str | None = None

    @property
    def kind(self) -> str:
        """What its taps give (``sources.source.live_kind``): frames from the CAN bus, bytes
        from the serial lines."""
        kinds = {"can" if bus == "can" else "bytes" for bus in self.buses}
        return kinds.pop() if len(kinds) == 1 else "mixed"
