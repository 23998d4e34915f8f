"""Compact storage for millions of decoded records: what the frame list, the filter and the
detail pane read.

A ``Record`` object with its fields dict and lists costs about a kilobyte; a million of them
would not fit the 600 MB budget. The store keeps what every row and every filter needs in typed
columns (``array``: 8 bytes or less per value; bus, name, protocol and kind as small integers
into intern tables; every flag code as one bit of a 64-bit mask) and the whole record (fields,
errors, warnings, raw) as JSON in zlib-compressed blocks of ``BLOCK`` records, opened only for
the detail pane, exports and searches.

One thread appends (the session's), any thread reads: the columns only grow, ``count`` is
published after a batch is complete, and readers look only below it. Block compression swaps
the open block under ``lock``.
"""

from __future__ import annotations

import threading
import zlib
from array import array
from bisect import bisect_left
from collections.abc import Iterable, Iterator
from itertools import pairwise
from typing import Any, Final

import orjson

from decoders.model import FRAME, REQUEST, RESPONSE, Record

from ..model import json_default

BLOCK: Final = 256  # records per compressed block
MAX_FLAG_BITS: Final = 63  # bit 63 collects codes beyond the first 63 seen
SUMMARY_INTERN_LIMIT: Final = 200_000  # distinct summaries shared before the table restarts
NONE_DEVICE: Final = -1
NONE_SEQ: Final = -1
NAN: Final = float("nan")

# severity of a record: what its colour says
OK: Final = 0
WARNING: Final = 1
ERROR: Final = 2

# direction column
DIRECTIONS: Final = {None: 0, REQUEST: 1, RESPONSE: 2}
DIRECTION_NAMES: Final = (None, REQUEST, RESPONSE)


class Interner:
    """Strings to small integers and back (bus names, manual names, protocols, kinds)."""

    def __init__(self) -> None:
        self.ids: dict[str, int] = {}
        self.names: list[str] = []

    def id(self, name: str) -> int:
        found = self.ids.get(name)
        if found is None:
            found = self.ids[name] = len(self.names)
            self.names.append(name)
        return found

    def get(self, name: str) -> int | None:
        return self.ids.get(name)

    def __getitem__(self, i: int) -> str:
        return self.names[i]

    def __len__(self) -> int:
        return len(self.names)


class FlagBits:
    """Flag codes to bits of a mask, in the order they are first seen."""

    def __init__(self) -> None:
        self.bits: dict[str, int] = {}

    def bit(self, code: str) -> int:
        found = self.bits.get(code)
        if found is None:
            found = self.bits[code] = 1 << min(len(self.bits), MAX_FLAG_BITS)
        return found

    def mask(self, codes: Iterable[str]) -> int:
        m = 0
        for code in codes:
            m |= self.bit(code)
        return m

    def get(self, code: str) -> int:
        """The bit of ``code``, 0 if it was never seen (matches nothing)."""
        return self.bits.get(code, 0)

    def codes(self, mask: int) -> list[str]:
        return [code for code, bit in self.bits.items() if mask & bit]


class RecordStore:
    """Every record of a session, compact; see the module doc."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.count = 0  # records readable (columns are complete below it)
        self.t = array("d")  # NaN: no time
        self.seq = array("q")
        self.bus = array("H")
        self.device = array("i")  # NONE_DEVICE: none
        self.direction = array("b")  # DIRECTIONS
        self.name = array("I")  # manual name, or protocol / kind when a frame has none
        self.protocol = array("B")
        self.kind = array("B")
        self.flags = array("Q")
        self.severity = array("B")
        self.latency = array("d")  # NaN: none
        self.pair = array("q")  # NONE_SEQ: none
        self.summary: list[str] = []
        self.buses = Interner()
        self.names = Interner()
        self.protocols = Interner()
        self.kinds = Interner()
        self.flag_bits = FlagBits()
        self.t0: float | None = None  # the first time seen
        self.t_last: float | None = None  # the latest time seen
        self._summaries: dict[str, str] = {}
        self._blocks: list[bytes] = []
        self._open: list[bytes] = []
        self._cache: dict[int, list[bytes]] = {}  # a few decompressed blocks
        self._seq_sorted = True

    def __len__(self) -> int:
        return self.count

    # -- writing (one thread) --------------------------------------------------------------

    def append(self, records: list[Record]) -> None:
        """Add a batch of records (in stream order). One comprehension per column: a Python
        loop with a dozen appends per record costs three times as much."""
        if not records:
            return
        times = [r.t for r in records]
        known = [t for t in times if t is not None]
        if known:
            if self.t0 is None:
                self.t0 = known[0]
            top = max(known)
            if self.t_last is None or top > self.t_last:
                self.t_last = top
        self.t.extend([NAN if t is None else t for t in times])
        seqs = [r.seq for r in records]
        if self._seq_sorted and (
            (self.seq and seqs[0] < self.seq[-1]) or any(a > b for a, b in pairwise(seqs))
        ):
            self._seq_sorted = False
        self.seq.extend(seqs)
        bus_id, name_id, proto_id, kind_id = (
            self.buses.id,
            self.names.id,
            self.protocols.id,
            self.kinds.id,
        )
        self.bus.extend([bus_id(r.bus) for r in records])
        self.device.extend([NONE_DEVICE if r.device is None else r.device for r in records])
        directions = DIRECTIONS
        self.direction.extend([directions.get(r.direction, 0) for r in records])
        self.name.extend(
            [name_id(r.name or (r.protocol if r.kind == FRAME else r.kind)) for r in records]
        )
        self.protocol.extend([proto_id(r.protocol) for r in records])
        self.kind.extend([kind_id(r.kind) for r in records])
        mask = self.flag_bits.mask
        self.flags.extend([mask(r.flags) if r.flags else 0 for r in records])
        self.severity.extend(
            [ERROR if r.errors else WARNING if r.warnings else OK for r in records]
        )
        self.latency.extend([NAN if r.latency_ms is None else r.latency_ms for r in records])
        self.pair.extend([NONE_SEQ if r.pair is None else r.pair for r in records])
        summaries = self._summaries
        if len(summaries) >= SUMMARY_INTERN_LIMIT:
            summaries.clear()
        intern = summaries.setdefault
        self.summary.extend([intern(r.summary, r.summary) for r in records])
        dumps, opts = orjson.dumps, orjson.OPT_NON_STR_KEYS
        self._add_lines(
            [
                dumps(
                    (
                        r.fields,
                        r.errors,
                        r.warnings,
                        r.flags,
                        r.raw.hex(),
                        r.code,
                        r.offset,
                        r.index,
                        r.length,
                    ),
                    default=json_default,
                    option=opts,
                )
                for r in records
            ]
        )
        self.count = len(self.seq)

    def _add_lines(self, lines: list[bytes]) -> None:
        while lines:
            room = BLOCK - len(self._open)
            self._open.extend(lines[:room])
            lines = lines[room:]
            if len(self._open) == BLOCK:
                packed = zlib.compress(b"\n".join(self._open), 1)
                with self.lock:
                    self._blocks.append(packed)
                    self._open = []

    # -- reading (any thread) --------------------------------------------------------------

    def record(self, i: int) -> Record:
        """The whole record at index ``i``, as it was decoded."""
        fields, errors, warnings, flags, raw, code, offset, index, length = self._detail(i)
        data = bytes.fromhex(raw)
        return Record(
            t=self.time(i),
            bus=self.bus_of(i),
            protocol=self.protocols[self.protocol[i]],
            kind=self.kinds[self.kind[i]],
            length=length,
            raw=data,
            offset=offset,
            index=index,
            direction=DIRECTION_NAMES[self.direction[i]],
            device=self.device_of(i),
            code=code,
            name=self._name_or_none(i),
            fields=fields,
            errors=errors,
            warnings=warnings,
            summary=self.summary[i],
            seq=self.seq[i],
            pair=self.pair_of(i),
            latency_ms=self.latency_ms(i),
            flags=flags,
        )

    def _name_or_none(self, i: int) -> str | None:
        # frames without a manual name were stored under their protocol, others their kind
        name = self.name_of(i)
        kind = self.kinds[self.kind[i]]
        fallback = self.protocols[self.protocol[i]] if kind == FRAME else kind
        return None if name == fallback else name

    def _detail(self, i: int) -> list[Any]:
        if not 0 <= i < self.count:
            raise IndexError(i)
        block, pos = divmod(i, BLOCK)
        with self.lock:
            if block < len(self._blocks):
                lines = self._cache.get(block)
                if lines is None:
                    lines = zlib.decompress(self._blocks[block]).split(b"\n")
                    if len(self._cache) >= 8:
                        self._cache.pop(next(iter(self._cache)))
                    self._cache[block] = lines
                line = lines[pos]
            else:
                line = self._open[pos]
        found: list[Any] = orjson.loads(line)
        return found

    def records(self, indices: Iterable[int]) -> Iterator[Record]:
        for i in indices:
            yield self.record(i)

    def index_of_seq(self, seq: int) -> int | None:
        """The index of the record numbered ``seq``, if stored."""
        n = self.count
        if self._seq_sorted:
            i = bisect_left(self.seq, seq, 0, n)
            return i if i < n and self.seq[i] == seq else None
        for i in range(n):
            if self.seq[i] == seq:
                return i
        return None

    def time(self, i: int) -> float | None:
        t = self.t[i]
        return None if t != t else t

    def latency_ms(self, i: int) -> float | None:
        v = self.latency[i]
        return None if v != v else v

    def device_of(self, i: int) -> int | None:
        d = self.device[i]
        return None if d == NONE_DEVICE else d

    def pair_of(self, i: int) -> int | None:
        p = self.pair[i]
        return None if p == NONE_SEQ else p

    def name_of(self, i: int) -> str:
        return self.names[self.name[i]]

    def bus_of(self, i: int) -> str:
        return self.buses[self.bus[i]]

    def flag_codes(self, i: int) -> list[str]:
        return self.flag_bits.codes(self.flags[i])

    def first_index_at_or_after(self, t: float) -> int | None:
        """The first record at or after time ``t`` (records without a time are skipped)."""
        column, n = self.t, self.count
        for i in range(n):
            if column[i] >= t:
                return i
        return None
