"""A bus's health in Rerun, from the ``HealthListener``'s per-second rows (``HealthSecond``: one
home for the counting): under ``/<bus>/health/``, the load in percent of the bus's rate, frames
and errors per second (``Scalars``, a point at the end of each second; the last second's at the
bus's last record, so no point lies past the capture; a silent stretch drops to zero) and, on a
CAN bus, the controller's state (a ``StateChange`` lane: the worst state of each second, from the
second's start, logged when it changes; the first from the bus's first record, so the lane does
not begin before the capture). All on ``capture_time`` only: a second has no frame.

The bus health hands out each second once, when the bus has passed it (``SecondLog``), and
every second at the end: each is plotted as it comes.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np

from ..health.seconds import HealthSecond
from . import entities as ent
from .columns import LANE, SCALAR, Columns

# what each plotted series takes of a second
_FIGURES: Final = {
    ent.LOAD: lambda row: row.load_pct,
    ent.FRAMES_PER_S: lambda row: row.frames,
    ent.ERRORS_PER_S: lambda row: row.errors,
}


class BusHealthColumns:
    """One bus's health series waiting to be sent. ``index``: the bus's place (its colours);
    ``highest_rate``, ``highest_load``: the most frames or errors in a second so far, the
    highest load (the y ranges of the views)."""

    def __init__(self, bus: str, index: int) -> None:
        base = f"{ent.bus_path(bus)}/{ent.HEALTH}"
        self.bus = bus
        self.series = {
            name: Columns(f"{base}/{name}", SCALAR, ent.health_style(name, bus, index), frame=False)
            for name in _FIGURES
        }
        self.state = Columns(
            f"{base}/{ent.CONTROLLER}", LANE, ent.controller_configuration(), frame=False
        )
        self.last_second: int | None = None  # the latest second plotted (silent ones after it)
        self.last_state: str | None = None
        self.highest_rate = 0.0
        self.highest_load = 0.0

    def add(self, rows: list[HealthSecond], first_t: float, last_t: float) -> None:
        """The bus's seconds (in order) as the bus health hands them out; ``first_t`` and
        ``last_t``: its first and last record's time (where the first state begins, where the
        last, partial second ends)."""
        if not rows:
            return
        secs = np.array([r.second for r in rows], dtype=np.float64)
        ends = np.minimum(secs + 1, last_t) if math.isfinite(last_t) else secs + 1
        ends = np.maximum(ends, secs)  # never before its own second
        before = [] if self.last_second is None else [float(self.last_second)]
        zeros = silent(np.array([*before, *secs.tolist()]))
        t = np.concatenate([ends, zeros])
        order = np.argsort(t, kind="stable")
        for name, figure in _FIGURES.items():
            values = [figure(r) for r in rows]
            if name == ent.LOAD and None in values:
                continue  # no rate to count it at: no load
            column = self.series[name]
            column.t.extend(t[order].tolist())
            column.values.extend(np.concatenate([values, np.zeros(len(zeros))])[order].tolist())
        self.highest_rate = max(self.highest_rate, *(max(r.frames, r.errors) for r in rows))
        self.highest_load = max(self.highest_load, *(r.load_pct or 0.0 for r in rows))
        self.last_second = rows[-1].second
        self._states(rows, first_t)

    def _states(self, rows: list[HealthSecond], first_t: float) -> None:
        for r in rows:
            if r.state is not None and r.state != self.last_state:
                begins = float(r.second) if self.last_state else max(r.second, first_t)
                self.state.add(begins if math.isfinite(begins) else r.second, None, r.state)
                self.last_state = r.state

    def columns(self) -> list[Columns]:
        return [*self.series.values(), self.state]


def silent(secs: np.ndarray) -> np.ndarray:
    """Zero points for the seconds without a row between ``secs``: at the end of the first
    and of the last silent second of each gap."""
    gap = np.nonzero(secs[1:] > secs[:-1] + 1)[0]
    first = secs[gap] + 2
    last = secs[gap + 1]
    return np.unique(np.concatenate([first, last[last > first]]))
