"""A CAN bus's error frames: counts by class (``decoders.can_errors``), the error counters
where the frames carry them, and the periods the controller spent error passive or bus-off."""

from __future__ import annotations

from collections import Counter
from typing import Any, Final

from decoders.can_errors import (
    BUS_OFF,
    ERROR_ACTIVE,
    ERROR_KEYS,
    ERROR_PASSIVE,
    ErrorReport,
    error_report,
)

#: the states whose periods are listed (error-warning is counted, not a period)
PERIOD_STATES: Final = (ERROR_PASSIVE, BUS_OFF)


class ErrorFrameLog:
    """The error frames of one CAN bus, in time order."""

    def __init__(self) -> None:
        self.total = 0
        self.counts: Counter[str] = Counter()
        self.tx_errors: int | None = None  # the last counters a frame carried, and the highest
        self.rx_errors: int | None = None
        self.tx_max: int | None = None
        self.rx_max: int | None = None
        self.periods: list[tuple[float, float, str]] = []
        self.state = ERROR_ACTIVE
        self.since: float | None = None  # when the state began (None: untimed, or from start)
        self.last_t: float | None = None  # the latest error frame's time

    def add(self, t: float | None, error_class: int, data: bytes) -> ErrorReport:
        """One error frame, in time order; returns what it says."""
        report = error_report(error_class, data)
        self.total += 1
        if t is not None and (self.last_t is None or t > self.last_t):
            self.last_t = t
        self.counts.update(report.keys)
        if report.tx_errors is not None and report.rx_errors is not None:
            self.tx_errors, self.rx_errors = report.tx_errors, report.rx_errors
            self.tx_max = max(self.tx_max or 0, report.tx_errors)
            self.rx_max = max(self.rx_max or 0, report.rx_errors)
        state = report.state
        if state is None or state == self.state:
            return report
        if self.state in PERIOD_STATES and self.since is not None and t is not None:
            self.periods.append((self.since, t, self.state))
        self.state, self.since = state, t
        return report

    def figures(self, end: float | None) -> dict[str, Any]:
        """``error_frames`` (every class, 0 where none), ``error_counters`` (None where no frame
        carried them) and ``error_states``: the periods, the last one ``to_end`` when the
        capture ended first (``end``: the bus's last frame's time; its last error frame's when
        that came later)."""
        states = [{"start": a, "end": b, "state": s, "to_end": False} for a, b, s in self.periods]
        if self.state in PERIOD_STATES and self.since is not None:
            last = max(t for t in (end, self.last_t, self.since) if t is not None)
            states.append({"start": self.since, "end": last, "state": self.state, "to_end": True})
        counters = None
        if self.tx_errors is not None:
            counters = {"tx": self.tx_errors, "rx": self.rx_errors, "tx_max": self.tx_max,
                        "rx_max": self.rx_max}  # fmt: skip
        return {
            "error_frames": {"total": self.total, **{k: self.counts[k] for k in ERROR_KEYS}},
            "error_counters": counters,
            "error_states": states,
        }
