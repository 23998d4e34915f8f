"""Reading an MCAP recording back: its raw input as a capture (``McapCaptureReader``, replayed
through a session and decoded again), and its records, events, state samples and metadata
(``read_records``, ``read_events``, ``read_states``, ``read_metadata``). The file is read by
recovery.py: through its index, or chunk by chunk up to the damage, which is reported.
"""

from __future__ import annotations

import base64
import os
from collections.abc import Iterator
from typing import Any

import orjson
from mcap.records import (
    Channel,
    Message,
)

from decoders.model import CanFrame, Record
from decoders.model import Chunk as ByteChunk

from ..errors import UsageError
from ..model import Item, SourceEvent
from ..sources.capture import CaptureReader
from .layout import DECODE_PROBLEM, DECODED, EVENTS, RAW, STATE, bus_of
from .recovery import Recording, Scan, describe, open_recording


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
            self._recording = Recording(self._file, self.size)
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
        scan = Scan(self._recording, (RAW, EVENTS), progress=self._progress)
        fixed = self.bus
        buses: dict[int, tuple[str, bool]] = {}  # channel id -> bus, raw or not
        for channel, message in scan.messages():
            known = buses.get(channel.id)
            if known is None:
                known = buses[channel.id] = (
                    fixed or bus_of(channel),
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
                    f"{describe(exc)}"
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
        scan = Scan(Recording(f, os.fstat(f.fileno()).st_size), (prefix,))
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
        yield event_from_log(d, bus_of(channel))


def read_states(
    path: str | os.PathLike[str], errors: list[str] | None = None
) -> Iterator[dict[str, Any]]:
    """The ``/state/<bus>/<device>`` messages (``StateSample.to_dict()``), in log-time order."""
    for _channel, d in _read(path, STATE, errors):
        yield d


def read_metadata(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The recording's ``eg2scope`` metadata record (JSON values decoded); {} if none."""
    with open_recording(path) as f:
        return Recording(f, os.fstat(f.fileno()).st_size).metadata
