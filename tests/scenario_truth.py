"""A scenario's grip cycles held against the simulator's truth of them: each gripper's cycles,
in the order they began, must be the truth's one for one (the same outcome, the width at
contact within 0.2 mm, the slip warned of, the stall's fault in words, the command's target).
Shared by the cycles' own scenario tests (tests/cycles/test_scenario_truth.py) and the batch
dataset's (tests/e2e/test_matrix_batch.py): whatever writes the cycles, one rule for them.

The one cycle the truth may lack is a gripper's last one, cut off by the end of the recording
while the host's script went on: it must be ``unfinished``; and the truth's last cycle may be
found ``unfinished`` where the taps stopped before the host's last readings.
"""

from __future__ import annotations

from typing import Any

import pytest

from analyzer.cycles.model import GRIPPED, SLIP, UNFINISHED
from decoders.registers import fault_text, opening_mm

WIDTH_TOLERANCE_MM = 0.2
EARLY_S = 0.05  # a command's capture time may lead the host's clock by this much, never more
TARGET_MM = {"catch": 0.0, "continuous catch": 0.0, "release": 70.0}  # a seek: its position
ALL_BUSES = ("rs232", "rs485", "can0")
Cycle = dict[str, Any]


def pairs(cycles: list[Cycle], truth: list[Cycle], bus: str) -> list[tuple[Cycle, Cycle]]:
    """(truth, detected) for every cycle of the bus, each gripper's in the order they began;
    a gripper's last cycle, found unfinished (cut off by the recording's end), left out."""
    out = []
    for device in sorted({t["device"] for t in truth if t["bus"] == bus}):
        told = sorted(
            (t for t in truth if (t["bus"], t["device"]) == (bus, device)),
            key=lambda t: t["start_t"],
        )
        seen = sorted(
            (c for c in cycles if (c["bus"], c["device"]) == (bus, device)),
            key=lambda c: c["start_seq"],
        )
        if seen and seen[-1]["outcome"] == UNFINISHED:  # cut off by the recording's end:
            seen = seen[:-1]  # the script's next cycle (the truth has none) ...
            if len(told) == len(seen) + 1:  # ... or its last, ended after the taps stopped
                told = told[:-1]
        assert len(seen) == len(told), _table(told, seen)
        out += list(zip(told, seen, strict=True))
    assert {c["bus"] for c in cycles} <= set(ALL_BUSES)
    return out


def _table(truth: list[Cycle], seen: list[Cycle]) -> str:
    told = [f"truth {t['start_t']:.3f} {t['command']} {t['outcome']}" for t in truth]
    return "\n".join(
        told + [f"found {c['start_t']:.3f} {c['command']} {c['outcome']}" for c in seen]
    )


def check(truth: Cycle, seen: Cycle) -> None:
    """One detected cycle against the truth of it."""
    what = f"{truth['scenario']} {truth['bus']} #{truth['index']} {truth['command']}: {seen}"
    assert truth["start_t"] - EARLY_S <= seen["start_t"] <= truth["end_t"], what
    assert seen["outcome"] == truth["outcome"], what
    if truth["outcome"] == GRIPPED:
        assert abs(seen["width_mm"] - truth["contact_mm"]) <= WIDTH_TOLERANCE_MM, what
    else:
        assert seen["width_mm"] is None, what
    assert (SLIP in seen["warnings"]) == (SLIP in truth["warnings"]), what
    assert seen["faults"] == fault_text(truth["faults"]), what
    target = TARGET_MM.get(truth["command"])
    expected = opening_mm(truth["position"]) if target is None else target
    assert seen["target_mm"] == pytest.approx(expected), what
    assert seen["retries"] >= (0 if truth["answered"] else 1), what  # the host resent it
