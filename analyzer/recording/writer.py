"""An MCAP writer for a live recorder: the file mcap's ``Writer`` writes, at a fraction of the cost.

The layout is the library's, record for record: magic and header; schemas and channels in the
chunk in progress; chunks ending after the message that takes them past ``chunk_size``, each
followed by one message index per channel (in the order the channels first appear in it);
metadata records between chunks; the summary (schemas, channels, statistics, chunk and metadata
indexes, summary offsets) and the footer. Every record but a message and a message index is
written by the library's own record classes, and the bytes are the library's, compressed or
not (zstd at the library's level).

Why not the library's ``Writer``: at three messages per CAN frame its per-message path costs
more than all the rest of a recording. It builds a ``Message`` object per message and writes it,
and its index, a field at a time, and compresses each chunk with a new zstd context. Here
messages come a batch at a time (``add_messages``: headers packed and joined in C), a chunk's
message indexes are built in one piece with numpy when it ends, and one zstd context is kept.

Not thread-safe: one thread writes.
"""

from __future__ import annotations

import struct
import zlib
from bisect import bisect_right
from collections.abc import Callable, Sequence
from itertools import accumulate, chain, repeat
from operator import add
from typing import IO, Final

import numpy as np
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    McapRecord,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

MAGIC: Final = b"\x89MCAP0\r\n"
ZSTD_LEVEL: Final = 3  # the library's (zstandard.compress's default)

_MESSAGE = struct.Struct("<BQHIQQ")  # opcode, length, channel, sequence, log and publish time
_MESSAGE_FIELDS = _MESSAGE.size - 9  # the length counts what follows opcode and length
_MESSAGE_OPCODE = int(Opcode.MESSAGE)
_INDEX = struct.Struct("<BQHI")  # opcode, length, channel, byte length of the entries
_INDEX_OPCODE = int(Opcode.MESSAGE_INDEX)
_FOOTER = struct.Struct("<BQQQ")  # opcode, length, summary start, summary offsets start


def compressor(name: str) -> Callable[[bytes], bytes]:
    """The chunk compressor an MCAP compression name stands for ("zstd", "lz4" or "" for
    none); ImportError if its module is not installed."""
    if name == "zstd":
        import zstandard

        return zstandard.ZstdCompressor(level=ZSTD_LEVEL).compress
    if name == "lz4":
        import lz4.frame

        return lz4.frame.compress
    if name == "":
        return bytes
    raise ValueError(f"unknown MCAP compression {name!r}")


class McapWriter:
    """Writes an MCAP file to ``stream`` (its magic and header at once); ``compression`` is
    "zstd", "lz4" or "" (none). ``library`` goes into the header."""

    def __init__(
        self,
        stream: IO[bytes],
        chunk_size: int = 1 << 20,
        compression: str = "zstd",
        library: str = "",
    ) -> None:
        self._stream = stream
        self._compress = compressor(compression)
        self.compression = compression
        self.chunk_size = chunk_size
        self._position = 0  # bytes written to the stream so far
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._statistics = Statistics(
            attachment_count=0,
            channel_count=0,
            channel_message_counts={},
            chunk_count=0,
            message_count=0,
            metadata_count=0,
            message_start_time=0,
            message_end_time=0,
            schema_count=0,
        )
        # the chunk in progress: its records so far, their length, and per message its log
        # time, channel and offset (for the message indexes)
        self._parts: list[bytes] = []
        self._size = 0
        self._times: list[int] = []
        self._ids: list[int] = []
        self._offsets: list[int] = []
        self._write(MAGIC)
        self._write_record(Header(profile="", library=library))

    # -- records outside the hot path ----------------------------------------------------------

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas.append(schema)
        self._statistics.schema_count += 1
        self._add_to_chunk(schema)
        return schema.id

    def register_channel(
        self, topic: str, message_encoding: str, schema_id: int, metadata: dict[str, str]
    ) -> int:
        channel = Channel(
            id=len(self._channels) + 1,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata=metadata,
        )
        self._channels.append(channel)
        self._statistics.channel_count += 1
        self._add_to_chunk(channel)
        return channel.id

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """A metadata record (between chunks: the chunk in progress stays open)."""
        offset = self._position
        length = self._write_record(Metadata(name=name, metadata=data))
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=length, name=name))
        self._statistics.metadata_count += 1

    # -- messages ------------------------------------------------------------------------------

    def add_messages(
        self, log_times: Sequence[int], channel_ids: Sequence[int], datas: Sequence[bytes]
    ) -> None:
        """Messages (sequence 0, publish time = log time) in the order given; ``log_times``
        must not decrease, here or from one call to the next."""
        while datas:
            # where each message would start in the chunk in progress, and where the last ends
            sizes = map(add, map(len, datas), repeat(_MESSAGE.size))
            offsets = list(accumulate(sizes, initial=self._size))
            # as the library: the chunk ends after the message that takes it past its size
            n = bisect_right(offsets, self.chunk_size, lo=1)
            if n > len(datas):  # all of them fit
                self._append(log_times, channel_ids, datas, offsets)
                return
            self._append(log_times[:n], channel_ids[:n], datas[:n], offsets[: n + 1])
            self._end_chunk()
            log_times, channel_ids, datas = log_times[n:], channel_ids[n:], datas[n:]

    def _append(
        self,
        log_times: Sequence[int],
        channel_ids: Sequence[int],
        datas: Sequence[bytes],
        offsets: list[int],
    ) -> None:
        lengths = map(add, map(len, datas), repeat(_MESSAGE_FIELDS))
        headers = map(
            _MESSAGE.pack, repeat(_MESSAGE_OPCODE), lengths, channel_ids, repeat(0), log_times,
            log_times,
        )  # fmt: skip
        self._parts.append(b"".join(chain.from_iterable(zip(headers, datas, strict=True))))
        self._size = offsets.pop()
        self._times += log_times
        self._ids += channel_ids
        self._offsets += offsets

    # -- chunks and the end --------------------------------------------------------------------

    def flush(self) -> None:
        """End the chunk in progress (if it holds a message) and flush the stream: a reader
        finds everything added so far."""
        self._end_chunk()
        self._stream.flush()

    def finish(self) -> None:
        """The last chunk, the summary and the footer. The stream is left open."""
        self._end_chunk()
        self._write_record(DataEnd(data_section_crc=0))
        summary_start = self._position
        summary = RecordBuilder()
        offsets = []
        groups: tuple[tuple[Opcode, Sequence[McapRecord]], ...] = (
            (Opcode.SCHEMA, self._schemas),
            (Opcode.CHANNEL, self._channels),
            (Opcode.STATISTICS, [self._statistics]),
            (Opcode.CHUNK_INDEX, self._chunk_indexes),
            (Opcode.ATTACHMENT_INDEX, []),
            (Opcode.METADATA_INDEX, self._metadata_indexes),
        )
        for opcode, records in groups:
            start = summary.count
            for record in records:
                record.write(summary)
            offsets.append(SummaryOffset(opcode, summary_start + start, summary.count - start))
        offsets_start = summary_start + summary.count
        for offset in offsets:
            offset.write(summary)
        data = summary.end()
        # the footer's CRC covers the summary and the footer up to the CRC itself
        footer_head = _FOOTER.pack(Opcode.FOOTER, 20, summary_start, offsets_start)
        crc = zlib.crc32(footer_head, zlib.crc32(data))
        self._write(data)
        self._write_record(Footer(summary_start, offsets_start, crc))
        self._write(MAGIC)
        self._stream.flush()

    def _end_chunk(self) -> None:
        """Compress and write the chunk in progress, then its message indexes. A chunk
        without messages is not written: its schemas and channels go into the next one."""
        if not self._times:
            return
        data = b"".join(self._parts)
        compressed = self._compress(data)
        start, end = self._times[0], self._times[-1]
        chunk_start = self._position
        chunk_length = self._write_record(
            Chunk(
                compression=self.compression,
                data=compressed,
                message_start_time=start,
                message_end_time=end,
                uncompressed_crc=zlib.crc32(data),
                uncompressed_size=len(data),
            )
        )
        index_offsets, indexes = self._message_indexes(self._position)
        self._write(indexes)
        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=start,
                message_end_time=end,
                chunk_start_offset=chunk_start,
                chunk_length=chunk_length,
                message_index_offsets=index_offsets,
                message_index_length=len(indexes),
                compression=self.compression,
                compressed_size=len(compressed),
                uncompressed_size=len(data),
            )
        )
        stats = self._statistics
        if stats.message_count == 0:
            stats.message_start_time = start
        stats.message_end_time = max(stats.message_end_time, end)
        stats.message_count += len(self._times)
        stats.chunk_count += 1
        self._parts, self._size = [], 0
        self._times, self._ids, self._offsets = [], [], []

    def _message_indexes(self, position: int) -> tuple[dict[int, int], bytes]:
        """The chunk's message index records (one per channel, (log time, offset) entries in
        the order the messages came), written from ``position`` on, and where each starts.
        Counts each channel's messages into the statistics."""
        ids = np.array(self._ids)
        by_channel = np.argsort(ids, kind="stable")  # each channel's messages, in order
        entries = np.empty((len(ids), 2), dtype="<u8")
        entries[:, 0] = np.array(self._times, dtype=np.uint64)[by_channel]
        entries[:, 1] = np.array(self._offsets, dtype=np.uint64)[by_channel]
        grouped = ids[by_channel]
        starts = np.flatnonzero(np.diff(grouped, prepend=-1))  # where each channel's run begins
        ends = np.append(starts[1:], len(ids)).tolist()
        channels, starts_list = grouped[starts].tolist(), starts.tolist()
        totals = self._statistics.channel_message_counts
        offsets: dict[int, int] = {}
        parts: list[bytes | memoryview] = []  # headers, and rows of entries
        # channels in the order they first appear (the first of each run is its first)
        for k in np.argsort(by_channel[starts]).tolist():
            channel, begin, end = channels[k], starts_list[k], ends[k]
            size = 16 * (end - begin)
            offsets[channel] = position
            head = _INDEX.pack(_INDEX_OPCODE, 6 + size, channel, size)
            parts += (head, entries[begin:end].data)
            position += _INDEX.size + size
            totals[channel] = totals.get(channel, 0) + end - begin
        return offsets, b"".join(parts)

    def _add_to_chunk(self, record: Schema | Channel) -> None:
        builder = RecordBuilder()
        record.write(builder)
        data = builder.end()
        self._parts.append(data)
        self._size += len(data)
        if self._size > self.chunk_size:
            self._end_chunk()

    def _write_record(self, record: Header | Metadata | Chunk | DataEnd | Footer) -> int:
        builder = RecordBuilder()
        record.write(builder)
        data = builder.end()
        self._write(data)
        return len(data)

    def _write(self, data: bytes) -> None:
        self._stream.write(data)
        self._position += len(data)
