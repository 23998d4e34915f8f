"""Reading an MCAP recording's messages, and recovering what a damaged one holds. An intact file
is read through its index, a damaged one (a recorder killed mid-session, a copy cut short)
chunk by chunk up to the damage. Every chunk is checked against its CRC (and, when indexed,
against the index): a damaged chunk is reported with its byte position and what it held, and
reading goes on with the next one where the file's structure allows. What was lost is reported
in ``errors``, never raised, and never decoded differently in silence. A file that cannot be
opened raises ``OSError``; a pipe or a device is refused (``UsageError``): the reader seeks.
"""

from __future__ import annotations

import io
import os
import stat
import struct
import zlib
from collections.abc import Iterable, Iterator
from typing import IO, Any

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

from decoders.model import EG2_SERIAL, MODBUS_RTU

from ..errors import UsageError
from ..sources.naming import BUS_BY_PROTOCOL
from .layout import CAN_FRAME, DECODED, METADATA_NAME, RAW, RAW_CHUNK, bus_of
from .writer import MAGIC

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


class Recording:
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
                why = describe(exc)
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
                self._raw(bus_of(ch), _KIND_OF_SCHEMA.get(schema.name, "bytes"))
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
                            self._raw(bus_of(rec), kind)
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
            ch.id: bus_of(ch)
            for ch in summary.channels.values()
            if ch.topic.startswith(DECODED) and bus_of(ch) in self.byte_buses
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


def describe(exc: BaseException) -> str:
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
                self.lost = _Lost(start, end, describe(exc), times)
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


class Scan:
    """One pass over the messages of the topics under ``prefixes``, in log-time order, tolerant
    of damage. ``progress`` is called with a byte position now and then. After the pass:
    ``errors`` (what was lost) and ``count`` (messages read)."""

    def __init__(
        self,
        recording: Recording,
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
                self.errors.append(rec.lost_in(ci, summary, describe(exc)).text(rec.size))
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
            why = "cut short" if failure is None or good == size else describe(failure)
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
            f"is damaged ({describe(failure)}); the rest is lost"
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
