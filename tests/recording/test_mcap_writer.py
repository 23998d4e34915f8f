"""The recorder's MCAP writer (``analyzer.recording.writer``) writes the file mcap's own ``Writer``
writes message by message, byte for byte, while adding messages a batch at a time; and the
recorder's clock conversion gives every message its log time without a Python step per message
when the times are plain numbers."""

from __future__ import annotations

import contextlib
import io
import itertools
import math
import random
import time
from typing import Any

import pytest
from mcap.exceptions import EndOfFile
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer

from analyzer.recording.recorder import _LAST_NS, _log_times, _ns
from analyzer.recording.writer import McapWriter

LIBRARY_COMPRESSION = {
    "": CompressionType.NONE,
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
}
T0_NS = 1_763_700_000 * 10**9


def random_messages(n: int, seed: int = 7) -> list[tuple[int, int, bytes]]:
    """(log time, channel 1-4, data): times never decrease, some equal; data 0-90 bytes."""
    rng = random.Random(seed)
    t, out = T0_NS, []
    for _ in range(n):
        t += rng.choice((0, 0, 1, 120_000, 5_000_000))
        out.append((t, rng.randint(1, 4), rng.randbytes(rng.randint(0, 90))))
    return out


def written(
    ours: bool, compression: str, chunk_size: int, messages: list[Any]
) -> tuple[bytes, int]:
    """A file with metadata, schemas and channels registered before and between messages,
    messages in batches of random size (ours) or one at a time (the library); and how many
    messages it holds."""
    rng = random.Random(3)
    out = io.BytesIO()
    if ours:
        writer: Any = McapWriter(out, chunk_size, compression, library="test")
    else:
        writer = Writer(out, chunk_size=chunk_size, compression=LIBRARY_COMPRESSION[compression])
        writer.start(library="test")
    writer.add_metadata("m", {"k": "v"})
    schema = writer.register_schema("s", "jsonschema", b"{}")
    for n in range(3):
        writer.register_channel(f"/c{n}", "json", schema, {"bus": f"b{n}"})
    cuts = sorted(rng.sample(range(1, len(messages)), min(60, len(messages) - 1)))
    count = 0
    for k, (begin, end) in enumerate(itertools.pairwise([0, *cuts, len(messages)])):
        if k == 20:  # a channel (and its schema) first used mid-recording
            other = writer.register_schema("s2", "jsonschema", b'{"type": "object"}')
            writer.register_channel("/c3", "json", other, {})
        if k == 40:
            writer.add_metadata("later", {"a": "b"})
        batch = [m for m in messages[begin:end] if k >= 20 or m[1] != 4]
        count += len(batch)
        if not batch:
            continue
        if ours:
            log_times, channels, datas = (list(x) for x in zip(*batch, strict=True))
            writer.add_messages(log_times, channels, datas)
        else:
            for log_time, channel, data in batch:
                writer.add_message(channel, log_time, data, log_time)
    writer.finish()
    return out.getvalue(), count


@pytest.mark.parametrize("compression", ["", "zstd", "lz4"])
@pytest.mark.parametrize("chunk_size", [1, 700, 2048, 1 << 20])
def test_the_writer_writes_the_bytes_the_library_writes(compression: str, chunk_size: int) -> None:
    """Chunk boundaries (a chunk ends after the message that takes it past its size; a
    message larger than a chunk gets one of its own), schemas and channels in the chunk in
    progress, metadata between chunks, message indexes, statistics, summary, footer CRC."""
    messages = random_messages(3000)
    library, count = written(False, compression, chunk_size, messages)
    ours, _ = written(True, compression, chunk_size, messages)
    assert ours == library
    with io.BytesIO(ours) as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == count > 2500
    assert (len(summary.chunk_indexes) > 1) == (chunk_size < 1 << 20)


@pytest.mark.parametrize("count", [0, 1])
def test_a_file_with_few_messages_is_the_library_s(count: int) -> None:
    """No message at all (schemas and channels never reach a chunk), or a single one."""
    messages = random_messages(2)[:count]

    def one(ours: bool) -> bytes:
        out = io.BytesIO()
        if ours:
            writer: Any = McapWriter(out, 2048, "zstd", library="x")
        else:
            writer = Writer(out, chunk_size=2048, compression=CompressionType.ZSTD)
            writer.start(library="x")
        schema = writer.register_schema("s", "jsonschema", b"{}")
        for n in range(4):
            writer.register_channel(f"/c{n}", "json", schema, {})
        for log_time, channel, data in messages:
            if ours:
                writer.add_messages([log_time], [channel], [data])
            else:
                writer.add_message(channel, log_time, data, log_time)
        writer.finish()
        return out.getvalue()

    assert one(True) == one(False)


def test_flush_ends_the_chunk_in_progress_for_a_reader() -> None:
    """What was added before a flush is in the file, readable chunk by chunk, before the
    writer finishes (a recorder killed after it loses nothing of it)."""
    out = io.BytesIO()
    writer = McapWriter(out, 1 << 20, "zstd")
    schema = writer.register_schema("s", "jsonschema", b"{}")
    channel = writer.register_channel("/c", "json", schema, {})
    writer.add_messages([T0_NS, T0_NS + 1], [channel, channel], [b'{"a":1}', b'{"a":2}'])
    writer.flush()
    writer.add_messages([T0_NS + 2], [channel], [b'{"a":3}'])  # in memory: not yet in the file
    datas = [m.data for m in mcap_messages_so_far(out.getvalue())]
    assert datas == [b'{"a":1}', b'{"a":2}']
    writer.finish()
    datas = [m.data for m in mcap_messages_so_far(out.getvalue())]
    assert datas == [b'{"a":1}', b'{"a":2}', b'{"a":3}']


def mcap_messages_so_far(data: bytes) -> list[Message]:
    """The messages of an MCAP file, read record by record up to where it ends."""
    messages = []
    with contextlib.suppress(EndOfFile):
        for record in StreamReader(io.BytesIO(data), emit_chunks=True).records:
            if isinstance(record, Chunk):
                parts = breakup_chunk(record, validate_crc=True)
                messages += [m for m in parts if isinstance(m, Message)]
    return messages


TIMES: list[list[float | None]] = [
    [],
    [1_763_700_000.5, 1_763_700_000.25, 1_763_700_001.0],
    [0.0, 1e-9, 12.5],
    [1_763_700_000.5, None, 1_763_700_000.6],
    [-5.0, 1_763_700_000.0],
    [float("nan"), 1.0],
    [float("inf"), 1.0, float("-inf")],
    [1e30, 1.0],
    [_LAST_NS / 1e9, 1.0],
]


@pytest.mark.parametrize("times", TIMES)
def test_log_times_are_the_times_in_ns_with_nonsense_pinned(times: list[float | None]) -> None:
    before = time.time_ns()
    got = _log_times(times)
    after = time.time_ns()
    assert len(got) == len(times)
    for t, ns in zip(times, got, strict=True):
        if t is None:
            assert before <= ns <= after  # the wall clock
        else:
            assert ns == _ns(t)
            assert 0 <= ns <= _LAST_NS
            if math.isfinite(t) and 0 < t < 1e10:
                assert ns == int(t * 1e9)
