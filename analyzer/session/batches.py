"""What listeners are handed: records and state samples as lists, or as the native core's batches.

A session on CAN input with the native core built (``session_engine``) decodes with
``_native.LiveCan`` and tracks with ``_native.Tracker``; the same records and samples as
``stage.Decoding`` and ``tracker.Tracker`` (tests/native/test_live_native.py and
test_tracker_native.py require it) come as a ``RecordBatch`` and a ``SampleBatch``. Both are
sequences whose items become Python objects only when read; their bulk methods give a column
(times, buses) or every item's JSON without any. The functions here take either kind, so a
listener that writes JSON (the recorder) makes no object per frame on the native path and the
same bytes on the Python one.

Byte streams keep the Python decoders: their protocol is detected per stream, frames are timed
per byte and ended by idle gaps, and a serial line carries a fraction of a CAN bus's frames.
"""

from __future__ import annotations

from collections.abc import Sequence
from operator import attrgetter
from typing import Any, Protocol

import orjson

from decoders.model import CanFrame, Record

from ..model import StateSample, json_default
from .engine import ENGINES, _native
from .stage import Decoding
from .tracker import Tracker

# the native batch classes (an empty tuple where the core is not built: isinstance is False)
RecordBatch: Any = getattr(_native, "RecordBatch", ())
SampleBatch: Any = getattr(_native, "SampleBatch", ())
_CAN_RAW: Any = getattr(_native, "can_raw_messages", None)


class SessionDecoding(Protocol):
    """What a session asks of its decoding (``stage.Decoding`` or the native ``LiveCan``).
    The native core answers with ``RecordBatch``es, which behave as these lists do where the
    session uses them (``len``, iteration, indexing, ``+=`` of another)."""

    def feed_items(self, items: list[Any]) -> list[Record]: ...
    def tick(self, now: float) -> list[Record]: ...
    def gap(self, bus: str) -> list[Record]: ...
    def cut_off(self, bus: str) -> list[Record]: ...
    def finish(self) -> list[Record]: ...
    def stop(self) -> list[Record]: ...
    def set_protocol(self, bus: str, protocol: str) -> None: ...


def native_session_available() -> bool:
    """The native core is built and has the session classes."""
    return all(hasattr(_native, name) for name in ("LiveCan", "Tracker"))


def session_engine(
    engine: str,
    kind: str,
    positional: bool,
    protocol: str | None = None,
    per_bus: dict[str, str] | None = None,
    byte_time_s: dict[str, float] | None = None,
) -> tuple[SessionDecoding, Any]:
    """The decoding and tracker of a session whose source gives ``kind`` input ("can", "bytes"
    or "mixed"): the native core's for CAN input when it is built (``engine`` "auto") or asked
    for ("native": ValueError where it cannot be used), else the Python ones."""
    if engine not in ENGINES:
        raise ValueError(f"unknown engine {engine!r}; choose from {', '.join(ENGINES)}")
    native = kind == "can" and native_session_available()
    if engine == "native" and not native:
        why = "it is not built" if not native_session_available() else "the input is not CAN"
        raise ValueError(f"the native engine cannot decode this session: {why}")
    if native and engine != "python":
        return NativeCanDecoding(positional), _native.Tracker()  # type: ignore[union-attr]
    decoding = Decoding(protocol, per_bus, positional_seq=positional, byte_time_s=byte_time_s)
    return decoding, Tracker()


class NativeCanDecoding:
    """``SessionDecoding`` over ``_native.LiveCan``: CAN frames in, a ``RecordBatch`` out."""

    def __init__(self, positional: bool) -> None:
        core = _native.LiveCan(positional)  # type: ignore[union-attr]
        self.feed_items = core.feed
        self.tick = core.tick
        self.gap = core.gap
        self.cut_off = core.cut_off
        self.finish = core.finish
        self.stop = core.stop

    def set_protocol(self, bus: str, protocol: str) -> None:
        """Byte-stream protocols do not apply: this decoding is chosen for CAN-only input."""
        raise ValueError(f"a CAN session has no byte streams to decode as {protocol} ({bus})")


def column(items: Sequence[Any], name: str) -> list[Any]:
    """``[getattr(x, name) for x in items]`` for records or samples; a native batch reads it
    from its Rust data without making an object per item."""
    if isinstance(items, (RecordBatch, SampleBatch)):
        return items.column(name)
    return list(map(attrgetter(name), items))


def error_count(records: Sequence[Record]) -> int:
    """How many of ``records`` have errors."""
    if isinstance(records, RecordBatch):
        return records.error_count()
    return sum(1 for r in records if r.errors)


def problem_indexes(records: Sequence[Record]) -> list[int]:
    """The indexes of the records that have errors or warnings."""
    if isinstance(records, RecordBatch):
        return records.problems()
    return [i for i, r in enumerate(records) if r.errors or r.warnings]


def with_problems(records: Sequence[Record]) -> list[Record]:
    """The records that have errors or warnings (made into objects only those, natively)."""
    return [records[i] for i in problem_indexes(records)]


def record_messages(records: Sequence[Record]) -> list[bytes]:
    """Each record as its JSONL object (``Record.to_dict``), one bytes object each."""
    if isinstance(records, RecordBatch):
        return records.messages()
    return [json_message(r.to_dict()) for r in records]


def records_jsonl(records: Sequence[Record]) -> bytes:
    """Records as JSONL lines, as ``decode --format jsonl`` writes them."""
    if isinstance(records, RecordBatch):
        messages = records.messages()
        return b"\n".join(messages) + b"\n" if messages else b""
    dumps = orjson.dumps
    return b"".join([dumps(r.to_dict()) + b"\n" for r in records])


def sample_keys(samples: Sequence[StateSample]) -> list[tuple[str, int]]:
    """(bus, device) of each sample."""
    if isinstance(samples, SampleBatch):
        return samples.keys()
    return [(s.bus, s.device) for s in samples]


Series = tuple[str, int, tuple[str, ...], list[float | None], list[int], list[list[Any]]]


def sample_series(samples: Sequence[StateSample], fields: Sequence[str]) -> list[Series]:
    """The samples that changed any of ``fields``, grouped by gripper and by which of them
    they changed: ``(bus, device, names, times, seqs, columns)`` per group, in the order groups
    first appear, ``names`` in the order of ``fields``, one column of values per name (as the
    samples hold them), samples in order. What a plot sends: a column per quantity."""
    if isinstance(samples, SampleBatch):
        return samples.series(tuple(fields))
    wanted = tuple(fields)
    groups: dict[tuple[str, int, tuple[str, ...]], Series] = {}
    names_of: dict[tuple[str, ...], tuple[str, ...]] = {}  # changed keys -> names among fields
    for s in samples:
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


def sample_messages(samples: Sequence[StateSample]) -> list[bytes]:
    """Each sample as its flat JSON object (``StateSample.to_dict``), one bytes object each."""
    if isinstance(samples, SampleBatch):
        return samples.messages()
    return [json_message(s.to_dict()) for s in samples]


def can_raw_messages(items: list[Any]) -> list[bytes] | None:
    """Each item's ``/raw`` message (the recorder's CAN frame JSON), from the native core, when
    every item is a CAN frame and the core is built; None otherwise (the recorder makes them)."""
    if _CAN_RAW is None or not items or type(items[0].payload) is not CanFrame:
        return None
    try:
        return _CAN_RAW(items)
    except TypeError:  # a byte chunk among them
        return None


def json_message(obj: Any) -> bytes:
    """``obj`` as JSON in a bytes object of its own size. orjson writes into a buffer of a few
    KiB and shrinks it in place: a batch of its results, held until the next tick, would strand
    the rest of every buffer, and touching that much fresh memory per message (page faults)
    costs more than encoding it."""
    return memoryview(orjson.dumps(obj, default=json_default)).tobytes()
