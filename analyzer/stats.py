"""Summary statistics over a record stream, in constant memory.

Latency percentiles come from a log-bucketed histogram (1 % relative resolution, as
HdrHistogram does) so that a capture of any length needs the same memory; the maximum is exact.
"""

from __future__ import annotations

import math
from collections import Counter
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
        self.max = max(self.max, ms)
        self.buckets[int(math.log(max(ms, 1e-6)) / _LOG_STEP)] += times

    def add_many(self, values: list[float]) -> None:
        """``add`` of each value, once (a batch's, in one loop)."""
        buckets, log, top = self.buckets, math.log, self.max
        for ms in values:
            if ms > top:
                top = ms
            buckets[int(log(ms if ms > 1e-6 else 1e-6) / _LOG_STEP)] += 1
        self.count += len(values)
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

    def add(self, rec: Record) -> None:
        if rec.direction == REQUEST:
            self.requests += 1
            flags = rec.flags
            if UNANSWERED in flags:
                self.unanswered += 1
            if RETRANSMISSION in flags:
                self.retransmissions += 1
        elif rec.direction == RESPONSE:
            self.responses += 1
            if rec.latency_ms is not None:
                self.latency.add(rec.latency_ms)
        if rec.errors:
            self.errors += 1
        if rec.warnings:
            self.warnings += 1

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

    def add(self, rec: Record) -> None:
        self.records += 1
        t = rec.t
        if t is not None:  # the span of the capture: records of several buses come per bus
            if self.first_t is None or t < self.first_t:
                self.first_t = t
            if self.last_t is None or t > self.last_t:
                self.last_t = t
        self.by_protocol[rec.protocol] += 1
        if rec.kind == GARBAGE:
            self.bytes_garbage += rec.length
        elif rec.kind == TRUNCATED:
            self.truncated += 1
        elif rec.kind == FRAME:
            self.frames += 1
            if not rec.errors:
                self.valid += 1
        if rec.flags:
            self.flags.update(rec.flags)
        if rec.device is None or rec.kind != FRAME:
            return
        dev_key = (rec.bus, rec.protocol, rec.device)
        counts = self.devices.get(dev_key)
        if counts is None:
            counts = self.devices[dev_key] = Counts()
        counts.add(rec)
        cmd_key = (*dev_key, rec.name or f"code {rec.code}")
        cmd = self.commands.get(cmd_key)
        if cmd is None:
            cmd = self.commands[cmd_key] = Counts()
        cmd.add(rec)
        if rec.direction == REQUEST and UNANSWERED in rec.flags:
            self.unanswered_ids.setdefault((rec.bus, rec.protocol), set()).add(rec.device)

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
