"""Scripted scenarios: grip cycles whose true outcome is known, so that tests and demos can hold
what eg2scope detects against what really happened.

A ``Scenario`` is a script of ``Step``s, each one grip cycle on one gripper: the motion command
the host sends (catch, continuous catch, release, seek), what the world does meanwhile (a part
between the jaws, a part that slips, an obstruction that stalls the jaw, a command the gripper
never hears, a bus-off on CAN, a stop from the host) and the cycle's true outcome (one of
``SCRIPT_OUTCOMES``, named where the cycles name them), with the opening where contact was made.
Pure data: ``play`` plays a script on a bus, ``script(bus)`` says exactly what it plays there.

Openings are in the protocol's unit, 0-1000 of the stroke (1000 = 70 mm).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Final

from decoders.registers import opening_mm

from ..cycles.model import (
    CLOSED_EMPTY,
    FAULTED,
    GRIPPED,
    OPENED,
    POSITIONED,
    SLIP,
    STOPPED,
    UNANSWERED,
)
from .gripper import FAULT_STALL

# the outcomes a script plays, named where the cycles name them (``unfinished`` is a capture's)
SCRIPT_OUTCOMES: Final = (GRIPPED, CLOSED_EMPTY, OPENED, POSITIONED, STOPPED, FAULTED, UNANSWERED)
COMMANDS: Final = ("catch", "continuous catch", "release", "seek")
CLOSING: Final = frozenset(("catch", "continuous catch", "seek"))  # a part is placed first
WARNINGS: Final = (SLIP,)  # the opening keeps closing after contact, or 6 is left while holding
DEFAULT_PART: Final = 420  # 29.4 mm
PART_RANGE: Final = (100, 900)  # a part's width the scripts take (it must be able to slip)
SLIP_FRACTION: Final = 0.6  # a slipping part ends at this fraction of its width
SEEK_TARGET: Final = 600
JAM_AT: Final = 600
STOP_AT: Final = 650


@dataclass(frozen=True)
class Step:
    """One grip cycle. ``command``: one of ``COMMANDS`` (``position``: a seek's target);
    ``outcome``: one of ``SCRIPT_OUTCOMES``; ``part``: the width of the part placed between the jaws
    before a closing command (None: none); ``contact``: the opening where the jaw met it (None:
    no contact); ``slip_to``: after contact the part slips to this width (a continuous catch
    closes on it again); ``jam_at``: an obstruction the closing jaw stalls on; ``faults``: the
    fault bits set during the cycle; ``stop_at``: the host stops the jaw once it polls an
    opening at or below this; ``drop``: the gripper hears nothing of the command (nor of its
    resends); ``bus_off``: on CAN, the gripper's node goes error-passive and bus-off while the
    jaw moves, and comes back; ``warnings``: what the cycle must warn of."""

    command: str
    outcome: str
    position: int | None = None
    part: int | None = None
    contact: int | None = None
    slip_to: int | None = None
    jam_at: int | None = None
    faults: int = 0
    stop_at: int | None = None
    drop: bool = False
    bus_off: bool = False
    warnings: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.command not in COMMANDS or self.outcome not in SCRIPT_OUTCOMES:
            raise ValueError(f"a step needs a known command and outcome: {self}")

    @property
    def words(self) -> str:
        """The command in words: "catch", "seek 600"."""
        return f"seek {self.position}" if self.command == "seek" else self.command

    def to_json(self) -> dict[str, Any]:
        """The step as plain values; openings also in millimetres."""
        out = dataclasses.asdict(self)
        out["warnings"] = list(self.warnings)
        out["command_words"] = self.words
        out["contact_mm"] = None if self.contact is None else opening_mm(self.contact)
        return out


RELEASE: Final = Step("release", "opened")


def _grip(part: int, **trouble: Any) -> Step:
    return Step("catch", "gripped", part=part, contact=part, **trouble)


def _slip(part: int) -> Step:
    slip_to = round(part * SLIP_FRACTION)
    return Step(
        "continuous catch",
        "gripped",
        part=part,
        contact=part,
        slip_to=slip_to,
        warnings=(SLIP,),
    )


@dataclass(frozen=True)
class Scenario:
    """A script of grip cycles. ``summary``: one line for ``--list-scenarios``; ``repeat``:
    the script starts again when it ends (else the host keeps polling); ``part``: the width of
    its part, where it has one (None: it has none); ``needs_can``: its trouble happens on CAN
    only (elsewhere the same cycles play without it)."""

    name: str
    summary: str
    steps: tuple[Step, ...]
    part: int | None = None
    repeat: bool = False
    needs_can: bool = False

    def script(self, protocol: str) -> tuple[Step, ...]:
        """The steps as they play on a bus of this protocol ("serial", "modbus", "can"): off
        CAN a bus-off step plays without the bus-off."""
        if protocol == "can":
            return self.steps
        return tuple(dataclasses.replace(s, bus_off=False) for s in self.steps)

    def to_json(self, protocol: str) -> dict[str, Any]:
        return {
            "scenario": self.name,
            "summary": self.summary,
            "protocol": protocol,
            "repeat": self.repeat,
            "steps": [s.to_json() for s in self.script(protocol)],
        }


def _make(name: str, part: int) -> Scenario:
    """A scenario by its name, with this part width where it has a part."""
    grip, empty = _grip(part), Step("catch", "closed_empty")
    stall = Step("catch", "faulted", jam_at=JAM_AT, faults=FAULT_STALL)
    drop = Step("catch", "unanswered", drop=True)
    seek = Step("seek", "positioned", position=SEEK_TARGET)
    stop = Step("catch", "stopped", stop_at=STOP_AT)
    bus_off = _grip(part, bus_off=True)
    made = {
        "grip": (f"a part present: caught at its width ({part}), then released", (grip,), True),
        "empty": ("no part: the jaw closes fully without contact, then opens", (empty,), False),
        "slip": (
            f"continuous catch on a part ({part}) that slips to {round(part * SLIP_FRACTION)} "
            "after contact: the jaw closes on it again",
            (_slip(part),),
            True,
        ),
        "stall": (
            f"an obstruction at {JAM_AT} stalls the closing jaw: fault bit 0 (stall)",
            (stall,),
            False,
        ),
        "drop": ("the gripper never hears a catch (nor its resends): unanswered", (drop,), False),
        "seek": (f"seek to {SEEK_TARGET}: the jaw stops there", (seek,), False),
        "stop": (f"the host stops a closing jaw at {STOP_AT}", (stop,), False),
        "bus-off": (
            f"CAN: error-passive, bus-off and a restart while the jaw closes on a part ({part})",
            (bus_off,),
            True,
        ),
    }
    if name == "tour":
        every = (grip, empty, _slip(part), stall, drop, seek, stop, bus_off)
        summary = "every scenario in turn, over and over (bus-off on CAN only)"
        return Scenario(name, summary, _released(every), part, repeat=True)
    summary, steps, has_part = made[name]
    part_or_none = part if has_part else None
    return Scenario(name, summary, _released(steps), part_or_none, needs_can=name == "bus-off")


def _released(steps: tuple[Step, ...]) -> tuple[Step, ...]:
    """Each step followed by a release (the place of a pick-and-place)."""
    return tuple(s for step in steps for s in (step, RELEASE))


NAMES: Final = ("grip", "empty", "slip", "stall", "drop", "seek", "stop", "bus-off", "tour")
SCENARIOS: Final = {name: _make(name, DEFAULT_PART) for name in NAMES}


def scenario(text: str) -> Scenario:
    """A scenario from ``NAME`` or ``NAME:WIDTH`` (the width of its part, 100-900 of the
    stroke); ValueError in words for anything else."""
    name, _, width = text.partition(":")
    if name not in SCENARIOS:
        raise ValueError(f"unknown scenario {name!r}; choose from {', '.join(NAMES)}")
    if not width:
        return SCENARIOS[name]
    lo, hi = PART_RANGE
    if SCENARIOS[name].part is None:
        raise ValueError(f"scenario {name!r} has no part to give a width to")
    if not width.isdigit() or not lo <= int(width) <= hi:
        raise ValueError(f"a part's width must be {lo}-{hi} (of 1000 = 70 mm), not {width!r}")
    return _make(name, int(width))


def listing() -> str:
    """One line per scenario, for ``--list-scenarios``."""
    wide = max(map(len, NAMES))
    return "\n".join(f"{name:<{wide}}  {SCENARIOS[name].summary}" for name in NAMES)
