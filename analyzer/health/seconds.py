"""Bus health second by second: one ``HealthSecond`` per bus and whole second of capture time,
the rows the TUI's health line, Rerun's ``/<bus>/health/...`` and ``batch``'s ``health`` table
show. ``SecondLog`` collects one bus's seconds as the listener counts its frames and hands out
those the bus has completed (a later second was seen on it), so a live session gets each second
once it is over and memory holds only the open ones.

A second's worst event is named in words, the most serious of its kind first (``SEVERITY``): a
bus-off outweighs an error-passive warning, a checksum error a gap too short for Modbus.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from decoders.can_errors import (
    BUS_OFF,
    ERROR_ACTIVE,
    ERROR_CLASSES,
    ERROR_PASSIVE,
    ERROR_WARNING,
    ErrorReport,
)
from decoders.flags import BAD_CHECKSUM, GARBAGE, TRUNCATED

from .figures import PERCENT_DIGITS

CLOSE_FRAMES: Final = "closer_than_t3_5"

_WORDS: Final = {
    **{key: words for _, key, words in ERROR_CLASSES},
    ERROR_WARNING: "error warning",
    ERROR_PASSIVE: "error passive",
    "unspecified": "error frame",
    BAD_CHECKSUM: "bad checksum",
    TRUNCATED: "truncated frame",
    GARBAGE: "garbage bytes",
    CLOSE_FRAMES: "frames closer than t3.5",
}
#: the events a second may name, the most serious first
SEVERITY: Final = (
    "bus_off", "error_passive", "no_ack", "tx_timeout", "transceiver", "protocol_violation",
    "bus_error", "controller", "error_warning", "restarted", "lost_arbitration", "unspecified",
    BAD_CHECKSUM, TRUNCATED, GARBAGE, CLOSE_FRAMES,
)  # fmt: skip
_RANK: Final = {key: rank for rank, key in enumerate(SEVERITY)}
_RANK_OF_WORDS: Final = {_WORDS.get(key, key): rank for key, rank in _RANK.items()}
#: the controller states, the worst last
STATES: Final = (ERROR_ACTIVE, ERROR_WARNING, ERROR_PASSIVE, BUS_OFF)
_WORSE: Final = {state: rank for rank, state in enumerate(STATES)}


def severity(worst: str) -> int:
    """The rank of an event as a ``HealthSecond`` names it (``worst``): 0 the most serious
    (``SEVERITY``), words it does not know after all it knows."""
    return _RANK_OF_WORDS.get(worst, len(SEVERITY))


@dataclass(frozen=True, slots=True)
class HealthSecond:
    """One bus in one whole second of capture time (``second``: ``floor(t)``).

    ``load_pct``: the bits of the frames that ended in it over the bus's rate (None for
    frames without a time); ``errors``: CAN error frames, or a serial line's records with
    errors; ``state``: the worst state a CAN controller was in during the second (None on
    serial: a bus-off that ends within its second still marks it);
    ``worst``: the most serious event of the second in words (None: none)."""

    bus: str
    kind: str
    second: int
    frames: int
    bits: int
    load_pct: float | None
    errors: int
    state: str | None
    worst: str | None


class _Open:
    """A second being counted."""

    __slots__ = ("bits", "errors", "frames", "state", "worst")

    def __init__(self, state: str | None) -> None:
        self.frames = 0
        self.bits = 0
        self.errors = 0
        self.state = state
        self.worst: str | None = None

    def event(self, key: str) -> None:
        if self.worst is None or _RANK.get(key, len(SEVERITY)) < _RANK.get(self.worst, 0):
            self.worst = key


class SecondLog:
    """One bus's seconds: counted as they come (in any order within the open ones), handed out
    by ``take`` once the bus has moved past them, each second once.

    What moves a bus past a second is a frame or an event in a later one. A serial line's reads
    do not: its records come after the reads they were found in (a framer holds a frame's bytes
    until it can decide), so a second is over once the line's records have passed it. Anything
    that still comes for a second already handed out (a record decided late) is counted in the
    first second still open, so every frame, bit and error is in exactly one row."""

    def __init__(self, bus: str, kind: str, rate: int, state: str | None) -> None:
        self.bus = bus
        self.kind = kind
        self.rate = rate
        self.state = state  # CAN: the controller's state carried from second to second
        self.open: dict[int, _Open] = {}
        self.latest: int | None = None  # the latest second that moved the bus on
        self.taken: int | None = None  # the seconds before this one were handed out

    def frames(self, second: int, frames: int, bits: int) -> None:
        row = self._at(self._open(second))
        row.frames += frames
        row.bits += bits

    def read(self, second: int, bits: int) -> None:
        """A serial line's bytes read in ``second`` (they do not move the line on)."""
        second = self._open(second)
        row = self.open.get(second)
        if row is None:
            row = self.open[second] = _Open(self.state)
        row.bits += bits

    def error(self, second: int, keys: tuple[str, ...]) -> None:
        row = self._at(self._open(second))
        row.errors += 1
        for key in keys:
            row.event(key)

    def controller(self, second: int, report: ErrorReport) -> None:
        """A CAN error frame: its classes, and the state it reports from its second on."""
        second = self._open(second)
        self.error(second, report.keys)
        state = report.state
        if state is not None:
            self.state = state
            for s, row in self.open.items():
                if s > second:
                    row.state = state  # a later second begins in it
                elif s == second and _WORSE[state] > _WORSE[row.state or ERROR_ACTIVE]:
                    row.state = state

    def event(self, second: int, key: str) -> None:
        """An event that is no error of a frame (Modbus frames too close)."""
        self._at(self._open(second)).event(key)

    def take(self, final: bool = False) -> list[HealthSecond]:
        """The seconds before the latest one (all of them when ``final``), in order."""
        if final:
            done = sorted(self.open)
            upto = done[-1] + 1 if done else self.taken
        elif self.latest is None:
            return []
        else:
            done = sorted(s for s in self.open if s < self.latest)
            upto = self.latest
        if upto is not None:
            self.taken = upto if self.taken is None else max(upto, self.taken)
        return [self._row(s, self.open.pop(s)) for s in done]

    def _open(self, second: int) -> int:
        """``second``, or the first one still open when it was handed out already."""
        taken = self.taken
        return second if taken is None or second >= taken else taken

    def _at(self, second: int) -> _Open:
        row = self.open.get(second)
        if row is None:
            row = self.open[second] = _Open(self.state)
        if self.latest is None or second > self.latest:
            self.latest = second
        return row

    def _row(self, second: int, row: _Open) -> HealthSecond:
        load = round(100.0 * row.bits / self.rate, PERCENT_DIGITS) if self.rate else None
        worst = None if row.worst is None else _WORDS.get(row.worst, row.worst)
        return HealthSecond(self.bus, self.kind, second, row.frames, row.bits, load,
                            row.errors, row.state, worst)  # fmt: skip
