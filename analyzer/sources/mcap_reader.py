"""eg2scope MCAP recordings read back: raw input again as Items, decoded records, events.

``McapCaptureReader`` (registered for ``.mcap``) yields the ``/raw/*`` topics as pipeline Items
in log-time order, so ``eg2scope decode run.mcap`` decodes the raw input again with the
current decoders. ``read_records``, ``read_events``, ``read_states`` and ``read_metadata`` read
the other topics (layout: ``analyzer/sinks/mcap.py``).

An intact file is read through its index (``mcap.reader.make_reader``). A damaged one (no
summary or footer: a recorder killed mid-session, a file cut short in a copy) is read chunk by
chunk with ``mcap.stream_reader.StreamReader`` up to the damage; what was lost is reported in
``errors``, never raised.
"""

from __future__ import annotations

import base64
import os
import struct
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import orjson
from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.summary import Summary

from decoders.model import CanFrame, Record
from decoders.model import Chunk as ByteChunk

from ..pipeline import Item
from .capture import CaptureReader, register_reader
from .live import SourceEvent

METADATA_NAME = "eg2scope"
CAN_FRAME = "eg2scope.CanFrame"
RAW_CHUNK = "eg2scope.RawChunk"
MAGIC = b"\x89MCAP0\r\n"

RAW, DECODED, STATE, EVENTS = "/raw/", "/decoded/", "/state/", "/events/"
_KIND_OF_SCHEMA = {CAN_FRAME: "can", RAW_CHUNK: "bytes"}


def _bus_of(channel: Channel, prefix: str) -> str:
    bus = channel.metadata.get("bus")
    if bus is not None:
        return bus
    rest = channel.topic[len(prefix) :]
    if prefix == STATE:  # /state/<bus>/<device>
        rest = rest.rpartition("/")[0]
    return rest


def _decode_metadata(values: dict[str, str]) -> dict[str, Any]:
    """Values were JSON-encoded unless they were strings: decode what decodes."""
    out: dict[str, Any] = {}
    for k, v in values.items():
        try:
            out[k] = orjson.loads(v)
        except orjson.JSONDecodeError:
            out[k] = v
    return out


_Pending = tuple[int, int, int, Channel, Message]  # log time, chunk offset, index, channel, msg


class _Merge:
    """Log-time order across chunks whose time ranges overlap (topics written by different
    threads interleave at chunk boundaries): chunks are held until one starts after all of
    them end, then released sorted by (log time, chunk offset, index), the order of the mcap
    library's log-time reader, without its per-message heap."""

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


@dataclass
class _Scan:
    """One pass over the messages of the topics under ``prefix``, tolerant of damage.

    ``progress`` is called with a byte position now and then. After the pass: ``errors``,
    ``metadata``, ``count``.
    """

    path: Path
    prefix: str
    progress: Callable[[int], None] | None = None
    errors: list[str] = field(default_factory=list)
    metadata: dict[str, Any] = field(default_factory=dict)
    count: int = 0
    size: int = 0

    def messages(self) -> Iterator[tuple[Channel, Message]]:
        self.size = self.path.stat().st_size
        with self.path.open("rb") as f:
            summary = None
            if _has_footer(f, self.size):
                try:
                    reader = make_reader(f)
                    summary = reader.get_summary()
                    if summary is not None:
                        self._metadata_indexed(reader)
                except Exception:
                    summary = None  # no usable index: read it as a stream
            if summary is not None and summary.chunk_indexes:
                yield from self._indexed(f, summary)
                return
            f.seek(0)
            yield from self._streamed(f)

    def _wanted(self, channels: Iterable[Channel]) -> dict[int, Channel]:
        return {ch.id: ch for ch in channels if ch.topic.startswith(self.prefix)}

    # -- intact: through the summary and chunk index ---------------------------------------------

    def _metadata_indexed(self, reader: Any) -> None:
        for meta in reader.iter_metadata():
            if meta.name == METADATA_NAME:
                self.metadata.update(_decode_metadata(meta.metadata))

    def _indexed(self, f: IO[bytes], summary: Summary) -> Iterator[tuple[Channel, Message]]:
        """The chunks holding the wanted channels, in log-time order (as the mcap reader's
        ``iter_messages``, which spends most of its time in a per-message heap)."""
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
        progress = self.progress
        done, total = 0, max(1, sum(c.chunk_length for c in chunks))
        try:
            for ci in chunks:
                f.seek(ci.chunk_start_offset + 1 + 8)  # opcode and record length
                chunk = Chunk.read(ReadDataStream(f))
                msgs = _pick(breakup_chunk(chunk), ci.chunk_start_offset, channels)
                ready = merge.add(
                    ci.message_start_time, ci.message_end_time, ci.chunk_start_offset, msgs
                )
                done += ci.chunk_length
                for m in ready:
                    self.count += 1
                    yield m[3], m[4]
                if progress is not None:
                    progress(done * self.size // total)
            for m in merge.release():
                self.count += 1
                yield m[3], m[4]
        except Exception as exc:
            self.errors.append(
                f"damaged recording: read {self.count} {_what(self.prefix)} messages, then "
                f"{_describe(exc)}; the rest is lost"
            )

    # -- damaged (or unindexed): chunk by chunk, up to the damage -------------------------------

    def _streamed(self, f: IO[bytes]) -> Iterator[tuple[Channel, Message]]:
        records = StreamReader(f, emit_chunks=True, record_size_limit=max(self.size, 1)).records
        channels: dict[int, Channel] = {}
        wanted: dict[int, Channel] = {}
        good = 0  # end of the last record read whole
        data_end = footer = False
        failure: BaseException | None = None
        prefix, progress = self.prefix, self.progress
        merge = _Merge()  # in file order: chunks are held only while their times overlap
        while not footer:
            ready: list[_Pending] = []
            try:
                record = next(records)
                if isinstance(record, Chunk):
                    parts = breakup_chunk(record, validate_crc=True)
                    for rec in parts:
                        if isinstance(rec, Channel):
                            channels[rec.id] = rec
                            if rec.topic.startswith(prefix):
                                wanted[rec.id] = rec
                    ready = merge.add(
                        record.message_start_time,
                        record.message_end_time,
                        good,
                        _pick(parts, good, wanted),
                    )
                elif isinstance(record, Message):  # an unchunked file
                    ready = merge.add(
                        record.log_time, record.log_time, good, _pick([record], good, wanted)
                    )
                elif isinstance(record, Channel):
                    channels[record.id] = record
                    if record.topic.startswith(prefix):
                        wanted[record.id] = record
                elif isinstance(record, Metadata) and record.name == METADATA_NAME:
                    self.metadata.update(_decode_metadata(record.metadata))
                elif isinstance(record, DataEnd):
                    data_end = True
                elif isinstance(record, Footer):
                    footer = True
            except StopIteration:
                break
            except Exception as exc:
                failure = exc
                break
            good = f.tell()
            if ready:
                for m in ready:
                    self.count += 1
                    yield m[3], m[4]
                if progress is not None:
                    progress(good)
        for m in merge.release():  # everything read whole before the damage
            self.count += 1
            yield m[3], m[4]
        if footer and failure is None:
            if f.read(len(MAGIC) + 1) == MAGIC:
                return  # an intact file without an index: nothing lost
            failure = ValueError("its closing magic bytes are missing")
            data_end = True
        if failure is None:
            why = "it ends before its footer"
        elif _cut_short(f, good, self.size):
            why = "the file ends in the middle of a record: the recorder was killed or the copy cut"
        else:
            why = _describe(failure)
        if self.size == 0:
            self.errors.append("the recording is empty")
            return
        if data_end:
            self.errors.append(
                f"the end of the recording is damaged ({why}): its index is lost, but all "
                f"{self.count} {_what(prefix)} messages were read"
            )
        elif good <= len(MAGIC) and not channels:
            self.errors.append(f"not a readable MCAP recording ({why})")
        else:
            self.errors.append(
                f"recovered a damaged recording: read {self.count} {_what(prefix)} messages up "
                f"to byte {good} of {self.size}; the rest is lost ({why})"
            )


def _what(prefix: str) -> str:
    return prefix.strip("/") or "all"


def _describe(exc: BaseException) -> str:
    text = str(exc)
    name = type(exc).__name__
    if name == "EndOfFile" or not text:
        return "the file ends in the middle of a record" if name == "EndOfFile" else name
    return f"{name}: {text}"


def _cut_short(f: IO[bytes], good: int, size: int) -> bool:
    """Whether the record after the last good one runs past the end of the file."""
    if size - good < 9:
        return True
    try:
        f.seek(good)
        opcode_length = f.read(9)
        length = struct.unpack_from("<Q", opcode_length, 1)[0]
    except (OSError, ValueError, struct.error):
        return True
    return bool(good + 9 + length > size)


def _has_footer(f: IO[bytes], size: int) -> bool:
    """Cheap check before trusting the index: the file ends with the MCAP magic."""
    if size < 2 * len(MAGIC) + 30:
        return False
    f.seek(size - len(MAGIC))
    ok = f.read(len(MAGIC)) == MAGIC
    f.seek(0)
    return ok


# -- raw input again ------------------------------------------------------------------------------


def item_from_message(channel: Channel, message: Message, bus: str) -> Item:
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


class McapCaptureReader(CaptureReader):
    """An eg2scope recording as a capture: the raw topics, as Items, in log-time order.

    ``kind`` is "can", "bytes" or "mixed" (from the raw channels' schemas, when known before
    reading); ``metadata`` holds the recording's ``eg2scope`` metadata record (JSON values
    decoded). ``errors`` says what was lost if the file is damaged.
    """

    def __init__(self, path: str | os.PathLike[str], bus: str | None = None) -> None:
        super().__init__(path, bus)
        self.kind = "bytes"
        self.damaged = False
        self._probe()

    def _probe(self) -> None:
        """Metadata and the kind of raw input, before reading: from the summary if intact,
        else from the records before (and in) the first chunk."""
        kinds: set[str] = set()
        try:
            with self.path.open("rb") as f:
                if _has_footer(f, self.size):
                    try:
                        reader = make_reader(f)
                        summary = reader.get_summary()
                        if summary is not None:
                            for ch in summary.channels.values():
                                schema = summary.schemas.get(ch.schema_id)
                                if ch.topic.startswith(RAW) and schema is not None:
                                    kinds.add(_KIND_OF_SCHEMA.get(schema.name, "bytes"))
                            for meta in reader.iter_metadata():
                                if meta.name == METADATA_NAME:
                                    self.metadata.update(_decode_metadata(meta.metadata))
                            self._set_kind(kinds)
                            return
                    except Exception:
                        f.seek(0)
                self.damaged = True
                self._probe_stream(f, kinds)
        except Exception:
            pass  # reported when read
        self._set_kind(kinds)

    def _probe_stream(self, f: IO[bytes], kinds: set[str]) -> None:
        schemas: dict[int, str] = {}
        for record in StreamReader(f, emit_chunks=True, record_size_limit=self.size).records:
            if isinstance(record, Metadata) and record.name == METADATA_NAME:
                self.metadata.update(_decode_metadata(record.metadata))
            elif isinstance(record, Chunk):
                for rec in breakup_chunk(record):
                    if isinstance(rec, Schema):
                        schemas[rec.id] = rec.name
                    elif isinstance(rec, Channel) and rec.topic.startswith(RAW):
                        kinds.add(_KIND_OF_SCHEMA.get(schemas.get(rec.schema_id, ""), "bytes"))
                return

    def _set_kind(self, kinds: set[str]) -> None:
        if len(kinds) == 1:
            self.kind = kinds.pop()
        elif kinds:
            self.kind = "mixed"

    def _progress(self, position: int) -> None:
        self.position = min(position, self.size)

    def __iter__(self) -> Iterator[Item]:
        scan = _Scan(self.path, RAW, progress=self._progress)
        fixed = self.bus
        buses: dict[int, str] = {}
        try:
            for channel, message in scan.messages():
                bus = fixed or buses.get(channel.id)
                if bus is None:
                    bus = buses[channel.id] = _bus_of(channel, RAW)
                try:
                    item = item_from_message(channel, message, bus)
                except Exception as exc:
                    self.errors.append(
                        f"{channel.topic}: unreadable message at log time {message.log_time}: "
                        f"{_describe(exc)}"
                    )
                    continue
                yield item
        except Exception as exc:  # never raise on a damaged file
            self.errors.append(f"damaged recording: {_describe(exc)}; the rest is lost")
        if scan.metadata:
            self.metadata.update(scan.metadata)
        self.errors += scan.errors
        self.damaged = self.damaged or bool(scan.errors)
        self.position = self.size


register_reader(".mcap", McapCaptureReader)


# -- the other topics -----------------------------------------------------------------------------


def _read(
    path: str | os.PathLike[str], prefix: str, errors: list[str] | None
) -> Iterator[tuple[Channel, dict[str, Any]]]:
    scan = _Scan(Path(path), prefix)
    try:
        for channel, message in scan.messages():
            try:
                yield channel, orjson.loads(message.data)
            except orjson.JSONDecodeError as exc:
                scan.errors.append(f"{channel.topic}: unreadable message: {exc}")
    except Exception as exc:
        scan.errors.append(f"damaged recording: {_describe(exc)}; the rest is lost")
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
    """The ``/events/*`` log (``foxglove.Log``) as SourceEvents; ``kind`` is the log's name
    ("decode" for records with errors or warnings)."""
    for channel, d in _read(path, EVENTS, errors):
        ts = d.get("timestamp") or {}
        t = ts.get("sec", 0) + ts.get("nsec", 0) / 1e9
        yield SourceEvent(
            t, _bus_of(channel, EVENTS), d.get("level", 0), d.get("message", ""), d.get("name", "")
        )


def read_states(
    path: str | os.PathLike[str], errors: list[str] | None = None
) -> Iterator[dict[str, Any]]:
    """The ``/state/<bus>/<device>`` messages (``DeviceState.to_dict()``), in log-time order."""
    for _channel, d in _read(path, STATE, errors):
        yield d


def read_metadata(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The recording's ``eg2scope`` metadata record (JSON values decoded); {} if none."""
    return McapCaptureReader(path).metadata
