"""Compact storage for millions of decoded records: what the frame list, the filter and the
detail pane read.

A ``Record`` object with its fields dict and lists costs about a kilobyte; a million of them
would not fit the 600 MB budget. The store keeps what every row and every filter needs in typed
columns (``array``: 8 bytes or less per value; bus, name, protocol and kind as small integers
into intern tables; every flag code as one bit of a 64-bit mask) and the whole record (fields,
errors, warnings, raw) as JSON in zlib-compressed blocks of ``BLOCK`` records, opened only for
the detail pane, exports and searches. A block is one JSON array, written by one ``orjson`` call
when it is full (one call per record cost more than the rest of storing); until then its
records' details wait as tuples.

One thread appends (the session's), any thread reads: the columns only grow, ``count`` is
published after a batch is complete, and readers look only below it. Block compression swaps
the open block under ``lock``.

A store given ``keep`` holds about that many of the newest records (a live session runs for
hours: ``LIVE_KEEP`` by default): ``trim`` drops the oldest whole blocks once the store holds
a tenth more. A record keeps its index for good (``first`` is the oldest one kept), so the
frame list's marks and the panels' indexes never point at another record. ``trim`` is called
on the thread that reads the columns (the app's, as the frame list takes new records in), so
nothing it reads goes from under it; ``record`` holds ``lock`` for the other threads.
"""

from __future__ import annotations

import threading
import zlib
from array import array
from bisect import bisect_left
from collections.abc import Iterable, Iterator, MutableSequence, Sequence
from typing import TYPE_CHECKING, Any, Final, Generic, TypeVar, overload

import orjson

from decoders.model import FRAME, REQUEST, RESPONSE, Record

from ..model import json_default

if TYPE_CHECKING:
    from ..session.batches import RecordSequence

BLOCK: Final = 256  # records per compressed block
LIVE_KEEP: Final = 1_000_000  # records a live session keeps (about 600 MB at most)
MAX_FLAG_BITS: Final = 63  # bit 63 collects codes beyond the first 63 seen
SUMMARY_INTERN_LIMIT: Final = 200_000  # distinct summaries shared before the table restarts
NONE_DEVICE: Final = -1
NONE_SEQ: Final = -1
NAN: Final = float("nan")
T = TypeVar("T")

# severity of a record: what its colour says
OK: Final = 0
WARNING: Final = 1
ERROR: Final = 2

# direction column
DIRECTIONS: Final = {None: 0, REQUEST: 1, RESPONSE: 2}
DIRECTION_NAMES: Final = (None, REQUEST, RESPONSE)


def _filled(values: Sequence[Any], none: Any) -> Sequence[Any]:
    """``values`` with None replaced by ``none`` (the column's marker for "no value")."""
    return values if None not in values else [none if v is None else v for v in values]


class Column(Generic[T]):
    """One column, indexed by record index: the values of the records dropped from its start
    are gone, the others keep their index (a negative index counts from the end)."""

    __slots__ = ("base", "data")

    def __init__(self, data: MutableSequence[T]) -> None:
        self.data = data
        self.base = 0  # the index of data[0]

    @overload
    def __getitem__(self, i: int) -> T: ...
    @overload
    def __getitem__(self, i: slice) -> MutableSequence[T]: ...
    def __getitem__(self, i: int | slice) -> T | MutableSequence[T]:
        base = self.base
        if isinstance(i, slice):  # of records kept (the filter's start is never below base)
            start = None if i.start is None else max(i.start - base, 0)
            stop = None if i.stop is None else max(i.stop - base, 0)
            return self.data[start:stop]
        if i < 0:
            return self.data[i]
        if i < base:
            raise IndexError(f"record {i} was dropped (the oldest kept is {base})")
        return self.data[i - base]

    def __len__(self) -> int:
        return self.base + len(self.data)

    def extend(self, values: Iterable[T]) -> None:
        self.data.extend(values)

    def index(self, value: T, start: int, stop: int) -> int:
        base = self.base
        return base + self.data.index(value, max(start - base, 0), max(stop - base, 0))

    def drop(self, n: int) -> None:
        """Drop the first ``n`` values kept."""
        del self.data[:n]
        self.base += n


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

    def ids_of(self, names: list[str]) -> list[int]:
        """The ids of ``names`` (new ones numbered in order of first appearance)."""
        ids = self.ids
        for name in dict.fromkeys(names):
            if name not in ids:
                self.id(name)
        return [ids[name] for name in names]

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
    """The records of a session (the newest ``keep`` of them; None: every one), compact; see
    the module doc."""

    def __init__(self, keep: int | None = None) -> None:
        self.keep = keep
        self.lock = threading.RLock()
        self.first = 0  # the oldest record kept (the ones before it were dropped)
        self.count = 0  # records readable (columns are complete below it)
        self.t = Column(array("d"))  # NaN: no time
        self.seq = Column(array("q"))
        self.bus = Column(array("H"))
        self.device = Column(array("i"))  # NONE_DEVICE: none
        self.direction = Column(array("b"))  # DIRECTIONS
        self.name = Column(array("I"))  # manual name, or protocol / kind when a frame has none
        self.protocol = Column(array("B"))
        self.kind = Column(array("B"))
        self.flags = Column(array("Q"))
        self.severity = Column(array("B"))
        self.latency = Column(array("d"))  # NaN: none
        self.pair = Column(array("q"))  # NONE_SEQ: none
        self.summary: Column[str] = Column([])
        self.buses = Interner()
        self.names = Interner()
        self.protocols = Interner()
        self.kinds = Interner()
        self.flag_bits = FlagBits()
        self.t0: float | None = None  # the earliest time seen
        self.t_last: float | None = None  # the latest time seen
        self._summaries: dict[str, str] = {}
        self._blocks: list[bytes] = []
        self._blocks_first = 0  # the block number of _blocks[0]
        self._open: list[tuple[Any, ...]] = []  # the details of the block being filled
        self._cache: dict[int, list[Any]] = {}  # a few decompressed, parsed blocks
        self._seq_sorted = True

    def __len__(self) -> int:
        return self.count

    @property
    def kept(self) -> int:
        """How many records the store holds."""
        return self.count - self.first

    # -- writing (one thread) --------------------------------------------------------------

    def append(self, records: RecordSequence) -> None:
        """Add a batch of records (in stream order), a column at a time (``records.column``:
        from a native batch without making the records; a Python loop with a dozen appends
        per record costs three times as much)."""
        if not records:
            return
        times = records.column("t")
        known: list[float] = [t for t in times if t is not None]
        if known:
            low = min(known)
            if self.t0 is None or low < self.t0:
                self.t0 = low
            top = max(known)
            if self.t_last is None or top > self.t_last:
                self.t_last = top
        self.t.extend(_filled(times, NAN))
        seqs = records.column("seq")
        if self._seq_sorted and ((self.seq and seqs[0] < self.seq[-1]) or seqs != sorted(seqs)):
            self._seq_sorted = False
        self.seq.extend(seqs)
        self.bus.extend(self.buses.ids_of(records.column("bus")))
        self.device.extend(_filled(records.column("device"), NONE_DEVICE))
        directions = DIRECTIONS
        self.direction.extend([directions.get(d, 0) for d in records.column("direction")])
        protocols, kinds = records.column("protocol"), records.column("kind")
        names = [
            n or (p if k == FRAME else k)
            for n, p, k in zip(records.column("name"), protocols, kinds, strict=True)
        ]
        self.name.extend(self.names.ids_of(names))
        self.protocol.extend(self.protocols.ids_of(protocols))
        self.kind.extend(self.kinds.ids_of(kinds))
        mask = self.flag_bits.mask
        flags = records.column("flags")
        self.flags.extend([mask(f) if f else 0 for f in flags])
        errors, warnings = records.column("errors"), records.column("warnings")
        self.severity.extend(
            [ERROR if e else WARNING if w else OK for e, w in zip(errors, warnings, strict=True)]
        )
        self.latency.extend(_filled(records.column("latency_ms"), NAN))
        self.pair.extend(_filled(records.column("pair"), NONE_SEQ))
        summaries = self._summaries
        if len(summaries) >= SUMMARY_INTERN_LIMIT:
            summaries.clear()
        intern = summaries.setdefault
        self.summary.extend([intern(x, x) for x in records.column("summary")])
        details = zip(
            records.column("fields"),
            errors,
            warnings,
            flags,
            [raw.hex() for raw in records.column("raw")],
            records.column("code"),
            records.column("offset"),
            records.column("index"),
            records.column("length"),
            strict=True,
        )
        self._add_details(list(details))
        with self.lock:  # not in the middle of a trim
            self.count = len(self.seq)

    def _add_details(self, details: list[tuple[Any, ...]]) -> None:
        while details:
            room = BLOCK - len(self._open)
            self._open.extend(details[:room])
            details = details[room:]
            if len(self._open) == BLOCK:
                packed = zlib.compress(_dumps(self._open), 1)
                with self.lock:
                    self._blocks.append(packed)
                    self._open = []

    def trim(self, below: int | None = None) -> int:
        """Drop the oldest records beyond ``keep`` (whole blocks, once the store holds a tenth
        more), none from ``below`` on (what the reader has not seen yet); how many were
        dropped. Only on the thread that reads the columns."""
        if self.keep is None or self.kept <= self.keep + max(BLOCK, self.keep // 10):
            return 0
        with self.lock:
            end = self.count - self.keep if below is None else min(self.count - self.keep, below)
            blocks = max(end // BLOCK - self._blocks_first, 0)
            n = blocks * BLOCK
            for column in self._columns():
                column.drop(n)
            del self._blocks[:blocks]
            self._blocks_first += blocks
            self._cache.clear()
            self.first += n
        return n

    def _columns(self) -> list[Column[Any]]:
        return [value for value in vars(self).values() if isinstance(value, Column)]

    # -- reading (any thread) --------------------------------------------------------------

    def record(self, i: int) -> Record:
        """The whole record at index ``i``, as it was decoded (IndexError: not kept)."""
        with self.lock:  # another thread's read is not cut by a trim
            return self._record(i)

    def _record(self, i: int) -> Record:
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
        if not self.first <= i < self.count:
            raise IndexError(i)
        block, pos = divmod(i, BLOCK)
        with self.lock:
            if block - self._blocks_first < len(self._blocks):
                details = self._cache.get(block)
                if details is None:
                    packed = self._blocks[block - self._blocks_first]
                    details = orjson.loads(zlib.decompress(packed))
                    if len(self._cache) >= 8:
                        self._cache.pop(next(iter(self._cache)))
                    self._cache[block] = details
                found: list[Any] = details[pos]
                return found
            waiting = self._open[pos]
        # through JSON, as a stored block gives it back (lists, string keys)
        found = orjson.loads(_dumps([waiting]))[0]
        return found

    def records(self, indices: Iterable[int]) -> Iterator[Record]:
        """The records at ``indices`` that are still kept (an export that runs while a live
        store drops its oldest writes what is left of them)."""
        for i in indices:
            try:
                yield self.record(i)
            except IndexError:
                continue

    def index_of_seq(self, seq: int) -> int | None:
        """The index of the record numbered ``seq``, if kept."""
        first, n = self.first, self.count
        if self._seq_sorted:
            i = bisect_left(self.seq, seq, first, n)
            return i if i < n and self.seq[i] == seq else None
        try:
            return self.seq.index(seq, first, n)  # records of several buses: in time order
        except ValueError:
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
        """The first record kept at or after time ``t`` (records without a time are skipped)."""
        column = self.t
        for k, value in enumerate(column[self.first : self.count]):
            if value >= t:
                return self.first + k
        return None


def _dumps(details: list[tuple[Any, ...]]) -> bytes:
    return orjson.dumps(details, default=json_default, option=orjson.OPT_NON_STR_KEYS)
