"""The MCAP recorder (``McapRecorder``, a session listener): a session's raw input, records,
state samples and events written as the layout (layout.py) says.

**One clock.** A message's log time is its ``t`` in nanoseconds (the wall clock when it has
none), and log times never decrease in file order across all channels (``mcap doctor
--strict-message-order``). The recorder gathers what it is given until the next ``tick``, sorts
it by time and moves a message that would go back in time up to the last time written; the
exact ``t`` stays in the message. Messages given in one call keep their order, so a byte stream
is never reordered, even when its clock steps back.

**Crash safety.** ``tick`` writes what was gathered and, every ``flush_interval_s``, ends the
chunk in progress and flushes the file, so a recorder killed with SIGKILL loses at most that
much; ``close`` writes the summary and index.

**Cost.** At three messages per CAN frame the recorder's work is per message: the file is
written by ``writer.McapWriter`` (the mcap library's layout, a batch of messages at a time),
and every message is a bytes object of its own size (``batches.json_message``).

Not thread-safe: one thread (the session's) writes.
"""

from __future__ import annotations

import os
import time
from bisect import bisect_left
from collections.abc import Sequence
from datetime import UTC, datetime
from itertools import accumulate, repeat
from operator import mul
from typing import IO, Any, Final

from mcap.writer import LIBRARY_IDENTIFIER

from decoders.model import CanFrame, Record

from .. import __version__
from ..lifecycle import Closing
from ..model import ERROR, WARNING, Item, SourceEvent
from ..session.batches import RecordSequence, SampleSequence, can_raw_messages, json_message
from ..session.listener import Listener
from .layout import (
    CAN_FRAME,
    COMPRESSIONS,
    DECODE_PROBLEM,
    DEVICE_STATE,
    FOXGLOVE_LOG,
    MARK,
    MARKS,
    METADATA_NAME,
    PREFIX_OF_SCHEMA,
    RAW_CHUNK,
    RECORD,
    SCHEMAS,
    best_compression,
    dumps_json,
    metadata_strings,
    raw_message,
    topic_part,
)
from .writer import McapWriter

_Timed = tuple[float | None, int, bytes]  # t (s), channel id, message
MAX_PENDING: Final = 50_000  # messages gathered before they are written even without a tick
_LAST_NS: Final = 2**64 - 1  # MCAP times are unsigned 64-bit nanoseconds
_LAST_S: Final = _LAST_NS / 1e9


def _ns(t: float) -> int:
    """A time in seconds as an MCAP log time; a capture's nonsense (negative, NaN, beyond the
    year 2554) is pinned to the range rather than failing the recording."""
    if 0 < t < _LAST_S:
        return int(t * 1e9)
    return _LAST_NS if t > 0 else 0


def _log_times(times: Sequence[float | None]) -> list[int]:
    """Times in seconds as MCAP log times (``_ns``), the wall clock for None."""
    try:  # all numbers: converted without a Python step per message
        log_times = list(map(int, map(mul, times, repeat(1e9))))
    except (TypeError, ValueError, OverflowError):  # None, NaN, infinite
        pass
    else:
        if not log_times or (min(log_times) >= 0 and max(log_times) <= _LAST_NS):
            return log_times
    now = time.time_ns()
    return [now if t is None else _ns(t) for t in times]


class McapRecorder(Closing, Listener):
    """Records a session into an MCAP file (see the module doc for the layout and the clock).

    ``metadata``: what to say about the session, e.g. ``{"sources": [{"bus": "can0",
    "interface": "socketcan", "channel": "can0", "bitrate": 500000}], "passive": "yes"}``;
    tool name and version, start time and mcap library are added.
    ``compression``: "zstd", "lz4", "none" or None for the best that is installed.
    ``log_record_problems``: also put records with errors/warnings on ``/events/<bus>``.
    """

    wants_raw = True
    wants_states = True

    def __init__(
        self,
        path: str | os.PathLike[str],
        metadata: dict[str, Any] | None = None,
        flush_interval_s: float = 0.5,
        compression: str | None = None,
        chunk_size: int = 1 << 20,
        log_record_problems: bool = True,
    ) -> None:
        compression = compression or best_compression()
        if compression not in COMPRESSIONS:
            raise ValueError(f"unknown MCAP compression {compression!r} (zstd, lz4 or none)")
        self.path = os.fspath(path)
        self.label = f"recording {self.path}"
        self.compression = compression
        self.flush_interval_s = flush_interval_s
        self.log_record_problems = log_record_problems
        self.messages = 0  # written so far
        self.closed = False
        self._file: IO[bytes] = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        try:
            self._writer = McapWriter(
                self._file,
                chunk_size,
                COMPRESSIONS[compression],
                library=f"eg2scope/{__version__} {LIBRARY_IDENTIFIER}",
            )
            meta: dict[str, Any] = {
                "tool": "eg2scope",
                "version": __version__,
                "started": datetime.now(UTC).isoformat(),
                "mcap": LIBRARY_IDENTIFIER,
            }
            meta.update(metadata or {})
            self._writer.add_metadata(METADATA_NAME, metadata_strings(meta))
            self._file.flush()
        except BaseException:
            self._file.close()
            raise
        self._schemas: dict[str, int] = {}
        # schema -> bus (or (bus, device) for states) -> channel id
        self._channels: dict[str, dict[Any, int]] = {name: {} for name in SCHEMAS}
        # the messages gathered since the last tick: log time, channel, message
        self._times: list[int] = []
        self._ids: list[int] = []
        self._datas: list[bytes] = []
        self._last_log_time = 0
        self._last_flush = time.monotonic()

    # -- the listener ---------------------------------------------------------------------------

    def on_raw(self, items: list[Item]) -> None:
        """Raw input, byte chunks and CAN frames, on ``/raw/<bus>``."""
        self._check_open()
        can_channels, byte_channels = self._channels[CAN_FRAME], self._channels[RAW_CHUNK]
        channels = [
            (can_channels.get(item.bus) or self._channel(CAN_FRAME, item.bus))
            if type(item.payload) is CanFrame
            else (byte_channels.get(item.bus) or self._channel(RAW_CHUNK, item.bus))
            for item in items
        ]
        datas = can_raw_messages(items)  # CAN frames only: the native core's JSON
        if datas is None:
            datas = [json_message(raw_message(item)) for item in items]
        self._gather([item.payload.t for item in items], channels, datas)

    def on_records(self, records: RecordSequence) -> None:
        """Decoded records on ``/decoded/<bus>``, and those with problems on ``/events/<bus>``
        (if ``log_record_problems``)."""
        self._check_open()
        known = self._channels[RECORD]
        self._gather(
            records.column("t"),
            [known.get(bus) or self._channel(RECORD, bus) for bus in records.column("bus")],
            records.messages(),
        )
        if self.log_record_problems:
            problems = [self._problem(records[i]) for i in records.problems()]
            if problems:
                times, channels, datas = zip(*problems, strict=True)
                self._gather(times, channels, datas)

    def on_states(self, samples: SampleSequence) -> None:
        """One message per state sample on ``/state/<bus>/<device>``, at its record's time."""
        self._check_open()
        known = self._channels[DEVICE_STATE]
        keys = samples.keys()  # (bus, device) per sample
        self._gather(
            samples.column("t"),
            [known.get(key) or self._channel(DEVICE_STATE, *key) for key in keys],
            samples.messages(),
        )

    def on_event(self, event: SourceEvent) -> None:
        """A source event (port lost, drops, passive, ...) as ``foxglove.Log``."""
        self._check_open()
        t, channel, data = self._log(
            event.bus, event.t, event.level, event.message, event.kind, 0, event.count
        )
        self._gather([t], [channel], [data])

    def write_mark(self, t: float | None, name: str, seq: int | None = None) -> None:
        """A mark set by a person (the TUI) on ``/marks``: ``seq`` is the record it marks."""
        self._check_open()
        channel = self._channels[MARK].get("") or self._channel(MARK, "")
        self._gather([t], [channel], [json_message({"t": t, "name": name, "seq": seq})])

    def tick(self, now: float = 0.0) -> None:
        """After every batch and when idle: write what was gathered, and end the chunk in
        progress every ``flush_interval_s`` (``now`` is not needed: the interval is measured on
        the monotonic clock)."""
        self._write_pending()

    def flush(self) -> None:
        """Write what was gathered, end the chunk in progress and flush the file, now."""
        if self.closed:
            return
        self._write_pending(flush=False)
        self._writer.flush()
        self._last_flush = time.monotonic()

    def close(self) -> None:
        """Finish the file: last chunk, summary, index, footer. Safe to call twice."""
        if self.closed:
            return
        self.closed = True
        try:
            self._write_pending(flush=False)
            self._writer.finish()
        finally:
            self._file.close()

    def on_error(self, exc: BaseException) -> None:
        """Detached by the session: finish the file with what it holds."""
        self.close()

    # -- internals ------------------------------------------------------------------------------

    def _check_open(self) -> None:
        if self.closed:
            raise ValueError(f"MCAP recording {self.path} is closed")

    def _gather(
        self, times: Sequence[float | None], channels: Sequence[int], datas: Sequence[bytes]
    ) -> None:
        """Messages of one call (their ``t``, channel and message), kept in their order: each
        gets its log time (``t`` in ns, the wall clock if none), raised to the highest of the
        call so far, so sorting the batch by time never reorders them."""
        self._times += accumulate(_log_times(times), max)
        self._ids += channels
        self._datas += datas
        if len(self._datas) >= MAX_PENDING:
            self._write_pending()

    def _write_pending(self, flush: bool = True) -> None:
        """The gathered messages in time order, none before the last one written."""
        times = self._times
        if times:
            # sorted stably by log time: equal times keep the order they came in
            order = sorted(range(len(times)), key=times.__getitem__)
            times = list(map(times.__getitem__, order))
            ids = list(map(self._ids.__getitem__, order))
            datas = list(map(self._datas.__getitem__, order))
            self._times, self._ids, self._datas = [], [], []
            last = self._last_log_time
            older = bisect_left(times, last)  # older than what was written: moved up to it
            times[:older] = repeat(last, older)
            self._writer.add_messages(times, ids, datas)
            self._last_log_time = times[-1]
            self.messages += len(times)
        if flush and time.monotonic() - self._last_flush >= self.flush_interval_s:
            self.flush()

    def _problem(self, rec: Record) -> _Timed:
        level = ERROR if rec.errors else WARNING
        what = rec.summary or rec.name or rec.kind
        if rec.device is not None:
            what = f"ID {rec.device} {what}"
        text = "; ".join(rec.errors + rec.warnings)
        return self._log(rec.bus, rec.t, level, f"{what}: {text}", DECODE_PROBLEM, rec.seq, 1)

    def _log(
        self,
        bus: str,
        t: float | None,
        level: int,
        message: str,
        name: str,
        line: int,
        count: int,
    ) -> _Timed:
        if t is None:
            t = time.time()
        ns = _ns(t)  # as its log time
        msg = {
            "timestamp": {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000},
            "level": level,
            "message": message,
            "name": name,
            "file": bus,
            "line": max(0, line),
            "count": count,
        }
        ch = self._channels[FOXGLOVE_LOG].get(bus) or self._channel(FOXGLOVE_LOG, bus)
        return (t, ch, json_message(msg))

    def _channel(self, schema: str, bus: str, device: int | None = None) -> int:
        schema_id = self._schemas.get(schema)
        if schema_id is None:
            schema_id = self._schemas[schema] = self._writer.register_schema(
                schema, "jsonschema", dumps_json(SCHEMAS[schema])
            )
        if schema == MARK:
            topic = MARKS
        else:
            topic = PREFIX_OF_SCHEMA[schema] + topic_part(bus)
            if device is not None:
                topic += f"/{device}"
        metadata = {"bus": bus} if schema != MARK else {}
        channel = self._writer.register_channel(topic, "json", schema_id, metadata)
        self._channels[schema][bus if device is None else (bus, device)] = channel
        return channel
