"""The mark a USB serial adapter's latency timer leaves on read times, and the setting that
fixes it.

An FTDI-style adapter holds the bytes it receives until its buffer fills or its latency timer
runs out (16 ms by default), so a tap's reads come at multiples of 16 ms, a request and its
answer often in one read: gaps, turnaround and 3.5-character silences cannot be measured, and
the times are late by up to the timer. At its 1 ms minimum, reads still come once per USB frame,
at multiples of 1 ms. The test: at least ``MIN_READS`` intervals between reads (reads closer than
``SAME_BURST_S`` are one burst read in two), and ``SHARE`` of them within a tolerance of a
multiple of the quantum (16 ms ones also no shorter than one quantum less its tolerance).
Reads at random times fall that close to multiples of 1 ms a fifth of the time, of 16 ms far
less.
"""

from __future__ import annotations

import os
from typing import Any, Final

MIN_READS: Final = 20
SHARE: Final = 0.8
SAME_BURST_S: Final = 0.0002
# (quantum, tolerance) in milliseconds, the coarser first: a multiple of 16 is one of 1 too
QUANTA_MS: Final = ((16.0, 1.0), (1.0, 0.1))
SYSFS_TIMER: Final = "/sys/bus/usb-serial/devices/{name}/latency_timer"
EXAMPLE_PORT: Final = "ttyUSB0"


class ReadTimes:
    """The intervals between a line's reads, counted near multiples of each quantum."""

    def __init__(self) -> None:
        self.last_t: float | None = None
        self.intervals = 0
        self.near = [0] * len(QUANTA_MS)

    def add(self, t: float) -> None:
        last, self.last_t = self.last_t, t
        if last is None:
            return
        ms = (t - last) * 1000.0
        if ms < SAME_BURST_S * 1000.0:
            self.last_t = last  # one burst: its first read keeps the time
            return
        self.intervals += 1
        for i, (quantum, tolerance) in enumerate(QUANTA_MS):
            off = abs(ms - round(ms / quantum) * quantum)
            if off <= tolerance and ms >= quantum - tolerance:
                self.near[i] += 1

    def hint(self, port: str | None) -> dict[str, Any] | None:
        """``quantum_ms``, ``share`` (of the intervals), ``message`` and ``fix`` (None where
        there is no setting to change) when the reads show an adapter's timer; else None."""
        if self.intervals < MIN_READS:
            return None
        for (quantum, _), near in zip(QUANTA_MS, self.near, strict=True):
            share = near / self.intervals
            if share >= SHARE:
                return _hint(quantum, share, port)
        return None


def _hint(quantum: float, share: float, port: str | None) -> dict[str, Any]:
    name = os.path.basename(port) if port and "ttyUSB" in port else EXAMPLE_PORT
    if quantum > 1.0:
        message = (
            f"reads arrive in bursts at multiples of {quantum:g} ms: a USB adapter's latency "
            f"timer holds the bytes, so gaps and turnaround inside a burst cannot be measured "
            f"and times are late by up to {quantum:g} ms"
        )
        fix = (f"echo 1 > {SYSFS_TIMER.format(name=name)} (or setserial /dev/{name} "
               "low_latency)")  # fmt: skip
    else:
        message = (
            "reads arrive at multiples of 1 ms (one per USB frame): the adapter's latency "
            "timer is at its minimum, times are good to about 1 ms; an interface with "
            "hardware time stamps measures finer"
        )
        fix = None
    return {"quantum_ms": quantum, "share": round(share, 3), "message": message, "fix": fix}
