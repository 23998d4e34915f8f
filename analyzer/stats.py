"""Summary statistics over a record stream, in constant memory.

Latency percentiles come from a log-bucketed histogram (1 % relative resolution, as
HdrHistogram does) so that a capture of any length needs the same memory; the maximum is exact.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from decoders.flags import RETRANSMISSION, UNANSWERED
from decoders.model import FRAME, GARBAGE, REQUEST, RESPONSE, TRUNCATED, Record

from .model import SourceEvent

_LOG_STEP = math.log(1.01)


class LatencyHistogram:
    def __init__(self) -> None:
        self.buckets: Counter[int] = Counter()
        self.count = 0
        self.max = 0.0

    def add(self, ms: float, times: int = 1) -> None:
        self.count += times
        if ms > self.max:  # NaN is never the maximum
            self.max = ms
        self.buckets[int(math.log(ms if ms > 1e-6 else 1e-6) / _LOG_STEP)] += times

    def add_many(self, values: list[float]) -> None:
        """``add`` of each value, once (a batch's, in one loop)."""
        buckets, log, top = self.buckets, math.log, self.max
        for ms in values:
            if ms > top:  # NaN is never the maximum, as in ``add``
                top = ms
            buckets[int(log(ms if ms > 1e-6 else 1e-6) / _LOG_STEP)] += 1
        self.count += len(values)
        self.max = top

    def add_counted(self, counted: Counter[float]) -> None:
        """``add(ms, n)`` of each value and count: latencies repeat (their times have a
        resolution), so a batch's are counted first, in C, and each value is bucketed once."""
        buckets, log, top = self.buckets, math.log, self.max
        for ms, n in counted.items():
            if ms > top:  # NaN is never the maximum, as in ``add``
                top = ms
            buckets[int(log(ms if ms > 1e-6 else 1e-6) / _LOG_STEP)] += n
        self.count += sum(counted.values())
        self.max = top

    def percentile(self, p: float) -> float | None:
        if not self.count:
            return None
        rank = p / 100.0 * self.count
        seen = 0
        for bucket in sorted(self.buckets):
            seen += self.buckets[bucket]
            if seen >= rank:
                return min(self.max, math.exp((bucket + 0.5) * _LOG_STEP))
        return self.max

    def merge(self, other: LatencyHistogram) -> None:
        self.buckets.update(other.buckets)
        self.count += other.count
        self.max = max(self.max, other.max)

    def summary(self) -> dict[str, float | None]:
        def r(x: float | None) -> float | None:
            return None if x is None else round(x, 3)

        return {
            "p50_ms": r(self.percentile(50)),
            "p95_ms": r(self.percentile(95)),
            "max_ms": r(self.max) if self.count else None,
        }


COUNT_NAMES = ("requests", "responses", "unanswered", "retransmissions", "errors", "warnings")


@dataclass
class Counts:
    requests: int = 0
    responses: int = 0
    unanswered: int = 0
    retransmissions: int = 0
    errors: int = 0
    warnings: int = 0
    latency: LatencyHistogram = field(default_factory=LatencyHistogram)

    def add_group(self, direction: str | None, flags: tuple[str, ...], errors: bool,
                  warnings: bool, n: int) -> None:  # fmt: skip
        """``n`` frames alike (``StatsGroup``): their direction, flags, errors and warnings."""
        if direction == REQUEST:
            self.requests += n
            if UNANSWERED in flags:
                self.unanswered += n
            if RETRANSMISSION in flags:
                self.retransmissions += n
        elif direction == RESPONSE:
            self.responses += n
        if errors:
            self.errors += n
        if warnings:
            self.warnings += n

    def merge(self, other: Counts) -> None:
        for name in COUNT_NAMES:
            setattr(self, name, getattr(self, name) + getattr(other, name))
        self.latency.merge(other.latency)

    def as_dict(self) -> dict[str, Any]:
        return {
            "requests": self.requests,
            "responses": self.responses,
            "unanswered": self.unanswered,
            "retransmissions": self.retransmissions,
            "errors": self.errors,
            "warnings": self.warnings,
            **self.latency.summary(),
        }


class CaptureStats:
    def __init__(self) -> None:
        self.records = 0
        self.frames = 0
        self.valid = 0
        self.bytes_garbage = 0
        self.truncated = 0
        self.by_protocol: Counter[str] = Counter()
        self.devices: dict[tuple[str, str, int], Counts] = {}
        self.commands: dict[tuple[str, str, int, str], Counts] = {}
        self.flags: Counter[str] = Counter()
        self.events: Counter[str] = Counter()
        self.unanswered_ids: dict[tuple[str, str], set[int]] = {}
        self.first_t: float | None = None
        self.last_t: float | None = None

    def totals(self) -> Counts:
        """The devices' counts added up, latency included (the Devices table's total)."""
        total = Counts()
        for counts in self.devices.values():
            total.merge(counts)
        return total

    def add_groups(self, found: StatsGroups) -> None:
        """A batch's records, grouped (``stats_groups``, or a native ``RecordBatch``'s)."""
        groups, latencies, first, last = found
        if first is not None and (self.first_t is None or first < self.first_t):
            self.first_t = first
        if last is not None and (self.last_t is None or last > self.last_t):
            self.last_t = last
        for group in groups:
            protocol, kind, bus, device, command, direction, flags, errors, warns, n, size = group
            self.records += n
            self.by_protocol[protocol] += n
            if kind == GARBAGE:
                self.bytes_garbage += size
            elif kind == TRUNCATED:
                self.truncated += n
            elif kind == FRAME:
                self.frames += n
                if not errors:
                    self.valid += n
            for flag in flags:
                self.flags[flag] += n
            if bus is None or device is None:
                continue
            self._counts(self.devices, (bus, protocol, device)).add_group(
                direction, flags, errors, warns, n
            )
            self._counts(self.commands, (bus, protocol, device, command)).add_group(
                direction, flags, errors, warns, n
            )
            if direction == REQUEST and UNANSWERED in flags:
                self.unanswered_ids.setdefault((bus, protocol), set()).add(device)
        for bus, protocol, device, command, values in latencies:
            counted = Counter(values)
            self.devices[(bus, protocol, device)].latency.add_counted(counted)
            self.commands[(bus, protocol, device, command)].latency.add_counted(counted)

    @staticmethod
    def _counts(table: dict[Any, Counts], key: Any) -> Counts:
        counts = table.get(key)
        if counts is None:
            counts = table[key] = Counts()
        return counts

    def add_event(self, event: SourceEvent) -> None:
        self.events[event.kind] += event.count

    def scans(self) -> list[str]:
        """Unanswered requests to many different IDs: a host scanning for devices."""
        notes = []
        for (bus, protocol), ids in sorted(self.unanswered_ids.items()):
            if len(ids) >= 5:
                notes.append(
                    f"{bus} {protocol}: unanswered requests to {len(ids)} different IDs "
                    f"({min(ids)}-{max(ids)}): looks like an ID scan, not a fault"
                )
        return notes

    def as_dict(self) -> dict[str, Any]:
        duration = None
        if self.first_t is not None and self.last_t is not None:
            duration = round(self.last_t - self.first_t, 6)
        return {
            "records": self.records,
            "frames": self.frames,
            "valid_frames": self.valid,
            "garbage_bytes": self.bytes_garbage,
            "truncated": self.truncated,
            "duration_s": duration,
            "protocols": dict(self.by_protocol),
            "devices": [
                {"bus": b, "protocol": p, "device": d, **c.as_dict()}
                for (b, p, d), c in sorted(self.devices.items())
            ],
            "commands": [
                {"bus": b, "protocol": p, "device": d, "name": n, **c.as_dict()}
                for (b, p, d, n), c in sorted(self.commands.items())
            ],
            "flags": dict(self.flags.most_common()),
            "events": dict(self.events.most_common()),
            "notes": self.scans(),
        }


#: records alike for the counts (``stats_groups``): protocol, kind; for a device's frame its bus,
#: device, command (its name, or "code N") and direction, else four Nones; flags; whether it has
#: errors, and warnings; how many records, and the bytes they span (``length``)
StatsGroup = tuple[
    str, str, str | None, int | None, str | None, str | None, tuple[str, ...], bool, bool, int, int
]
#: a batch's groups in the order each first appears; the response latencies per device and
#: command, in record order; the earliest and latest time (NaN left out)
StatsGroups = tuple[
    list[StatsGroup], list[tuple[str, str, int, str, list[float]]], float | None, float | None
]


def stats_groups(records: Iterable[Record]) -> StatsGroups:
    """The records grouped for ``CaptureStats.add_groups``: what it counts of each record, a
    group at a time (the native ``RecordBatch.stats_groups`` gives the same, with no Python
    object per record)."""
    groups: dict[tuple[Any, ...], list[int]] = {}
    latencies: dict[tuple[str, str, int, str], list[float]] = {}
    first: float | None = None
    last: float | None = None
    for rec in records:
        t = rec.t
        if t is not None and t == t:  # NaN is no time
            if first is None or t < first:
                first = t
            if last is None or t > last:
                last = t
        device: tuple[Any, ...] = (None, None, None, None)
        if rec.kind == FRAME and rec.device is not None:
            command = rec.name or f"code {rec.code}"
            device = (rec.bus, rec.device, command, rec.direction)
            if rec.direction == RESPONSE and rec.latency_ms is not None:
                key = (rec.bus, rec.protocol, rec.device, command)
                latencies.setdefault(key, []).append(rec.latency_ms)
        group = (rec.protocol, rec.kind, *device, tuple(rec.flags), bool(rec.errors),
                 bool(rec.warnings))  # fmt: skip
        tally = groups.get(group)
        if tally is None:
            groups[group] = [1, rec.length]
        else:
            tally[0] += 1
            tally[1] += rec.length
    rows = [(*key, n, length) for key, (n, length) in groups.items()]
    return rows, [(*key, values) for key, values in latencies.items()], first, last
