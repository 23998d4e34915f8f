"""Replay at the original pace (or a multiple of it): ``decode --speed 1|10|max`` and the TUI.

``paced`` lets items through when their capture time, divided by ``speed``, has come on the wall
clock. Items without a time pass at once; a capture clock that goes backwards does not make it
wait. A consumer slower than the capture is never slowed further: it catches up at full speed.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Iterator

from ..errors import UsageError
from ..model import Item, SourceEvent

MIN_SPEED = 0.001  # slower than this, a one-second capture would take over 16 minutes
MAX_SPEED = 1e6
MIN_SLEEP_S = 0.002  # shorter waits are gathered into the next (sleep has ~ms granularity)


def parse_speed(text: str | float | None) -> float | None:
    """``"max"``/``"inf"``/``"0"``/None -> None (as fast as possible); ``"10"``, ``"10x"``,
    ``"0.5"`` -> a factor. Raises ValueError for anything else."""
    if text is None:
        return None
    if isinstance(text, int | float):
        value = float(text)
    else:
        s = text.strip().lower()
        if s in ("max", "inf", "fast", ""):
            return None
        try:
            value = float(s.removesuffix("x"))
        except ValueError:
            value = math.nan
    if value == 0 or value == math.inf:
        return None
    if not MIN_SPEED <= value <= MAX_SPEED:  # also NaN and negatives
        raise UsageError(
            f"replay speed must be 'max' or a factor from {MIN_SPEED:g} to {MAX_SPEED:g} "
            f"(1 = real time), not {text!r}"
        )
    return value


def paced(
    items: Iterable[Item | SourceEvent],
    speed: float | None,
    *,
    max_gap_s: float | None = None,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
) -> Iterator[Item | SourceEvent]:
    """Yield ``items`` at their original timing divided by ``speed`` (None or inf: at once).

    ``max_gap_s``: wait at most this long (wall time) between two items, however long the
    capture was idle. ``clock``/``sleep`` are for tests.
    """
    if speed is None or math.isinf(speed) or speed <= 0:
        yield from items
        return
    t0: float | None = None  # capture time that maps to wall time w0
    w0 = 0.0
    last: float | None = None
    for item in items:
        t = item.t if isinstance(item, SourceEvent) else item.payload.t
        if t is not None:
            if t0 is None or last is None:
                t0, w0 = t, clock()
            else:
                if t < last:  # the capture clock went back: carry on from here
                    t0, w0 = t, clock()
                due = w0 + (t - t0) / speed
                now = clock()
                wait = due - now
                if max_gap_s is not None and wait > max_gap_s:
                    # skip the idle time: shift the mapping so the wait is max_gap_s
                    w0 -= wait - max_gap_s
                    wait = max_gap_s
                if wait >= MIN_SLEEP_S:
                    sleep(wait)
            last = t
        yield item
