"""What a plot's .rrd must hold of a capture's grip cycles and bus health, read back and held
against ``eg2scope cycles --format jsonl`` and ``stats --format json`` of the same capture
(docs/rerun.md, docs/contracts.md).

- Cycles: per gripper, the lane ``/<bus>/<device>/cycles`` has one row per cycle at its command
  (``start_t``, ``start_seq``) named by its outcome (``slip`` for a grip that slipped), and a gap
  (an empty state) at its end unless the gripper's next cycle begins there; the log beside it a
  line at the command with the cycle's figures and one at its end, at the outcome's level.
- Health: the frames and errors of every second add up to the bus's totals, the loads of its
  seconds to its bits, and the p95 and max over the seconds its span covers whole are
  ``load_pct``'s.
"""

from __future__ import annotations

import math
from typing import Any

from rrd_helpers import Rrd

# the outcome -> the log's level (docs/rerun.md: INFO a good end, WARN a missed part, a slip or a
# stop, ERROR a fault, refusal or no answer, DEBUG an end not seen)
LEVELS = {
    "gripped": "INFO", "opened": "INFO", "positioned": "INFO",
    "closed_empty": "WARN", "slip": "WARN", "stopped": "WARN",
    "faulted": "ERROR", "refused": "ERROR", "unanswered": "ERROR",
    "unfinished": "DEBUG", "unknown": "DEBUG",
}  # fmt: skip
# colours the contract names (0xRRGGBBAA)
GREEN, AMBER, RED, GREY = 0x2CA02CFF, 0xFFB000FF, 0xE3000BFF, 0x8C8C8CFF


def ns(t: float | None) -> int | None:
    """Seconds to the nanoseconds a capture_time holds: to the nanosecond the float gives (an
    epoch float times 1e9 is off by a few hundred ns)."""
    if t is None:
        return None
    whole = math.floor(t)
    return whole * 1_000_000_000 + round((t - whole) * 1e9)


def shown_as(c: dict[str, Any]) -> str:
    """The lane's name of a cycle: its outcome, ``slip`` for a grip that slipped."""
    return "slip" if c["outcome"] == "gripped" and "slip" in c["warnings"] else c["outcome"]


def lane_rows(rrd: Rrd) -> dict[tuple[str, int], list[tuple[int | None, int | None, str]]]:
    """Each gripper's cycle lane: (frame, capture_time ns, state) in frame order."""
    out = {}
    for path, e in rrd.entities.items():
        parts = path.split("/")
        if len(parts) == 4 and parts[3] == "cycles" and e.values:
            out[(parts[1], int(parts[2]))] = [(f, t, v) for t, f, v in e.rows()]
    return out


def plotted_cycles(rrd: Rrd) -> list[dict[str, Any]]:
    """The cycles a plot shows: (bus, device, start_seq, start_t ns, shown as, the log's line
    at the command and its level), in the order they began per gripper."""
    out = []
    for (bus, device), rows in lane_rows(rrd).items():
        log = rrd[f"/{bus}/{device}/cycles/log"]
        lines = sorted(
            (f, text, level)
            for f, text, level in zip(log.frame, log.values, log.levels, strict=True)
            if not text.startswith("end of cycle")
        )
        starts = [(f, t, v) for f, t, v in rows if v]
        assert [f for f, _, _ in starts] == [f for f, _, _ in lines], (bus, device)
        for (f, t, v), (_, text, level) in zip(starts, lines, strict=True):
            out.append({"bus": bus, "device": device, "start_seq": f, "start_t": t,
                        "shown": v, "text": text, "level": level})  # fmt: skip
    return out


def check_cycles(
    rrd: Rrd, cycles: list[dict[str, Any]], slack_ns: int = 0, live: bool = False
) -> None:
    """The plot's lanes and logs hold exactly ``cycles`` (``cycles --format jsonl``): the same
    frames and outcomes, at the same times. ``live``: a live session's plot against its
    recording's replay, which numbers the records its own way (frames not compared) and times
    a serial frame within ``slack_ns`` of the live one."""
    lanes = lane_rows(rrd)
    assert set(lanes) == {(c["bus"], c["device"]) for c in cycles}
    for key, rows in lanes.items():
        mine = sorted((c for c in cycles if (c["bus"], c["device"]) == key),
                      key=lambda c: c["start_seq"])  # fmt: skip
        starts = {c["start_seq"] for c in mine}
        want = [(c["start_seq"], ns(c["start_t"]), shown_as(c)) for c in mine]
        want += [(c["end_seq"], ns(c["end_t"]), "") for c in mine if c["end_seq"] not in starts]
        got, want = sorted(rows, key=_order), sorted(want, key=_order)
        seen = [v for _, _, v in got] if live else [(f, v) for f, _, v in got]
        assert seen == ([v for _, _, v in want] if live else [(f, v) for f, _, v in want]), key
        assert all(_near(t, u, slack_ns) for (_, t, _), (_, u, _) in zip(got, want, strict=True))
        _check_log(rrd, key, mine, slack_ns, live)
    static = next(iter(lanes)) if lanes else None
    if static is not None:
        config = rrd[f"/{static[0]}/{static[1]}/cycles"].static
        colors = dict(zip(config["StateConfiguration:values"][0],
                          config["StateConfiguration:colors"][0], strict=True))  # fmt: skip
        assert (colors["gripped"], colors["closed_empty"]) == (GREEN, AMBER)
        assert (colors["faulted"], colors["unfinished"]) == (RED, GREY)


def _near(t: int | None, u: int | None, slack_ns: int) -> bool:
    return t == u if t is None or u is None else abs(t - u) <= slack_ns


def _order(row: tuple[int | None, int | None, str]) -> tuple[int, str]:
    return (row[0] if row[0] is not None else -1, row[2])


def _check_log(
    rrd: Rrd, key: tuple[str, int], mine: list[dict[str, Any]], slack_ns: int, live: bool
) -> None:
    """A line at each command with the cycle's figures, one at its end; the outcome's level."""
    log = rrd[f"/{key[0]}/{key[1]}/cycles/log"]
    rows = sorted(zip(log.frame, log.capture_time, log.values, log.levels, strict=True),
                  key=lambda r: (r[0], r[2].startswith("end")))  # fmt: skip
    want = []
    for c in mine:
        level = LEVELS[shown_as(c)]
        want += [(c["start_seq"], ns(c["start_t"]), c, level, False),
                 (c["end_seq"], ns(c["end_t"]), c, level, True)]  # fmt: skip
    want.sort(key=lambda w: (w[0], w[4]))
    assert len(rows) == len(want), key
    for (frame, t, text, level), (seq, t_want, c, level_want, end) in zip(rows, want, strict=True):
        assert level == level_want and _near(t, t_want, slack_ns), (key, text)
        assert live or frame == seq, (key, text)
        if end:
            assert text.startswith("end of cycle: ") and c["command"] in text, text
            continue
        assert text.startswith(f"{c['command']}: "), text
        figures = [] if live else [f"frames {c['start_seq']}-{c['end_seq']}"]
        if c["width_mm"] is not None:
            figures.append(f"width {c['width_mm']} mm")
        if c["force_peak"] is not None:
            figures.append(f"force peak {c['force_peak']}")
        if c["time_to_contact_ms"] is not None and not slack_ns:  # (times: within the slack)
            figures.append(f"contact {c['time_to_contact_ms']:.1f} ms")
        assert all(f in text for f in figures), (text, figures)


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
