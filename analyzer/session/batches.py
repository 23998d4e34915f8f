"""What listeners are handed: records and state samples as sequences with bulk methods, one
kind per engine (the engine is chosen here, ``session_engine``).

A session on CAN input with the native core built decodes with ``_native.CanStage`` and tracks
with ``_native.Tracker``; the same records and samples as ``stage.Decoding`` and
``tracker.Tracker`` (tests/native/test_live_native.py and test_tracker_native.py require it)
come as a ``RecordBatch`` and a ``SampleBatch``, whose items become Python objects only when
read. The Python engine hands out a ``RecordSequence`` and a ``SampleSequence``: lists with the
same bulk methods (``column``, ``messages``, ``problems``, ``take``, ``series``, ...), the
reference the native ones are tested against (tests/analyzer/test_sequences.py). Listeners
call the methods, so a listener that writes JSON (the recorder) makes no object per frame on the
native path and the same bytes on the Python one.

A session on one byte stream (a raw serial or Modbus dump replayed) decodes with
``_native.ByteStage`` and tracks with the native ``Tracker`` in the same way. Several byte
streams (recordings, live taps) keep the Python decoders: their records are merged by time, they
are timed per byte and ended by idle gaps, and a serial line carries a fraction of a CAN bus's
frames.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from operator import attrgetter
from typing import Any, Final, Protocol

import orjson

from decoders.model import CanFrame, Record

from ..model import StateSample, json_default
from ..stats import StatsGroups, stats_groups
from .engine import ENGINES, _native
from .stage import Decoding
from .tracker import Tracker


class SessionDecoding(Protocol):
    """What a session asks of its decoding (``PythonDecoding``, ``NativeCanDecoding`` or
    ``NativeByteDecoding``): records
    as ``RecordSequence``s, or as the native core's ``RecordBatch``es, which behave alike where
    the session uses them (``len``, iteration, indexing, ``+=`` of another, the bulk methods)."""

    def feed_items(self, items: list[Any]) -> RecordSequence: ...
    def tick(self, now: float) -> RecordSequence: ...
    def gap(self, bus: str) -> RecordSequence: ...
    def cut_off(self, bus: str) -> RecordSequence: ...
    def finish(self) -> RecordSequence: ...
    def stop(self) -> RecordSequence: ...
    def set_protocol(self, bus: str, protocol: str) -> None: ...


def native_session_available() -> bool:
    """The native core is built (then it is complete: tests/native_core.py lists what the
    product calls on it)."""
    return _native is not None


def native_input(
    kind: str,
    positional: bool,
    per_bus: dict[str, str] | None = None,
    byte_time_s: dict[str, float] | None = None,
) -> bool:
    """Whether the native core decodes a session on this input: CAN, or one byte stream (a
    single-stream capture: a raw dump) with no protocols named per bus and no byte times."""
    one_stream = kind == "bytes" and positional and not per_bus and not byte_time_s
    return kind == "can" or one_stream


def session_engine(
    engine: str,
    kind: str,
    positional: bool,
    protocol: str | None = None,
    per_bus: dict[str, str] | None = None,
    byte_time_s: dict[str, float] | None = None,
) -> tuple[SessionDecoding, Any]:
    """The decoding and tracker of a session whose source gives ``kind`` input ("can", "bytes"
    or "mixed"; ``positional``: one stream, a single-stream capture): the native core's for CAN
    input and for one byte stream when it is built (``engine`` "auto") or asked for ("native":
    ValueError where it cannot be used), else the Python ones."""
    if engine not in ENGINES:
        raise ValueError(f"unknown engine {engine!r}; choose from {', '.join(ENGINES)}")
    native = native_input(kind, positional, per_bus, byte_time_s) and native_session_available()
    if engine == "native" and not native:
        why = (
            "it is not built"
            if not native_session_available()
            else "it decodes CAN input and single byte streams (raw dumps), not this"
        )
        raise ValueError(f"the native engine cannot decode this session: {why}")
    if native and engine != "python":
        tracker = _native.Tracker()  # type: ignore[union-attr]
        if kind == "can":
            return NativeCanDecoding(positional), tracker
        return NativeByteDecoding(protocol), tracker
    decoding = PythonDecoding(protocol, per_bus, positional_seq=positional, byte_time_s=byte_time_s)
    return decoding, PythonTracker()


class PythonDecoding(Decoding):
    """``pipeline.Decoding`` handing out its records as ``RecordSequence``s, the Python kind of
    what the native ``CanStage`` hands out (``RecordBatch``es)."""

    def feed_items(self, items: list[Any]) -> RecordSequence:
        return RecordSequence(super().feed_items(items))

    def tick(self, now: float) -> RecordSequence:
        return RecordSequence(super().tick(now))

    def gap(self, bus: str) -> RecordSequence:
        return RecordSequence(super().gap(bus))

    def cut_off(self, bus: str) -> RecordSequence:
        return RecordSequence(super().cut_off(bus))

    def finish(self) -> RecordSequence:
        return RecordSequence(super().finish())

    def stop(self) -> RecordSequence:
        return RecordSequence(super().stop())


class PythonTracker(Tracker):
    """``tracker.Tracker`` handing out its samples as a ``SampleSequence``, the Python kind of
    what the native ``Tracker`` hands out (``SampleBatch``es)."""

    def update_many(self, records: list[Record]) -> SampleSequence:
        return SampleSequence(super().update_many(records))


class _NativeDecoding:
    """A native stage (``CanStage``, ``ByteStage``) as the session calls it: its records come
    as ``RecordBatch``es."""

    def __init__(self, core: Any) -> None:
        self.feed_items = core.feed
        self.tick = core.tick
        self.gap = core.gap
        self.cut_off = core.cut_off
        self.finish = core.finish
        self.stop = core.stop


class NativeCanDecoding(_NativeDecoding):
    """``SessionDecoding`` over ``_native.CanStage``: CAN frames in, a ``RecordBatch`` out."""

    def __init__(self, positional: bool) -> None:
        super().__init__(_native.CanStage(positional))  # type: ignore[union-attr]

    def set_protocol(self, bus: str, protocol: str) -> None:
        """Byte-stream protocols do not apply: this decoding is chosen for CAN-only input."""
        raise ValueError(f"a CAN session has no byte streams to decode as {protocol} ({bus})")


class NativeByteDecoding(_NativeDecoding):
    """``SessionDecoding`` over ``_native.ByteStage``: the chunks of one byte stream in, a
    ``RecordBatch`` out."""

    def __init__(self, protocol: str | None) -> None:
        core = _native.ByteStage(protocol)  # type: ignore[union-attr]
        super().__init__(core)
        self.set_protocol = core.set_protocol


class RecordSequence(list[Record]):
    """Records as a list (the Python engine's; the reference for the native ``RecordBatch``,
    which has the same methods): a list, plus the bulk methods listeners read it with."""

    __slots__ = ()

    def column(self, name: str) -> list[Any]:
        """``[getattr(rec, name) for rec in self]``."""
        return list(map(attrgetter(name), self))

    def count_of(self, name: str, value: Any) -> int:
        """How many records have ``getattr(rec, name) == value``."""
        return self.column(name).count(value)

    def error_count(self) -> int:
        """How many records have errors."""
        return sum(1 for r in self if r.errors)

    def problems(self) -> list[int]:
        """The indexes of the records that have errors or warnings."""
        return [i for i, r in enumerate(self) if r.errors or r.warnings]

    def stats_groups(self) -> StatsGroups:
        return stats_groups(self)

    def take(self, indexes: Sequence[int]) -> RecordSequence:
        """The records at ``indexes``, in that order, as a sequence of this kind."""
        return RecordSequence([self[i] for i in indexes])

    def messages(self) -> list[bytes]:
        """Each record as its JSONL object (``Record.to_dict``), one bytes object each."""
        return [json_message(r.to_dict()) for r in self]

    def jsonl(self) -> bytes:
        """The records as JSONL lines, as ``decode --format jsonl`` writes them."""
        dumps = orjson.dumps
        return b"".join([dumps(r.to_dict()) + b"\n" for r in self])

    def rerun_log_rows(self, polls: Sequence[tuple[str, int]], quiet: Sequence[str]) -> Any:
        """What ``eg2scope plot``'s logs show of these records (``rerun_logs.log_rows``)."""
        from ..plot.logs import records_log_rows  # the plot's own module knows its texts

        return records_log_rows(self, frozenset(polls), frozenset(quiet))


Series = tuple[str, int, tuple[str, ...], list[float | None], list[int], list[list[Any]]]


class SampleSequence(list[StateSample]):
    """State samples as a list (the Python tracker's; the reference for the native
    ``SampleBatch``, which has the same methods)."""

    __slots__ = ()

    def column(self, name: str) -> list[Any]:
        """``[getattr(sample, name) for sample in self]``."""
        return list(map(attrgetter(name), self))

    def keys(self) -> list[tuple[str, int]]:
        """(bus, device) of each sample."""
        return [(s.bus, s.device) for s in self]

    def messages(self) -> list[bytes]:
        """Each sample as its flat JSON object (``StateSample.to_dict``), one bytes object each."""
        return [json_message(s.to_dict()) for s in self]

    def series(self, fields: Sequence[str]) -> list[Series]:
        """The samples that changed any of ``fields``, grouped by gripper and by which of them
        they changed: ``(bus, device, names, times, seqs, columns)`` per group, in the order
        groups first appear, ``names`` in the order of ``fields``, one column of values per name
        (as the samples hold them), samples in order. What a plot sends: a column per quantity."""
        wanted = tuple(fields)
        groups: dict[tuple[str, int, tuple[str, ...]], Series] = {}
        names_of: dict[tuple[str, ...], tuple[str, ...]] = {}  # changed keys -> names
        for s in self:
            changed = s.changed
            keys = tuple(changed)
            names = names_of.get(keys)
            if names is None:
                names = names_of[keys] = tuple(f for f in wanted if f in changed)
            if not names:
                continue
            group = groups.get((s.bus, s.device, names))
            if group is None:
                group = groups[(s.bus, s.device, names)] = (
                    s.bus,
                    s.device,
                    names,
                    [],
                    [],
                    [[] for _ in names],
                )
            group[3].append(s.t)
            group[4].append(s.seq)
            for column_, name in zip(group[5], names, strict=True):
                column_.append(changed[name])
        return list(groups.values())

    def arrow(self, columns: Sequence[tuple[str, str, int]]) -> tuple[int, list[Any]]:
        """The samples as Arrow columns described as ``native_parquet.columns`` describes them
        (top-level names: a sample's attributes or its ``values`` keys; ``changed``: the names
        it changed): ``(rows, parts)`` as ``native_parquet.batch_table`` reads them."""
        import pyarrow as pa  # only the fleet dataset asks: not loaded for every session

        described = iter(columns)
        parts: list[Any] = []
        for name, kind, children in described:
            type_ = _arrow_type(kind, children, described)
            _arrow_parts(pa.array(self._values_of(name), type_), parts)
        return len(self), parts

    def _values_of(self, name: str) -> list[Any]:
        if name == "changed":
            return [list(s.changed) for s in self]
        if name in _SAMPLE_ATTRIBUTES:
            return self.column(name)
        return [s.values[name] for s in self]


_SAMPLE_ATTRIBUTES: Final = frozenset({"t", "bus", "device", "protocol", "seq"})


def _arrow_type(kind: str, children: int, described: Iterator[tuple[str, str, int]]) -> Any:
    """The Arrow type of a described column (its children follow it in ``described``)."""
    import pyarrow as pa

    if kind == "struct":
        fields = []
        for _ in range(children):
            name, child_kind, grandchildren = next(described)
            fields.append(pa.field(name, _arrow_type(child_kind, grandchildren, described)))
        return pa.struct(fields)
    if kind == "list":
        _name, child_kind, grandchildren = next(described)
        return pa.list_(_arrow_type(child_kind, grandchildren, described))
    scalars = {"int64": pa.int64(), "float64": pa.float64(), "string": pa.string()}
    return pa.bool_() if kind == "bool" else scalars[kind]


def _arrow_parts(array: Any, parts: list[Any]) -> None:
    """An array and its children, depth first, as the core hands them out:
    ``(length, nulls, validity, values, data)``."""
    import pyarrow as pa

    buffers = array.buffers()
    if pa.types.is_struct(array.type):
        parts.append((len(array), array.null_count, buffers[0], None, None))
        for i in range(array.type.num_fields):
            _arrow_parts(array.field(i), parts)
    elif pa.types.is_list(array.type):
        parts.append((len(array), array.null_count, buffers[0], buffers[1], None))
        _arrow_parts(array.values, parts)
    else:
        data = buffers[2] if len(buffers) > 2 else None
        parts.append((len(array), array.null_count, buffers[0], buffers[1], data))


def can_raw_messages(items: list[Any]) -> list[bytes] | None:
    """Each item's ``/raw`` message (the recorder's CAN frame JSON), from the native core, when
    every item is a CAN frame and the core is built; None otherwise (the recorder makes them)."""
    if _native is None or not items or type(items[0].payload) is not CanFrame:
        return None
    try:
        return _native.can_raw_messages(items)
    except TypeError:  # a byte chunk among them
        return None


def json_message(obj: Any) -> bytes:
    """``obj`` as JSON in a bytes object of its own size. orjson writes into a buffer of a few
    KiB and shrinks it in place: a batch of its results, held until the next tick, would strand
    the rest of every buffer, and touching that much fresh memory per message (page faults)
    costs more than encoding it."""
    return memoryview(orjson.dumps(obj, default=json_default)).tobytes()
