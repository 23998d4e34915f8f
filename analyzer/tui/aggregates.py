"""What the side panels show, folded from records as they arrive (on the session's thread):
problems grouped by flag code and device (Wireshark's expert info), latency per command and per
gripper, and every register seen per gripper. ``snapshot()`` copies them for the screen.
"""

from __future__ import annotations

from bisect import bisect_left
from collections import deque
from dataclasses import dataclass, field
from itertools import pairwise
from typing import TYPE_CHECKING, Any, Final

from decoders import flags as F
from decoders.model import FRAME, REQUEST, RESPONSE

if TYPE_CHECKING:
    from ..session.batches import RecordSequence


LATENCY_KEEP: Final = 2000  # latencies kept per key for percentiles (the latest)
HISTOGRAM_BINS: Final = 8
NOT_PROBLEMS: Final = frozenset({F.FOREIGN, F.ESTIMATED_TIME})  # notes, not problems
SERIAL_SKIP: Final = frozenset({"id", "state_text", "fault_text", "position_mm", "data"})

DeviceKey = tuple[str, int]


@dataclass
class ProblemGroup:
    code: str
    bus: str
    device: int | None
    count: int
    first: int  # store index of the first occurrence
    level: str  # "error" or "warning"


@dataclass
class LatencyStats:
    count: int  # the latencies the percentiles are of: the last LATENCY_KEEP at most
    p50: float
    p95: float
    max: float
    histogram: list[int]  # counts in HISTOGRAM_BINS equal bins from 0 to max
    total: int = 0  # every latency seen

    def samples_text(self) -> str:
        """How many latencies the figures are of: "1,234", or "last 2,000 of 15,300"."""
        if self.total > self.count:
            return f"last {self.count:,} of {self.total:,}"
        return f"{self.count:,}"


@dataclass
class RegisterSeen:
    value: Any
    previous: Any = None
    count: int = 1
    first_t: float | None = None
    last_t: float | None = None
    changes: int = 0

    @property
    def rate_hz(self) -> float | None:
        if self.count < 2 or self.first_t is None or self.last_t is None:
            return None
        span = self.last_t - self.first_t
        return (self.count - 1) / span if span > 0 else None


@dataclass
class Snapshot:
    problems: list[ProblemGroup] = field(default_factory=list)
    latency_by_command: dict[str, LatencyStats] = field(default_factory=dict)
    latency_by_device: dict[DeviceKey, LatencyStats] = field(default_factory=dict)
    registers: dict[DeviceKey, dict[str, RegisterSeen]] = field(default_factory=dict)


def latency_stats(values: deque[float] | list[float], total: int = 0) -> LatencyStats | None:
    """Percentiles and a histogram of ``values`` (the last of ``total`` seen)."""
    if not values:
        return None
    ordered = sorted(values)
    n = len(ordered)
    top = ordered[-1]
    if top > 0:  # bin k holds values in [k, k+1) * top / BINS, the last one top too
        edges = [bisect_left(ordered, top * k / HISTOGRAM_BINS) for k in range(1, HISTOGRAM_BINS)]
        bins = [b - a for a, b in pairwise([0, *edges, n])]
    else:
        bins = [n] + [0] * (HISTOGRAM_BINS - 1)
    p95 = ordered[min(n - 1, int(n * 0.95))]
    return LatencyStats(n, ordered[n // 2], p95, top, bins, max(total, n))


class Aggregates:
    """Folds records into the panels' tables; one thread writes (see the module doc)."""

    def __init__(self) -> None:
        self.problems: dict[tuple[str, str, int | None], ProblemGroup] = {}
        self.latency_command: dict[str, deque[float]] = {}
        self.latency_device: dict[DeviceKey, deque[float]] = {}
        self.latency_seen: dict[Any, int] = {}  # per command name and per gripper: every one
        self.registers: dict[DeviceKey, dict[str, RegisterSeen]] = {}
        # percentiles sort up to LATENCY_KEEP values: redone only for the keys that got new ones
        self.stats_command: dict[str, LatencyStats] = {}
        self.stats_device: dict[DeviceKey, LatencyStats] = {}
        self._dirty_command: set[str] = set()
        self._dirty_device: set[DeviceKey] = set()

    def add(self, records: RecordSequence, first_index: int) -> None:
        """Fold a batch in, a column at a time (``records.column``: a native batch makes no
        records); ``first_index``: the store index of its first record."""
        names = ("flags", "kind", "device", "errors", "bus", "latency_ms", "direction", "name")
        rows = zip(*(records.column(n) for n in names), strict=True)
        frames = []  # (index in the batch, bus, device) of the valid frames of a gripper
        protocols: list[str] | None = None
        for k, (flags, kind, device, errors, bus, latency, direction, name) in enumerate(rows):
            if flags:
                self._problems(flags, bool(errors), bus, device, first_index + k)
            if kind != FRAME or device is None or errors:
                continue
            key = (bus, device)
            frames.append((k, key))
            if latency is not None and direction == RESPONSE:
                if not name:  # as the frame list names it: by its protocol
                    protocols = protocols or records.column("protocol")
                    name = protocols[k]
                self._latency(self.latency_command, name, latency)
                self._latency(self.latency_device, key, latency)
                self._dirty_command.add(name)
                self._dirty_device.add(key)
        if frames:
            fields, directions = records.column("fields"), records.column("direction")
            protocols, times = records.column("protocol"), records.column("t")
            for k, key in frames:
                self._registers(fields[k], directions[k], protocols[k], times[k], key)

    def _problems(
        self, flags: list[str], errors: bool, bus: str, device: int | None, index: int
    ) -> None:
        level = "error" if errors else "warning"
        for code in flags:
            if code in NOT_PROBLEMS:
                continue
            k = (code, bus, device)
            group = self.problems.get(k)
            if group is None:
                self.problems[k] = ProblemGroup(code, bus, device, 1, index, level)
            else:
                group.count += 1

    def _latency(self, table: dict[Any, deque[float]], key: Any, value: float) -> None:
        values = table.get(key)
        if values is None:
            values = table[key] = deque(maxlen=LATENCY_KEEP)
        values.append(value)
        seen = self.latency_seen
        seen[key] = seen.get(key, 0) + 1

    def _registers(
        self,
        f: dict[str, Any],
        direction: str | None,
        protocol: str,
        t: float | None,
        key: DeviceKey,
    ) -> None:
        seen: dict[str, Any] = {}
        values = f.get("values")
        if isinstance(values, dict):
            seen.update(values)
        elif direction == REQUEST and isinstance(f.get("name"), str) and "value" in f:
            seen[f["name"]] = f["value"]
        elif protocol == "eg2-serial" and direction == RESPONSE:
            seen.update(
                (k, v)
                for k, v in f.items()
                if k not in SERIAL_SKIP and isinstance(v, int | float | str)
            )
        if not seen:
            return
        table = self.registers.setdefault(key, {})
        for name, value in seen.items():
            reg = table.get(name)
            if reg is None:
                table[name] = RegisterSeen(value, None, 1, t, t)
                continue
            if value != reg.value:
                reg.previous, reg.value = reg.value, value
                reg.changes += 1
            reg.count += 1
            reg.last_t = t if t is not None else reg.last_t

    def snapshot(self) -> Snapshot:
        snap = Snapshot(
            problems=[ProblemGroup(**vars(g)) for g in self.problems.values()],
            registers={
                k: {n: RegisterSeen(**vars(r)) for n, r in table.items()}
                for k, table in self.registers.items()
            },
        )
        self._update_stats(self.latency_command, self.stats_command, self._dirty_command)
        self._update_stats(self.latency_device, self.stats_device, self._dirty_device)
        snap.latency_by_command = dict(self.stats_command)
        snap.latency_by_device = dict(self.stats_device)
        return snap

    def _update_stats(
        self, values: dict[Any, deque[float]], stats: dict[Any, LatencyStats], dirty: set[Any]
    ) -> None:
        for key in dirty:
            found = latency_stats(values[key], self.latency_seen.get(key, 0))
            if found is not None:
                stats[key] = found
        dirty.clear()
