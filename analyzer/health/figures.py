"""The figures bus health is made of: load per whole second of capture time and its mean, p95
and max; nearest-rank percentiles; the spread of a time (gaps, turnaround) in constant memory.

Seconds are whole seconds of capture time (``floor(t)``), the same for every bus, so seconds of
several buses line up. A bus's span runs from the start of its first frame to the end of its
last. The mean load is the bits over the span; p95 and max are over the seconds the span covers
whole (a second without a frame in it counts, at 0 %); a span that covers no whole second gives
its mean for both.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, Final

from ..stats import LatencyHistogram

PERCENT_DIGITS: Final = 3  # load figures are rounded to 0.001 %
MS_DIGITS: Final = 3  # times in milliseconds, to the microsecond


def load_pct(
    seconds: Mapping[int, int], start: float, end: float, total_bits: int, rate: int
) -> dict[str, float | None]:
    """``mean``, ``p95`` and ``max`` of a bus's load in percent of ``rate`` (bits per second):
    ``seconds`` maps a whole second to the bits in it, ``start`` and ``end`` are the span."""
    if not end > start:
        return {"mean": None, "p95": None, "max": None}
    mean = 100.0 * total_bits / rate / (end - start)
    first, stop = math.ceil(start), math.floor(end)  # the seconds [s, s + 1) inside the span
    if stop <= first:
        return _rounded(mean, mean, mean)
    loads = sorted(100.0 * bits / rate for s, bits in seconds.items() if first <= s < stop)
    silent = stop - first - len(loads)  # seconds without a frame, at 0 % (never listed: a
    # clock that jumps a year would make a list of every second in between)
    rank = max(1, math.ceil(0.95 * (stop - first)))  # p95 by nearest rank
    p95 = 0.0 if rank <= silent else loads[rank - silent - 1]
    return _rounded(mean, p95, loads[-1] if loads else 0.0)


def _rounded(mean: float, p95: float, top: float) -> dict[str, float | None]:
    return {
        "mean": round(mean, PERCENT_DIGITS),
        "p95": round(p95, PERCENT_DIGITS),
        "max": round(top, PERCENT_DIGITS),
    }


def per_second(count: int, start: float | None, end: float | None) -> float | None:
    """``count`` over the span in seconds (None where the span is unknown or empty)."""
    if start is None or end is None or not end > start:
        return None
    return round(count / (end - start), PERCENT_DIGITS)


class Spread:
    """The spread of a time in milliseconds: count, min, median, p95, max, in constant memory
    (percentiles from ``stats.LatencyHistogram``: 1 % resolution; min and max exact), and how
    many times could not be measured (``unmeasured``)."""

    def __init__(self) -> None:
        self.histogram = LatencyHistogram()
        self.min: float | None = None
        self.unmeasured = 0

    def add(self, ms: float | None) -> None:
        """One time; None: one that could not be measured."""
        if ms is None:
            self.unmeasured += 1
            return
        self.histogram.add(ms)
        if self.min is None or ms < self.min:
            self.min = ms

    @property
    def count(self) -> int:
        return self.histogram.count

    def summary(self) -> dict[str, Any]:
        h = self.histogram
        if not h.count:
            return {"count": 0, "min": None, "median": None, "p95": None, "max": None,
                    "unmeasured": self.unmeasured}  # fmt: skip
        low = self.min or 0.0  # a bucket's middle may lie under the least value in it

        def at(p: float) -> float | None:
            value = h.percentile(p)
            return None if value is None else _ms(max(low, value))

        return {"count": h.count, "min": _ms(self.min), "median": at(50), "p95": at(95),
                "max": _ms(h.max), "unmeasured": self.unmeasured}  # fmt: skip


def _ms(x: float | None) -> float | None:
    return None if x is None else round(x, MS_DIGITS)
