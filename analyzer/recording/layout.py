"""The MCAP recording's layout (docs/contracts.md, "MCAP recordings"): its topics, schema
names, JSON schemas, metadata and compression; what the recorder writes and the reader reads.
Every message is JSON with a ``jsonschema`` schema, so Foxglove opens and plots the file as it is:

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
"""

from __future__ import annotations

import binascii
import functools
import importlib.util
import re
from typing import Any, Final

import orjson
from mcap.records import (
    Channel,
)

from decoders.model import CanFrame

from ..model import Item, json_default

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

COMPRESSIONS = {"zstd": "zstd", "lz4": "lz4", "none": ""}  # option -> MCAP compression name
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


dumps_json = functools.partial(orjson.dumps, default=json_default)


def _b64(data: bytes) -> str:
    return binascii.b2a_base64(data, newline=False).decode("ascii")


def metadata_strings(metadata: dict[str, Any]) -> dict[str, str]:
    """MCAP metadata values must be strings: JSON-encode anything else."""
    return {
        str(k): v if isinstance(v, str) else dumps_json(v).decode() for k, v in metadata.items()
    }


def raw_message(item: Item) -> dict[str, Any]:
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


def bus_of(channel: Channel) -> str:
    bus = channel.metadata.get("bus")
    if bus is not None:
        return bus
    rest = channel.topic.partition("/")[2].partition("/")[2]  # /<prefix>/<bus>[/<device>]
    if channel.topic.startswith(STATE):
        rest = rest.rpartition("/")[0]
    return rest
