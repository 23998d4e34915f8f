"""The bus health a plot holds, read back from its .rrd, held against the figures ``stats``
reports for the same capture (``HealthListener.buses()``, the JSON's ``buses``): the frames and
errors of every second add up to the bus's totals, the loads of its seconds to its bits, and the
p95 and max over the seconds its span covers whole are ``load_pct``'s (docs/contracts.md, "Bus
health")."""

from __future__ import annotations

import math
from typing import Any

from rrd_helpers import Rrd


def per_second(rrd: Rrd, bus: str, entity: str) -> dict[int, float]:
    """The value of each second of ``/<bus>/health/<entity>``: a point sits at the end of its
    second (the last, partial one at the bus's last record, inside its second)."""
    e = rrd[f"/{bus}/health/{entity}"]
    out: dict[int, float] = {}
    for t_ns, value in zip(e.capture_time, e.values, strict=True):
        assert t_ns is not None and e.frame == [None] * len(e.frame)  # capture_time only
        second = (t_ns - 1) // 1_000_000_000
        assert second not in out, f"{bus} {entity}: two points in second {second}"
        out[second] = value
    return out


def last_point_s(rrd: Rrd, bus: str) -> float:
    times = rrd[f"/{bus}/health/frames_per_s"].capture_time
    return max(t for t in times if t is not None) / 1e9


def check_bus_health(rrd: Rrd, figures: dict[str, Any]) -> None:
    """One bus's plotted seconds against its ``stats`` figures."""
    bus = figures["bus"]
    frames = per_second(rrd, bus, "frames_per_s")
    assert sum(frames.values()) == figures["frames"], bus
    assert sum(per_second(rrd, bus, "errors_per_s").values()) == figures["error_frames"]["total"]
    loads = per_second(rrd, bus, "load_pct")
    assert loads.keys() == frames.keys(), bus
    rate = figures.get("bitrate") or figures["baud"]
    rounding = 0.0005 / 100 * rate * len(loads)  # each second's load is rounded to 0.001 %
    assert abs(sum(loads.values()) * rate / 100 - figures["bits"]) <= rounding + 1e-6, bus
    end = last_point_s(rrd, bus)
    start = end - figures["duration_s"]
    whole = range(math.ceil(start), math.floor(end))
    if not whole:
        return  # no whole second: stats gives the mean for p95 and max
    covered = sorted(loads.get(s, 0.0) for s in whole)
    rank = max(1, math.ceil(0.95 * len(covered)))
    assert covered[-1] == figures["load_pct"]["max"], bus
    assert covered[rank - 1] == figures["load_pct"]["p95"], bus
