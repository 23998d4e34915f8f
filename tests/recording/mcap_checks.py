"""Checks on MCAP files that every test making a recording runs on it.

``assert_time_ordered`` is ``mcap doctor --strict-message-order`` in Python (the mcap CLI is a Go
program the test machines do not have): read record by record in file order, every chunk's CRC
checks out, every chunk's time range is its messages', and no message's log time is below any
before it, across all channels. Importable from any test folder as ``recording.mcap_checks``.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import orjson
from mcap.exceptions import EndOfFile
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk


def assert_time_ordered(path: Path, finished: bool = True) -> int:
    """Fails unless log times never decrease in file order; returns the number of messages.
    ``finished=False``: a file a killed recorder left, checked up to where it ends."""
    latest = 0
    count = 0
    with path.open("rb") as f:
        for record in _records(f, finished):
            if isinstance(record, Chunk):
                parts = breakup_chunk(record, validate_crc=True)
                msgs = [m for m in parts if isinstance(m, Message)]
                if msgs:
                    times = [m.log_time for m in msgs]
                    assert (record.message_start_time, record.message_end_time) == (
                        min(times),
                        max(times),
                    )
            elif isinstance(record, Message):
                msgs = [record]
            else:
                continue
            for m in msgs:
                assert m.log_time >= latest, (
                    f"{path}: message {count} (channel {m.channel_id}) has log time "
                    f"{m.log_time}, less than the latest log time {latest}"
                )
                latest = m.log_time
                count += 1
    return count


def _records(f: IO[bytes], finished: bool) -> Iterator[Any]:
    records = StreamReader(f, emit_chunks=True, validate_crcs=True).records
    if finished:
        yield from records
        return
    try:
        yield from records
    except (EndOfFile, struct.error):
        pass  # the end a killed recorder left


def mcap_messages(path: Path) -> list[tuple[str, str, str, str, int, Any]]:
    """(topic, schema name, schema encoding, message encoding, log time, message) of every
    message in file order, through the mcap library's own reader."""
    with path.open("rb") as f:
        reader = make_reader(f)
        return [
            (ch.topic, sc.name, sc.encoding, ch.message_encoding, m.log_time, orjson.loads(m.data))
            for sc, ch, m in reader.iter_messages(log_time_order=False)
            if sc is not None
        ]
