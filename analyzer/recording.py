"""The MCAP recording: its layout, the writer (``McapRecorder``, a session listener) and the
readers (``McapCaptureReader``, ``read_records``/``read_events``/``read_states``/
``read_metadata``), in one module as python-can keeps a format's reader and writer together.

Layout (docs/contracts.md, "MCAP recordings"); every message is JSON with a ``jsonschema``
schema, so Foxglove opens and plots the file as it is:

- ``/raw/<bus>``: raw byte chunks (``eg2scope.RawChunk``) or CAN frames (``eg2scope.CanFrame``),
  bytes in base64. Raw input is the truth: ``eg2scope decode run.mcap`` decodes it again.
- ``/decoded/<bus>``: ``Record.to_dict()`` (``eg2scope.Record``).
- ``/state/<bus>/<device>``: one ``StateSample.to_dict()`` per reading (``eg2scope.DeviceState``),
  flat, so the plot path ``/state/can0/1.opening_mm`` works.
- ``/events/<bus>``: source events, and records with errors or warnings (named "decode"), as
  ``foxglove.Log``.
- ``/marks``: marks set while recording (``eg2scope.Mark``).
- a metadata record named ``eg2scope``: tool version, source settings, passive or not (MCAP
  metadata values are strings, so anything else is JSON-encoded).

Every channel carries its exact bus name in its metadata (``bus``): a topic holds only a
cleaned-up form of it.

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
written by ``mcap_writer.McapWriter`` (the mcap library's layout, a batch of messages at a
time), and every message is a bytes object of its own size (``batches.json_message``).

**Reading.** An intact file is read through its index, a damaged one (a recorder killed
mid-session, a copy cut short) chunk by chunk up to the damage. Every chunk is checked against
its CRC (and, when indexed, against the index): a damaged chunk is reported with its byte
position and what it held, and reading goes on with the next one where the file's structure
allows. What was lost is reported in ``errors``, never raised, and never decoded differently in
silence. A file that cannot be opened raises ``OSError``; a pipe or a device is refused
(``UsageError``): the reader seeks.

Not thread-safe: one thread (the session's) writes.
"""

from __future__ import annotations

import base64
import binascii
import functools
import importlib.util
import io
import os
import re
import stat
import struct
import time
import zlib
from bisect import bisect_left
from collections.abc import Iterable, Iterator, Sequence
from datetime import UTC, datetime
from itertools import accumulate, repeat
from operator import mul
from typing import IO, Any, Final

import orjson
from mcap.data_stream import ReadDataStream, RecordBuilder
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Message,
    MessageIndex,
    Metadata,
    Schema,
)
from mcap.stream_reader import StreamReader, breakup_chunk, get_chunk_data_stream
from mcap.summary import Summary
from mcap.writer import LIBRARY_IDENTIFIER

from decoders.model import EG2_SERIAL, MODBUS_RTU, CanFrame, Record
from decoders.model import Chunk as ByteChunk

from . import __version__
from .batches import RecordSequence, SampleSequence, can_raw_messages, json_message
from .errors import UsageError
from .lifecycle import Closing
from .listener import Listener
from .mcap_writer import MAGIC, McapWriter
from .model import ERROR, WARNING, Item, SourceEvent, json_default
from .sources.capture import CaptureReader
from .sources.naming import BUS_BY_PROTOCOL

# -- layout ----------------------------------------------------------------------------------------

RAW: Final = "/raw/"
DECODED: Final = "/decoded/"
STATE: Final = "/state/"
EVENTS: Final = "/events/"
MARKS: Final = "/marks"

METADATA_NAME: Final = "eg2scope"
RAW_CHUNK: Final = "eg2scope.RawChunk"
CAN_FRAME: Final = "eg2scope.CanFrame"
RECORD: Final = "eg2scope.Record"
DEVICE_STATE: Final = "eg2scope.DeviceState"
MARK: Final = "eg2scope.Mark"
FOXGLOVE_LOG: Final = "foxglove.Log"
DECODE_PROBLEM: Final = "decode"  # the foxglove.Log name of a record's errors and warnings

# the topic prefix of each schema (a state topic ends in /<device>)
PREFIX_OF_SCHEMA: Final = {
    RAW_CHUNK: RAW,
    CAN_FRAME: RAW,
    RECORD: DECODED,
    DEVICE_STATE: STATE,
    FOXGLOVE_LOG: EVENTS,
}

_B64 = {"type": "string", "contentEncoding": "base64"}
_T = {"type": ["number", "null"], "description": "seconds (epoch or capture clock), or null"}
_STRINGS = {"type": "array", "items": {"type": "string"}}


def _nullable(kind: str, description: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {"type": [kind, "null"]}
    if description:
        out["description"] = description
    return out


def _schema(name: str, description: str, properties: dict[str, Any], required: list[str]) -> Any:
    return {
        "title": name,
        "description": description,
        "type": "object",
        "properties": properties,
        "required": required,
    }


SCHEMAS: Final[dict[str, dict[str, Any]]] = {
    RAW_CHUNK: _schema(
        RAW_CHUNK,
        "A chunk of bytes as it arrived from a serial line",
        {
            "t": _T,
            "stream": {"type": "string", "description": "byte stream on this bus ('' if one)"},
            "direction": _nullable("string", "request, response, or null when unknown"),
            "data": _B64,
        },
        ["t", "stream", "direction", "data"],
    ),
    CAN_FRAME: _schema(
        CAN_FRAME,
        "One CAN frame",
        {
            "t": _T,
            "id": {"type": "integer", "minimum": 0, "description": "arbitration id"},
            "extended": {"type": "boolean"},
            "remote": {"type": "boolean"},
            "error": {"type": "boolean"},
            "fd": {"type": "boolean"},
            "dlc": {"type": "integer", "minimum": 0, "description": "data length in bytes"},
            "data": _B64,
            "channel": _nullable("string", "the capture's channel name"),
        },
        ["t", "id", "extended", "remote", "error", "fd", "dlc", "data"],
    ),
    RECORD: _schema(
        RECORD,
        "One decoded frame, or a run of bytes that belongs to no frame",
        {
            "t": _T,
            "bus": {"type": "string"},
            "protocol": {"type": "string", "enum": ["eg2-serial", "modbus-rtu", "eg2-can", "can"]},
            "kind": {"type": "string", "enum": ["frame", "garbage", "truncated"]},
            "offset": _nullable("integer", "byte offset in the input stream"),
            "index": _nullable("integer", "frame number in the input (CAN)"),
            "length": {"type": "integer"},
            "direction": _nullable("string"),
            "device": _nullable("integer"),
            "code": _nullable("integer"),
            "name": _nullable("string"),
            "fields": {"type": "object", "description": "decoded values by manual name"},
            "raw": {"type": "string", "description": "hex"},
            "errors": _STRINGS,
            "warnings": _STRINGS,
            "flags": {**_STRINGS, "description": "a code for every error and warning"},
            "summary": {"type": "string"},
            "seq": {"type": "integer"},
            "pair": _nullable("integer"),
            "latency_ms": _nullable("number"),
        },
        ["t", "bus", "protocol", "kind", "length", "raw", "errors", "warnings", "flags"],
    ),
    DEVICE_STATE: _schema(
        DEVICE_STATE,
        "The state of one gripper after a record that set some of it (one per reading)",
        {
            "t": _T,
            "bus": {"type": "string"},
            "device": {"type": "integer"},
            "protocol": {"type": "string"},
            "seq": {"type": "integer", "description": "the record's seq"},
            "opening": _nullable("integer", "0-1000"),
            "opening_mm": _nullable("number", "opening in mm"),
            "force": _nullable("integer", "measured force"),
            "current": _nullable("integer"),
            "temperature_c": _nullable("integer"),
            "state": _nullable("integer"),
            "state_text": _nullable("string"),
            "fault": _nullable("integer"),
            "fault_text": _STRINGS,
            "target_opening": _nullable("integer", "0-1000"),
            "target_mm": _nullable("number"),
            "speed": _nullable("integer"),
            "force_setting": _nullable("integer"),
            "catch_mode": _nullable("integer"),
            "max_opening": _nullable("integer"),
            "min_opening": _nullable("integer"),
            "last_command": _nullable("string"),
            "latency_ms": _nullable("number"),
            "frames": {"type": "integer"},
            "errors": {"type": "integer"},
            "unanswered": {"type": "integer"},
            "changed": {**_STRINGS, "description": "the fields this record set"},
        },
        ["t", "bus", "device", "protocol", "seq", "changed"],
    ),
    MARK: _schema(
        MARK,
        "A mark set while recording",
        {
            "t": _T,
            "name": {"type": "string"},
            "seq": _nullable("integer", "the seq of the record it marks"),
        },
        ["t", "name", "seq"],
    ),
    FOXGLOVE_LOG: _schema(
        FOXGLOVE_LOG,
        "A log message",
        {
            "timestamp": {
                "type": "object",
                "title": "time",
                "properties": {
                    "sec": {"type": "integer", "minimum": 0},
                    "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
                },
            },
            "level": {
                "title": "foxglove.LogLevel",
                "oneOf": [
                    {"title": title, "const": n}
                    for n, title in enumerate(
                        ("UNKNOWN", "DEBUG", "INFO", "WARNING", "ERROR", "FATAL")
                    )
                ],
            },
            "message": {"type": "string"},
            "name": {"type": "string", "description": "what logged it: the event's kind"},
            "file": {"type": "string", "description": "the bus"},
            "line": {"type": "integer", "minimum": 0, "description": "the record's seq"},
            "count": {"type": "integer", "minimum": 1, "description": "repeats collapsed"},
        },
        ["timestamp", "level", "message", "name", "file", "line"],
    ),
}

_COMPRESSIONS = {"zstd": "zstd", "lz4": "lz4", "none": ""}  # option -> MCAP compression name
_TOPIC_UNSAFE = re.compile(r"[^A-Za-z0-9_.\-/]+")


def best_compression() -> str:
    """zstd if its module is installed, else lz4, else none."""
    for name, module in (("zstd", "zstandard"), ("lz4", "lz4")):
        if importlib.util.find_spec(module) is not None:
            return name
    return "none"


def topic_part(bus: str) -> str:
    """A bus name as a topic component: ``/dev/ttyUSB0`` -> ``dev/ttyUSB0``,
    ``rfc2217://host:4000`` -> ``rfc2217/host_4000``. The exact name is in the channel's
    metadata."""
    part = _TOPIC_UNSAFE.sub("_", bus.replace("://", "/"))
    part = re.sub(r"/{2,}", "/", part).strip("/")
    return part or "_"


_dumps = functools.partial(orjson.dumps, default=json_default)


def _b64(data: bytes) -> str:
    return binascii.b2a_base64(data, newline=False).decode("ascii")


def metadata_strings(metadata: dict[str, Any]) -> dict[str, str]:
    """MCAP metadata values must be strings: JSON-encode anything else."""
    return {str(k): v if isinstance(v, str) else _dumps(v).decode() for k, v in metadata.items()}


def _raw_message(item: Item) -> dict[str, Any]:
    """The ``/raw`` message of one item (schemas CAN_FRAME and RAW_CHUNK)."""
    p = item.payload
    if isinstance(p, CanFrame):
        return {
            "t": p.t,
            "id": p.arbitration_id,
            "extended": p.is_extended,
            "remote": p.is_remote,
            "error": p.is_error,
            "fd": p.is_fd,
            "dlc": p.length,
            "data": _b64(p.data),
            "channel": p.channel,
        }
    return {"t": p.t, "stream": item.stream, "direction": p.direction, "data": _b64(p.data)}


# -- writing ---------------------------------------------------------------------------------------

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
        if compression not in _COMPRESSIONS:
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
                _COMPRESSIONS[compression],
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
            datas = [json_message(_raw_message(item)) for item in items]
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
                schema, "jsonschema", _dumps(SCHEMAS[schema])
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


# -- reading: the file and its index --------------------------------------------------------------

_FOOTER = struct.Struct("<BQQQI")  # opcode, length, summary start, summary offsets start, CRC
_KIND_OF_SCHEMA = {CAN_FRAME: "can", RAW_CHUNK: "bytes"}
_PROTOCOL_OF_BUS = {bus: protocol for protocol, bus in BUS_BY_PROTOCOL.items()}


def open_recording(path: str | os.PathLike[str]) -> IO[bytes]:
    """The recording opened for reading. It is read by seeking to its index, so a pipe or a
    device (which would also block here) is refused; an unreadable file raises OSError."""
    mode = os.stat(path).st_mode
    if not stat.S_ISREG(mode):
        raise UsageError(
            f"{os.fspath(path)}: not a regular file; an MCAP recording is read by seeking to its "
            "index at the end, so give the file itself, not a pipe or a device"
        )
    return open(path, "rb")  # the caller closes it


class _Recording:
    """An MCAP file opened for reading: what is known before reading its messages (its index
    if the file is intact, its metadata, the channels of its raw input)."""

    def __init__(self, f: IO[bytes], size: int) -> None:
        self.f = f
        self.size = size
        self.problem: str | None = None  # the file holds no MCAP data at all
        self.index_damage: str | None = None
        self.summary: Summary | None = None
        self.metadata: dict[str, Any] = {}
        self.raw_kinds: set[str] = set()
        self.raw_buses: set[str] = set()
        self.byte_buses: set[str] = set()  # buses whose raw input is byte chunks
        head = f.read(len(MAGIC))
        if size == 0:
            self.problem = "the recording is empty"
        elif not MAGIC.startswith(head) or not head:
            self.problem = "not an MCAP file: it does not begin with the MCAP magic bytes"
        elif len(head) < len(MAGIC):
            self.problem = f"the recording is cut short: it has only {size} bytes"
        else:
            self.summary = self._summary()
            if self.summary is not None:
                self._known_from_index(self.summary)
            else:
                self._known_from_stream()

    @property
    def intact(self) -> bool:
        return self.summary is not None

    def _summary(self) -> Summary | None:
        """The summary of a finished file whose index checks out; None otherwise (a file that
        was not finished has none; a damaged one is noted in ``index_damage``)."""
        f, size = self.f, self.size
        if size < 2 * len(MAGIC) + _FOOTER.size:
            return None
        f.seek(size - len(MAGIC) - _FOOTER.size)
        tail = f.read(_FOOTER.size + len(MAGIC))
        if tail[_FOOTER.size :] != MAGIC:
            return None  # not finished (or cut short): read as a stream
        opcode, length, start, _offsets, crc = _FOOTER.unpack_from(tail)
        why = None
        if opcode != Opcode.FOOTER or length != _FOOTER.size - 9 or not 0 <= start < size:
            why = "its footer is damaged"
        elif start and crc:
            f.seek(start)
            if zlib.crc32(f.read(size - len(MAGIC) - 4 - start)) != crc:
                why = f"its CRC does not match from byte {start} on"
        summary = None
        if why is None and start:
            try:
                f.seek(0)
                summary = make_reader(f).get_summary()
            except Exception as exc:
                why = _describe(exc)
        if why is not None:
            self.index_damage = (
                f"the index at the end of the recording is damaged ({why}): read it chunk by "
                "chunk instead"
            )
        return summary

    def _known_from_index(self, summary: Summary) -> None:
        for ch in summary.channels.values():
            schema = summary.schemas.get(ch.schema_id)
            if ch.topic.startswith(RAW) and schema is not None:
                self._raw(_bus_of(ch), _KIND_OF_SCHEMA.get(schema.name, "bytes"))
        try:
            self.f.seek(0)
            for meta in make_reader(self.f).iter_metadata():
                if meta.name == METADATA_NAME:
                    self.metadata.update(_decode_metadata(meta.metadata))
        except Exception:
            pass  # metadata only describes; the messages are what is read (and checked)

    def _known_from_stream(self) -> None:
        """The metadata and raw channels written before (and in) the first chunk."""
        self.f.seek(0)
        schemas: dict[int, str] = {}
        try:
            for record in StreamReader(
                self.f, emit_chunks=True, record_size_limit=self.size
            ).records:
                if isinstance(record, Metadata) and record.name == METADATA_NAME:
                    self.metadata.update(_decode_metadata(record.metadata))
                elif isinstance(record, Chunk):
                    for rec in breakup_chunk(record, validate_crc=True):
                        if isinstance(rec, Schema):
                            schemas[rec.id] = rec.name
                        elif isinstance(rec, Channel) and rec.topic.startswith(RAW):
                            kind = _KIND_OF_SCHEMA.get(schemas.get(rec.schema_id, ""), "bytes")
                            self._raw(_bus_of(rec), kind)
                    return
        except Exception:
            pass  # the damage is reported when the messages are read

    def _raw(self, bus: str, kind: str) -> None:
        self.raw_kinds.add(kind)
        self.raw_buses.add(bus)
        if kind == "bytes":
            self.byte_buses.add(bus)

    def protocols(self) -> dict[str, str]:
        """The protocol each byte bus was decoded with when it was recorded (bus -> protocol):
        its first decoded frame says it (a finished file), else its name does (``rs232``,
        ``rs485``); a bus that says neither is left to detection."""
        out = {bus: by_name for bus in self.byte_buses if (by_name := _PROTOCOL_OF_BUS.get(bus))}
        summary = self.summary
        if summary is None:
            return out
        channels = {
            ch.id: _bus_of(ch)
            for ch in summary.channels.values()
            if ch.topic.startswith(DECODED) and _bus_of(ch) in self.byte_buses
        }
        for ci in sorted(summary.chunk_indexes, key=lambda c: c.message_start_time):
            if not channels:
                break
            if channels.keys().isdisjoint(ci.message_index_offsets):
                continue
            try:
                records = self.chunk_at(ci)
            except Exception:
                continue  # reported when the messages are read
            for rec in records:
                bus = channels.get(rec.channel_id) if isinstance(rec, Message) else None
                if bus is None:
                    continue
                protocol = orjson.loads(rec.data).get("protocol")
                if protocol in (EG2_SERIAL, MODBUS_RTU):
                    out[bus] = protocol
                    del channels[rec.channel_id]
        return out

    def chunk_at(self, ci: ChunkIndex) -> list[Any]:
        """The records of the chunk the index entry names, checked byte for byte against the
        index and the chunk's CRC; raises ValueError (or the decompressor's error) if damaged."""
        f = self.f
        f.seek(ci.chunk_start_offset)
        data = f.read(ci.chunk_length)
        if len(data) != ci.chunk_length:
            raise ValueError("the file ends inside it")
        chunk = Chunk.read(ReadDataStream(io.BytesIO(data[9:])))
        again = RecordBuilder()
        chunk.write(again)
        if again.end() != data:  # opcode, lengths: the record's own structure
            raise ValueError("its record structure is damaged")
        header = (chunk.message_start_time, chunk.message_end_time, chunk.compression)
        sizes = (chunk.uncompressed_size, len(chunk.data))
        if header != (ci.message_start_time, ci.message_end_time, ci.compression) or sizes != (
            ci.uncompressed_size,
            ci.compressed_size,
        ):
            raise ValueError("its header does not match the index")
        return breakup_chunk(chunk, validate_crc=True)

    def lost_in(self, ci: ChunkIndex, summary: Summary, why: str) -> _Lost:
        """What a damaged chunk held, from its message indexes (outside the chunk)."""
        start, times = ci.chunk_start_offset, (ci.message_start_time, ci.message_end_time)
        lost = _Lost(start, start + ci.chunk_length, why, times)
        for offset in ci.message_index_offsets.values():
            try:
                self.f.seek(offset + 9)  # opcode and record length
                lost.add(MessageIndex.read(ReadDataStream(self.f)), summary.channels)
            except Exception:
                continue  # a damaged message index: the time span still says what was lost
        return lost


def _decode_metadata(values: dict[str, str]) -> dict[str, Any]:
    """Values were JSON-encoded unless they were strings: decode what decodes."""
    out: dict[str, Any] = {}
    for k, v in values.items():
        try:
            out[k] = orjson.loads(v)
        except orjson.JSONDecodeError:
            out[k] = v
    return out


def _describe(exc: BaseException) -> str:
    text = str(exc)
    name = type(exc).__name__
    if name == "EndOfFile":
        return "the file ends in the middle of a record"
    if isinstance(exc, struct.error | UnicodeDecodeError):
        return f"a malformed record: {text}"
    if isinstance(exc, ValueError) and text and name in ("ValueError", "CRCValidationError"):
        return text
    return f"{name}: {text}" if text else name


class _Lost:
    """A damaged chunk (bytes ``start`` to ``end``) and what its message indexes (records of
    their own after it) say it held."""

    def __init__(self, start: int, end: int, why: str, times: tuple[int, int] | None) -> None:
        self.start = start
        self.end = end
        self.why = why
        self.times = times  # from the chunk index or the chunk's own header
        self.indexed_times: tuple[int, int] | None = None
        self.counts: dict[str, int] = {}

    def add(self, index: MessageIndex, channels: dict[int, Channel]) -> None:
        ch = channels.get(index.channel_id)
        topic = ch.topic if ch is not None else f"channel {index.channel_id}"
        self.counts[topic] = self.counts.get(topic, 0) + len(index.records)
        if index.records:
            low, high = min(e[0] for e in index.records), max(e[0] for e in index.records)
            if self.indexed_times is not None:
                low, high = min(low, self.indexed_times[0]), max(high, self.indexed_times[1])
            self.indexed_times = (low, high)

    def text(self, size: int) -> str:
        if self.counts:
            per_topic = ", ".join(f"{n} on {topic}" for topic, n in sorted(self.counts.items()))
            what = f"{sum(self.counts.values())} messages ({per_topic})"
        else:
            what = "its messages"
        times = self.indexed_times or self.times
        if times is not None:
            what += f", log time {times[0] / 1e9:.6f} to {times[1] / 1e9:.6f} s"
        return (
            f"damaged chunk at bytes {self.start}-{self.end - 1} of {size} ({self.why}): "
            f"lost {what}; read on after it"
        )


def _checked_records(chunk: Chunk) -> list[Any]:
    """The records of a chunk read without an index, checked against its CRC and its header
    (size and time range), as far as the chunk itself allows."""
    _data, size = get_chunk_data_stream(chunk, validate_crc=True)
    if size != chunk.uncompressed_size:
        raise ValueError("its uncompressed size does not match its header")
    parts = breakup_chunk(chunk)
    times = [m.log_time for m in parts if isinstance(m, Message)]
    if times and (min(times), max(times)) != (chunk.message_start_time, chunk.message_end_time):
        raise ValueError("its time range does not match its messages")
    return parts


def _chunk_size(chunk: Chunk) -> int:
    # opcode, length, start and end time, size, CRC, compression, data
    return 9 + 8 + 8 + 8 + 4 + 4 + len(chunk.compression.encode()) + 8 + len(chunk.data)


def _record_length(f: IO[bytes], start: int, end: int) -> int:
    """The length a record starting at ``start`` claims, with its opcode and length fields; the
    stream reader reads on from ``end`` (where it left the file)."""
    f.seek(start + 1)
    length: int = struct.unpack("<Q", f.read(8))[0]
    f.seek(end)
    return 9 + length


def _message_index_size(index: MessageIndex) -> int:
    return 9 + 2 + 4 + 16 * len(index.records)  # opcode, length, channel, entries


# -- reading: messages in log-time order, damage reported ------------------------------------------

_Pending = tuple[int, int, int, Channel, Message]  # log time, chunk offset, index, channel, msg


class _Merge:
    """Log-time order across chunks whose time ranges overlap (recordings made before the
    recorder kept one clock interleave topics at chunk boundaries): chunks are held until one
    starts after all of them end, then released sorted by (log time, chunk offset, index), the
    order of the mcap library's log-time reader, without its per-message heap. A recording in
    time order releases every chunk as the next one comes."""

    def __init__(self) -> None:
        self.pending: list[_Pending] = []
        self.end = -1
        self.offset = -1

    def add(self, start: int, end: int, offset: int, msgs: list[_Pending]) -> list[_Pending]:
        out: list[_Pending] = []
        if start > self.end or (start == self.end and offset > self.offset):
            out = self.release()
        self.pending += msgs
        self.end = max(self.end, end)
        self.offset = max(self.offset, offset)
        return out

    def release(self) -> list[_Pending]:
        out = self.pending
        if len(out) > 1:
            out.sort(key=lambda m: (m[0], m[1], m[2]))
        self.pending = []
        return out


def _pick(records: Iterable[Any], offset: int, channels: dict[int, Channel]) -> list[_Pending]:
    """The messages of the wanted channels among a chunk's records."""
    out: list[_Pending] = []
    for i, rec in enumerate(records):
        if isinstance(rec, Message):
            ch = channels.get(rec.channel_id)
            if ch is not None:
                out.append((rec.log_time, offset, i, ch, rec))
    return out


class _Walk:
    """Reading a file record by record (no index to trust): the channels seen, and the checks
    that keep a damaged record from being read as something else. Our recordings hold schemas,
    channels and messages in chunks, each followed by its message indexes."""

    def __init__(self, f: IO[bytes], size: int, prefixes: tuple[str, ...], errors: list[str]):
        self.f = f
        self.size = size
        self.prefixes = prefixes
        self.errors = errors
        self.known: dict[int, Channel] = {}
        self.wanted: dict[int, Channel] = {}
        self.lost: _Lost | None = None  # a damaged chunk, until its message indexes are counted
        self.orphans = 0  # messages on channels defined in a damaged chunk
        self.previous: type | None = None
        self.data_end = self.footer = False

    def take(self, record: Any, start: int, end: int) -> tuple[tuple[int, int], list[Any]]:
        """The time range and the records to read of one record at bytes ``start``-``end``
        (a chunk's records, checked). Raises ValueError where the file's structure breaks."""
        previous, self.previous = self.previous, type(record)
        if self.data_end and not isinstance(record, Footer):
            return (0, 0), []  # the summary section repeats what the data section said
        if isinstance(record, MessageIndex):
            self._index(record, previous, start, end)
            return (0, 0), []
        self._report_lost()
        times, parts = (0, 0), []
        if isinstance(record, Chunk):
            times = (record.message_start_time, record.message_end_time)
            try:
                if _record_length(self.f, start, end) != _chunk_size(record):
                    raise ValueError("its record length is damaged")
                parts = _checked_records(record)
            except Exception as exc:  # its neighbours are framed apart: go on after it
                self.lost = _Lost(start, end, _describe(exc), times)
        elif isinstance(record, Message | Channel):  # outside chunks: another writer's file
            parts = [record]
            if isinstance(record, Message):
                times = (record.log_time, record.log_time)
        elif isinstance(record, DataEnd):
            self.data_end = True
        elif isinstance(record, Footer):
            if end + len(MAGIC) != self.size:
                raise ValueError("a footer record in the middle of the file")
            self.footer = True
        self._learn(parts)
        return times, parts

    def _index(self, index: MessageIndex, previous: type | None, start: int, end: int) -> None:
        """A message index follows its chunk, right after it or another index: if not, the
        chunk it indexes was damaged into something else."""
        begin = end - _message_index_size(index)
        if begin != start or previous not in (Chunk, MessageIndex):
            self._report_lost()
            self.lost = _Lost(start, begin, "its record type is damaged", None)
        if self.lost is not None:
            self.lost.add(index, self.known)

    def _learn(self, parts: list[Any]) -> None:
        for part in parts:
            if isinstance(part, Channel):
                seen = self.known.get(part.id)
                if seen is not None and seen != part:
                    raise ValueError(f"a record redefines channel {part.id} ({seen.topic})")
                self.known[part.id] = part
                if part.topic.startswith(self.prefixes):
                    self.wanted[part.id] = part
            elif isinstance(part, Message) and part.channel_id not in self.known:
                self.orphans += 1

    def _report_lost(self) -> None:
        if self.lost is not None:
            self.errors.append(self.lost.text(self.size))
            self.lost = None

    def finish(self) -> None:
        self._report_lost()
        if self.orphans:
            self.errors.append(
                f"{self.orphans} later messages are on channels defined in a damaged chunk: lost"
            )


class _Scan:
    """One pass over the messages of the topics under ``prefixes``, in log-time order, tolerant
    of damage. ``progress`` is called with a byte position now and then. After the pass:
    ``errors`` (what was lost) and ``count`` (messages read)."""

    def __init__(
        self,
        recording: _Recording,
        prefixes: tuple[str, ...],
        progress: Any = None,
    ) -> None:
        self.recording = recording
        self.prefixes = prefixes
        self.progress = progress
        self.errors: list[str] = []
        self.count = 0
        self.label = " and ".join(p.rstrip("/") for p in prefixes)

    def messages(self) -> Iterator[tuple[Channel, Message]]:
        rec = self.recording
        if rec.problem is not None:
            self.errors.append(rec.problem)
            return
        if rec.index_damage is not None:
            self.errors.append(rec.index_damage)
        if rec.summary is not None and rec.summary.chunk_indexes:
            yield from self._indexed(rec.summary)
        elif rec.summary is None:
            yield from self._streamed()
        # else: a finished recording without chunks holds no messages

    def _wanted(self, channels: Iterable[Channel]) -> dict[int, Channel]:
        return {ch.id: ch for ch in channels if ch.topic.startswith(self.prefixes)}

    def _release(self, ready: list[_Pending]) -> Iterator[tuple[Channel, Message]]:
        self.count += len(ready)
        for m in ready:
            yield m[3], m[4]

    # -- intact: through the summary and chunk index ---------------------------------------------

    def _indexed(self, summary: Summary) -> Iterator[tuple[Channel, Message]]:
        """The chunks holding the wanted channels, in log-time order (as the mcap reader's
        ``iter_messages``, which spends most of its time in a per-message heap)."""
        rec = self.recording
        channels = self._wanted(summary.channels.values())
        if not channels:
            return
        chunks = sorted(
            (
                ci
                for ci in summary.chunk_indexes
                if not ci.message_index_offsets
                or not channels.keys().isdisjoint(ci.message_index_offsets)
            ),
            key=lambda ci: (ci.message_start_time, ci.chunk_start_offset),
        )
        merge = _Merge()
        done, total = 0, max(1, sum(c.chunk_length for c in chunks))
        for ci in chunks:
            start = ci.chunk_start_offset
            try:
                msgs = _pick(rec.chunk_at(ci), start, channels)
            except Exception as exc:  # never decoded differently: reported and skipped
                self.errors.append(rec.lost_in(ci, summary, _describe(exc)).text(rec.size))
                msgs = []
            ready = merge.add(ci.message_start_time, ci.message_end_time, start, msgs)
            yield from self._release(ready)
            done += ci.chunk_length
            if self.progress is not None:
                self.progress(done * rec.size // total)
        yield from self._release(merge.release())

    # -- not finished, or its index damaged: record by record ------------------------------------

    def _streamed(self) -> Iterator[tuple[Channel, Message]]:
        rec = self.recording
        f, size = rec.f, rec.size
        f.seek(0)
        records = StreamReader(f, emit_chunks=True, record_size_limit=max(size, 1)).records
        walk = _Walk(f, size, self.prefixes, self.errors)
        good = len(MAGIC)  # end of the last record read whole (the magic was checked)
        failure: BaseException | None = None
        merge = _Merge()  # in file order: chunks are held only while their times overlap
        while not walk.footer:
            try:
                record = next(records)
                times, parts = walk.take(record, good, f.tell())
            except StopIteration:
                break
            except Exception as exc:
                failure = exc
                break
            start, good = good, f.tell()
            msgs = _pick(parts, start, walk.wanted)
            if msgs:
                yield from self._release(merge.add(times[0], times[1], start, msgs))
                if self.progress is not None:
                    self.progress(good)
        walk.finish()
        yield from self._release(merge.release())  # everything read whole before the damage
        ending = self._ending(failure, good, walk.footer, walk.data_end)
        if ending:
            self.errors.append(ending)

    def _ending(
        self, failure: BaseException | None, good: int, footer: bool, data_end: bool
    ) -> str | None:
        """How a file read record by record ends, in one message (None: intact)."""
        f, size = self.recording.f, self.recording.size
        read = f"{self.count} {self.label} messages"
        if footer and failure is None:
            if f.read(len(MAGIC) + 1) == MAGIC:
                return None  # a finished file without an index: nothing lost
            why = "its closing magic bytes are missing"
            return f"the end of the recording is damaged ({why}): all {read} were read"
        if data_end:
            why = "cut short" if failure is None or good == size else _describe(failure)
            return (
                f"the end of the recording is damaged ({why}, after its data): all {read} were read"
            )
        if good == size:
            return (
                f"recovered a damaged recording: read all {read} in its {size} bytes; it was "
                "not finished (no index: the recorder was killed or did not close it), so what "
                "it had not yet written is lost"
            )
        if failure is None or _cut_short(f, good, size):
            return (
                f"recovered a damaged recording: read {read}; the file is cut short in the "
                f"middle of a record at byte {good} of {size} (the recorder was killed or the "
                "copy cut), so the rest is lost"
            )
        return (
            f"recovered a damaged recording: read {read} up to byte {good} of {size}, where it "
            f"is damaged ({_describe(failure)}); the rest is lost"
        )


def _cut_short(f: IO[bytes], good: int, size: int) -> bool:
    """Whether the record after the last good one is a real record that runs past the end of
    the file (rather than bytes damaged into a record header)."""
    if size - good < 9:
        return True
    try:
        f.seek(good)
        opcode, length = struct.unpack("<BQ", f.read(9))
    except (OSError, ValueError, struct.error):
        return True
    return opcode in _OPCODES and good + 9 + length > size


_OPCODES = frozenset(int(op) for op in Opcode)


# -- raw input again ------------------------------------------------------------------------------


def _bus_of(channel: Channel) -> str:
    bus = channel.metadata.get("bus")
    if bus is not None:
        return bus
    rest = channel.topic.partition("/")[2].partition("/")[2]  # /<prefix>/<bus>[/<device>]
    if channel.topic.startswith(STATE):
        rest = rest.rpartition("/")[0]
    return rest


def item_from_message(message: Message, bus: str) -> Item:
    """A ``/raw/<bus>`` message back to the Item it was recorded from."""
    d = orjson.loads(message.data)
    data = base64.b64decode(d.get("data") or "")
    if "id" in d:  # eg2scope.CanFrame
        dlc = d.get("dlc")
        frame = CanFrame(
            t=d.get("t"),
            arbitration_id=d["id"],
            data=data,
            is_extended=bool(d.get("extended", True)),
            is_remote=bool(d.get("remote", False)),
            is_error=bool(d.get("error", False)),
            is_fd=bool(d.get("fd", False)),
            dlc=None if dlc is None or dlc == len(data) else dlc,
            channel=d.get("channel"),
        )
        return Item(bus, frame)
    return Item(bus, ByteChunk(data, d.get("t"), d.get("direction")), d.get("stream") or "")


def event_from_log(d: dict[str, Any], bus: str) -> SourceEvent:
    """A ``foxglove.Log`` message back to the event it was recorded from."""
    ts = d.get("timestamp") or {}
    t = ts.get("sec", 0) + ts.get("nsec", 0) / 1e9
    return SourceEvent(
        t, bus, d.get("level", 0), d.get("message", ""), d.get("name", ""), d.get("count", 1)
    )


class McapCaptureReader(CaptureReader):
    """An eg2scope recording as a capture: the raw input as Items and the recorded source events
    (lost, reopened, drops, ...) as SourceEvents, in log-time order.

    ``kind`` is "can", "bytes" or "mixed" (from the raw channels' schemas, when known before
    reading); ``metadata`` holds the recording's ``eg2scope`` metadata record (JSON values
    decoded); ``damaged``: the file was not finished or its index is damaged. ``errors`` says
    what was lost.
    """

    def __init__(self, path: str | os.PathLike[str], bus: str | None = None) -> None:
        super().__init__(path, bus)
        self._file = open_recording(self.path)
        try:
            self._recording = _Recording(self._file, self.size)
        except BaseException:
            self._file.close()
            raise
        self.metadata.update(self._recording.metadata)
        kinds = self._recording.raw_kinds
        self.kind = "mixed" if len(kinds) > 1 else next(iter(kinds), "bytes")
        self.damaged = not self._recording.intact
        buses = self._recording.raw_buses
        if bus is not None and len(buses) > 1:
            self._file.close()
            raise UsageError(
                f"{self.path} is a recording of {len(buses)} buses ({', '.join(sorted(buses))}): "
                "--bus would give them one name; leave it out"
            )
        protocols = self._recording.protocols()
        self.protocols = {bus or name: protocol for name, protocol in protocols.items()}

    def _progress(self, position: int) -> None:
        self.position = min(position, self.size)

    def __iter__(self) -> Iterator[Item | SourceEvent]:
        scan = _Scan(self._recording, (RAW, EVENTS), progress=self._progress)
        fixed = self.bus
        buses: dict[int, tuple[str, bool]] = {}  # channel id -> bus, raw or not
        for channel, message in scan.messages():
            known = buses.get(channel.id)
            if known is None:
                known = buses[channel.id] = (
                    fixed or _bus_of(channel),
                    channel.topic.startswith(RAW),
                )
            bus, raw = known
            try:
                if raw:
                    out: Item | SourceEvent = item_from_message(message, bus)
                else:
                    d = orjson.loads(message.data)
                    if d.get("name") == DECODE_PROBLEM:
                        continue  # a record's problem: decoding again finds it again
                    out = event_from_log(d, bus)
            except Exception as exc:
                self.errors.append(
                    f"{channel.topic}: unreadable message at log time {message.log_time}: "
                    f"{_describe(exc)}"
                )
                continue
            yield out
        self.errors += scan.errors
        self.damaged = self.damaged or bool(scan.errors)
        self.position = self.size

    def close(self) -> None:
        self._file.close()


# -- the other topics -----------------------------------------------------------------------------


def _read(
    path: str | os.PathLike[str], prefix: str, errors: list[str] | None
) -> Iterator[tuple[Channel, dict[str, Any]]]:
    with open_recording(path) as f:
        scan = _Scan(_Recording(f, os.fstat(f.fileno()).st_size), (prefix,))
        for channel, message in scan.messages():
            try:
                yield channel, orjson.loads(message.data)
            except orjson.JSONDecodeError as exc:
                scan.errors.append(f"{channel.topic}: unreadable message: {exc}")
    if errors is not None:
        errors += scan.errors


def read_records(path: str | os.PathLike[str], errors: list[str] | None = None) -> Iterator[Record]:
    """The decoded records (``/decoded/*``) as they were recorded, in log-time order.
    Damage is appended to ``errors`` (if given), never raised."""
    for _channel, d in _read(path, DECODED, errors):
        yield Record.from_dict(d)


def read_events(
    path: str | os.PathLike[str], errors: list[str] | None = None
) -> Iterator[SourceEvent]:
    """The ``/events/*`` log as SourceEvents; ``kind`` is the log's name ("decode" for records
    with errors or warnings)."""
    for channel, d in _read(path, EVENTS, errors):
        yield event_from_log(d, _bus_of(channel))


def read_states(
    path: str | os.PathLike[str], errors: list[str] | None = None
) -> Iterator[dict[str, Any]]:
    """The ``/state/<bus>/<device>`` messages (``StateSample.to_dict()``), in log-time order."""
    for _channel, d in _read(path, STATE, errors):
        yield d


def read_metadata(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The recording's ``eg2scope`` metadata record (JSON values decoded); {} if none."""
    with open_recording(path) as f:
        return _Recording(f, os.fstat(f.fileno()).st_size).metadata
