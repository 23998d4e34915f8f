"""MCAP recording: raw input, decoded records, device state and events in one file.

Layout (DESIGN.md, "MCAP layout"); every message is JSON with a ``jsonschema`` schema, so
Foxglove opens and plots the file as it is:

- ``/raw/<bus>``: raw byte chunks (``eg2scope.RawChunk``) or CAN frames (``eg2scope.CanFrame``),
  bytes in base64. Raw input is the truth: ``eg2scope decode run.mcap`` decodes these again.
- ``/decoded/<bus>``: ``Record.to_dict()`` (``eg2scope.Record``).
- ``/state/<bus>/<device>``: ``DeviceState.to_dict()`` (``eg2scope.DeviceState``), flat, so the
  plot path ``/state/can0/1.opening_mm`` works.
- ``/events/<bus>``: source events and decode problems as ``foxglove.Log``.
- a metadata record named ``eg2scope``: tool version, source settings, passive or not (MCAP
  metadata values are strings, so anything not a string is JSON-encoded).

Log time is the item's ``t`` in nanoseconds (the wall clock when it has none), kept from going
backwards within a topic, so that reading in log-time order keeps every stream in the order it
was recorded; the exact ``t`` is in the message. Every channel carries its bus name in its
metadata (``bus``), since a topic holds only a cleaned-up form of it.

Crash safety: the chunk in progress is compressed, written and the file flushed at least every
``flush_interval_s`` (checked in every write and in ``tick()``, which the live loop calls when
idle), so a recorder killed with SIGKILL loses at most that much; ``McapCaptureReader`` recovers
the rest chunk by chunk. ``close()`` writes the summary and index.

Not thread-safe: one thread (the consumer of the live loop) writes.
"""

from __future__ import annotations

import base64
import contextlib
import os
import re
import time
from datetime import UTC, datetime
from typing import IO, Any

import orjson
from mcap import writer as mcap_writer
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer

from decoders.model import CanFrame, Record

from .. import __version__
from ..lifecycle import Closing
from ..pipeline import Item
from ..sources.live import ERROR, WARNING, SourceEvent

METADATA_NAME = "eg2scope"
RAW_CHUNK = "eg2scope.RawChunk"
CAN_FRAME = "eg2scope.CanFrame"
RECORD = "eg2scope.Record"
DEVICE_STATE = "eg2scope.DeviceState"
FOXGLOVE_LOG = "foxglove.Log"

_B64 = {"type": "string", "contentEncoding": "base64"}
_T = {"type": ["number", "null"], "description": "seconds (epoch or capture clock), or null"}


def _nullable(kind: str, description: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {"type": [kind, "null"]}
    if description:
        out["description"] = description
    return out


SCHEMAS: dict[str, dict[str, Any]] = {
    RAW_CHUNK: {
        "title": RAW_CHUNK,
        "description": "A chunk of bytes as it arrived from a serial line",
        "type": "object",
        "properties": {
            "t": _T,
            "stream": {"type": "string", "description": "byte stream on this bus ('' if one)"},
            "direction": _nullable("string", "request, response, or null when unknown"),
            "data": _B64,
        },
        "required": ["t", "stream", "direction", "data"],
    },
    CAN_FRAME: {
        "title": CAN_FRAME,
        "description": "One CAN frame",
        "type": "object",
        "properties": {
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
        "required": ["t", "id", "extended", "remote", "error", "fd", "dlc", "data"],
    },
    RECORD: {
        "title": RECORD,
        "description": "One decoded frame, or a run of bytes that belongs to no frame",
        "type": "object",
        "properties": {
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
            "errors": {"type": "array", "items": {"type": "string"}},
            "warnings": {"type": "array", "items": {"type": "string"}},
            "summary": {"type": "string"},
            "seq": {"type": "integer"},
            "pair": _nullable("integer"),
            "latency_ms": _nullable("number"),
        },
        "required": ["t", "bus", "protocol", "kind", "length", "raw", "errors", "warnings"],
    },
    DEVICE_STATE: {
        "title": DEVICE_STATE,
        "description": "The state of one gripper, folded from the records of any protocol",
        "type": "object",
        "properties": {
            "bus": {"type": "string"},
            "device": {"type": "integer"},
            "protocol": {"type": "string"},
            "t": _T,
            "opening": _nullable("integer", "0-1000"),
            "opening_mm": _nullable("number", "opening in mm"),
            "force": _nullable("integer", "measured force"),
            "current": _nullable("integer"),
            "temperature_c": _nullable("integer"),
            "state": _nullable("integer"),
            "state_text": _nullable("string"),
            "fault": _nullable("integer"),
            "fault_text": {"type": "array", "items": {"type": "string"}},
            "target_opening": _nullable("integer", "0-1000"),
            "target_mm": _nullable("number"),
            "speed": _nullable("integer"),
            "force_setting": _nullable("integer"),
            "catch_mode": _nullable("integer"),
            "max_opening": _nullable("integer"),
            "min_opening": _nullable("integer"),
            "last_command": _nullable("string"),
            "frames": {"type": "integer"},
            "errors": {"type": "integer"},
            "unanswered": {"type": "integer"},
            "latency_ms": _nullable("number"),
            "extra": {"type": "object"},
        },
        "required": ["bus", "device"],
    },
    FOXGLOVE_LOG: {
        "title": FOXGLOVE_LOG,
        "description": "A log message",
        "type": "object",
        "properties": {
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
            "name": {"type": "string", "description": "what logged it"},
            "file": {"type": "string"},
            "line": {"type": "integer", "minimum": 0},
        },
        "required": ["timestamp", "level", "message", "name", "file", "line"],
    },
}

_COMPRESSIONS = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}
_TOPIC_UNSAFE = re.compile(r"[^A-Za-z0-9_.\-/]+")


def best_compression() -> str:
    """zstd if the installed mcap can write it, else lz4, else none."""
    # the mcap writer imports its compressors optionally and sets them to None when missing
    for name, module in (("zstd", "zstandard"), ("lz4", "lz4")):
        if getattr(mcap_writer, module, None) is not None:
            return name
    return "none"


def topic_part(bus: str) -> str:
    """A bus name as a topic component: ``/dev/ttyUSB0`` -> ``dev/ttyUSB0``,
    ``rfc2217://host:4000`` -> ``rfc2217/host_4000``. The exact name is in the channel's
    metadata."""
    part = _TOPIC_UNSAFE.sub("_", bus.replace("://", "/"))
    part = re.sub(r"/{2,}", "/", part).strip("/")
    return part or "_"


def _default(obj: Any) -> Any:
    """orjson fallback for values decoders may put in ``fields``."""
    if isinstance(obj, bytes | bytearray | memoryview):
        return bytes(obj).hex(" ").upper()
    if isinstance(obj, set | frozenset | tuple):
        return list(obj)
    return str(obj)


_OPTS = orjson.OPT_NON_STR_KEYS


def _dumps(obj: Any) -> bytes:
    return orjson.dumps(obj, default=_default, option=_OPTS)


def _b64(data: bytes) -> str:
    return base64.b64encode(data).decode("ascii")


def metadata_strings(metadata: dict[str, Any]) -> dict[str, str]:
    """MCAP metadata values must be strings: JSON-encode anything else."""
    return {str(k): v if isinstance(v, str) else _dumps(v).decode() for k, v in metadata.items()}


class McapRecorder(Closing):
    """Records a session into an MCAP file (see the module doc for the layout).

    ``metadata``: what to say about the session, e.g. ``{"sources": [{"bus": "can0",
    "interface": "socketcan", "channel": "can0", "bitrate": 500000}], "passive": "yes"}``;
    tool name and version, start time and mcap library are added.
    ``compression``: "zstd", "lz4", "none" or None for the best the installed mcap writes.
    ``log_record_problems``: also put records with errors/warnings on ``/events/<bus>``.
    """

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
        self.compression = compression
        self.flush_interval_s = flush_interval_s
        self.log_record_problems = log_record_problems
        self.messages = 0
        self.closed = False
        self._file: IO[bytes] = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        try:
            self._writer = Writer(
                self._file, chunk_size=chunk_size, compression=_COMPRESSIONS[compression]
            )
            self._writer.start(library=f"eg2scope/{__version__} {LIBRARY_IDENTIFIER}")
            meta: dict[str, Any] = {
                "tool": "eg2scope",
                "version": __version__,
                "started": datetime.now(UTC).isoformat(),
                "mcap": LIBRARY_IDENTIFIER,
            }
            meta.update(metadata or {})
            self._writer.add_metadata(METADATA_NAME, metadata_strings(meta))
            self._flush_file()
        except BaseException:
            self._file.close()
            raise
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._last_time: dict[int, int] = {}  # channel -> last log time written
        self._sequence: dict[int, int] = {}
        self._last_flush = time.monotonic()

    # -- the public API -----------------------------------------------------------------------

    def write_item(self, item: Item) -> None:
        """Raw input: a byte chunk or a CAN frame, on ``/raw/<bus>``."""
        p = item.payload
        if isinstance(p, CanFrame):
            msg: dict[str, Any] = {
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
            schema = CAN_FRAME
        else:
            msg = {"t": p.t, "stream": item.stream, "direction": p.direction, "data": _b64(p.data)}
            schema = RAW_CHUNK
        self._write("/raw/", item.bus, "", schema, p.t, _dumps(msg))

    def write_items(self, items: list[Item]) -> None:
        for item in items:
            self.write_item(item)

    def write_record(self, rec: Record) -> None:
        """A decoded record on ``/decoded/<bus>`` (and on ``/events/<bus>`` if it has
        problems and ``log_record_problems``)."""
        self._write("/decoded/", rec.bus, "", RECORD, rec.t, _dumps(rec.to_dict()))
        if self.log_record_problems and (rec.errors or rec.warnings):
            level = ERROR if rec.errors else WARNING
            what = rec.summary or rec.name or rec.kind
            if rec.device is not None:
                what = f"ID {rec.device} {what}"
            text = "; ".join(rec.errors + rec.warnings)
            self._log(rec.bus, rec.t, level, f"{what}: {text}", "decode", rec.seq)

    def write_records(self, records: list[Record]) -> None:
        for rec in records:
            self.write_record(rec)

    def write_state(self, state: Any) -> None:
        """A device state (``DeviceState`` or its ``to_dict()``) on ``/state/<bus>/<device>``."""
        d: dict[str, Any] = state if isinstance(state, dict) else state.to_dict()
        suffix = f"/{d['device']}"
        self._write("/state/", str(d["bus"]), suffix, DEVICE_STATE, d.get("t"), _dumps(d))

    def write_event(self, ev: SourceEvent) -> None:
        """A source event (port lost, drops, passive, ...) as ``foxglove.Log``."""
        self._log(ev.bus, ev.t, ev.level, ev.message, ev.kind, 0)

    def tick(self) -> None:
        """Call when idle: writes the chunk in progress if flush_interval_s has passed."""
        if time.monotonic() - self._last_flush >= self.flush_interval_s:
            self.flush()

    def flush(self) -> None:
        """Compress and write the chunk in progress and flush the file, now."""
        if self.closed:
            return
        flush = getattr(self._writer, "flush", None)
        if flush is not None:  # public in mcap 1.6.0 (checked): ends the chunk, flushes the file
            flush()
        else:  # older mcap: only the private name-mangled method ends the chunk
            self._writer._Writer__finalize_chunk()  # type: ignore[attr-defined]
            self._writer._Writer__flush()  # type: ignore[attr-defined]
            self._file.flush()
        self._last_flush = time.monotonic()

    def close(self) -> None:
        """Finish the file: last chunk, summary, index, footer. Safe to call twice."""
        if self.closed:
            return
        self.closed = True
        try:
            self._writer.finish()
        finally:
            self._file.close()

    # -- internals ------------------------------------------------------------------------------

    def _flush_file(self) -> None:
        with contextlib.suppress(OSError, ValueError):
            self._file.flush()

    def _log(
        self, bus: str, t: float | None, level: int, message: str, name: str, line: int
    ) -> None:
        ts = time.time() if t is None else t
        ns = round(ts * 1e9)
        msg = {
            "timestamp": {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000},
            "level": level,
            "message": message,
            "name": name,
            "file": bus,
            "line": max(0, line),
        }
        self._write("/events/", bus, "", FOXGLOVE_LOG, ts, _dumps(msg))

    def _write(
        self, prefix: str, bus: str, suffix: str, schema: str, t: float | None, data: bytes
    ) -> None:
        if self.closed:
            raise ValueError(f"MCAP recording {self.path} is closed")
        key = prefix + bus + suffix
        channel = self._channels.get(key)
        if channel is None:
            channel = self._new_channel(key, prefix + topic_part(bus) + suffix, bus, schema)
        log_time = time.time_ns() if t is None else int(t * 1e9) if t > 0 else 0
        last = self._last_time[channel]
        if log_time < last:  # keep a topic's log times monotonic (exact t is in the message)
            log_time = last
        self._last_time[channel] = log_time
        seq = self._sequence[channel] = (self._sequence[channel] + 1) & 0xFFFFFFFF  # uint32
        self._writer.add_message(channel, log_time, data, log_time, seq)
        self.messages += 1
        if time.monotonic() - self._last_flush >= self.flush_interval_s:
            self.flush()

    def _new_channel(self, key: str, topic: str, bus: str, schema: str) -> int:
        schema_id = self._schemas.get(schema)
        if schema_id is None:
            schema_id = self._schemas[schema] = self._writer.register_schema(
                schema, "jsonschema", _dumps(SCHEMAS[schema])
            )
        channel = self._writer.register_channel(topic, "json", schema_id, {"bus": bus})
        self._channels[key] = channel
        self._last_time[channel] = 0
        self._sequence[channel] = 0
        return channel
