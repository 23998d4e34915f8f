"""Damaged recordings, made real: bytes flipped inside chunks (compressed or not, finished file
or one a killed recorder left), files cut at every kind of place, a damaged index. What was
lost is reported with its place; nothing is ever decoded differently in silence."""

from __future__ import annotations

import shutil
import struct
from collections import Counter
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.records import ChunkIndex, Message
from mcap_checks import assert_time_ordered

from analyzer.model import INFO, Item, SourceEvent
from analyzer.recording.reader import (
    McapCaptureReader,
    item_from_message,
    read_events,
    read_records,
)
from analyzer.recording.recorder import McapRecorder
from analyzer.recording.recovery import Recording
from analyzer.session.batches import RecordSequence
from decoders.model import CanFrame, Chunk, Record

T0 = 1_763_700_000.0
META = {"passive": "yes"}


def many_items(n: int) -> list[Item]:
    out = []
    for i in range(n):
        t = T0 + i * 1e-3
        if i % 3:
            out.append(Item("can0", CanFrame(t, 0x100 + i % 7, i.to_bytes(4, "little"))))
        else:
            out.append(Item("ttyUSB0", Chunk(i.to_bytes(4, "little"), t, "request"), "tx"))
    return out


def note(i: int, t: float) -> Record:
    return Record(
        t=t,
        bus="can0",
        protocol="can",
        kind="frame",
        length=1,
        raw=bytes([i % 256]),
        index=i,
        seq=i,
        summary=f"r{i}",
    )


def write(rec: McapRecorder, items: list[Item]) -> None:
    """Items in small batches, a record and an event every 40 items, as a session does."""
    for k in range(0, len(items), 10):
        part = items[k : k + 10]
        rec.on_raw(part)
        if k % 40 == 0:
            t = part[0].payload.t or 0
            rec.on_records(RecordSequence([note(k, t)]))
            rec.on_event(SourceEvent(t, "can0", INFO, f"e{k}", "info"))
        rec.tick(0.0)


def replayed(path: Path) -> tuple[list[Item | SourceEvent], list[str]]:
    with McapCaptureReader(path) as reader:
        return list(reader), reader.errors


def chunk_indexes(path: Path) -> list[ChunkIndex]:
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)


def held_in(path: Path, ci: ChunkIndex) -> list[Item | SourceEvent]:
    """What replaying reads from one chunk of an intact file."""
    with path.open("rb") as f:
        rec = Recording(f, path.stat().st_size)
        assert rec.summary is not None
        channels = rec.summary.channels
        out: list[Item | SourceEvent] = []
        for m in rec.chunk_at(ci):
            if isinstance(m, Message):
                ch = channels[m.channel_id]
                if ch.topic.startswith("/raw/"):
                    out.append(item_from_message(m, ch.metadata["bus"]))
    return out


@pytest.fixture(params=["none", "zstd", "lz4"])
def finished(request: pytest.FixtureRequest, tmp_path: Path) -> Path:
    path = tmp_path / f"{request.param}.mcap"
    with McapRecorder(path, META, chunk_size=600, compression=request.param) as rec:
        write(rec, many_items(120))
    assert_time_ordered(path)
    return path


def flip(data: bytes, pos: int, mask: int) -> bytes:
    out = bytearray(data)
    out[pos] ^= mask
    return bytes(out)


def flips_of(ci: ChunkIndex) -> list[tuple[int, int]]:
    """(position, mask) of the flips tried in one chunk: every bit of its record header
    (opcode, length), two bits of every byte of its chunk header, one bit of every third byte
    of its records (the CRC covers them all alike)."""
    start, end = ci.chunk_start_offset, ci.chunk_start_offset + ci.chunk_length
    header = 9 + 8 + 8 + 8 + 4 + 4 + len(ci.compression) + 8
    out = [(pos, 1 << bit) for pos in range(start, start + 9) for bit in range(8)]
    out += [(pos, mask) for pos in range(start + 9, start + header) for mask in (0x01, 0x80)]
    return out + [(pos, 1 << pos % 8) for pos in range(start + header, end, 3)]


def is_subsequence(part: list[object], whole: list[object]) -> bool:
    it = iter(whole)
    return all(any(x == y for y in it) for x in part)


def test_a_flipped_byte_in_any_chunk_byte_is_reported_and_the_rest_read(
    finished: Path, tmp_path: Path
) -> None:
    """Every byte of one chunk of a finished file, flipped in turn (its record header, its
    chunk header, its records): the chunk is reported with its byte range and what it held,
    every other chunk is read, and nothing comes out different. Compressed data has a few
    bits its format ignores: a flip there must leave the replay identical."""
    data = finished.read_bytes()
    size = len(data)
    whole, errors = replayed(finished)
    assert errors == []
    chunks = chunk_indexes(finished)
    assert len(chunks) > 6
    ci = chunks[3]
    lost = held_in(finished, ci)
    assert lost and all(x in whole for x in lost)
    rest = [x for x in whole if not (isinstance(x, Item) and x in lost)]
    start, end = ci.chunk_start_offset, ci.chunk_start_offset + ci.chunk_length
    where = f"damaged chunk at bytes {start}-{end - 1} of {size} ("
    damaged = tmp_path / "flipped.mcap"
    flips = silent = 0
    for pos, mask in flips_of(ci):
        damaged.write_bytes(flip(data, pos, mask))
        got, errors = replayed(damaged)
        flips += 1
        if not errors and finished.stem != "none":  # a bit the compression ignores
            assert got == whole, (pos, mask)
            silent += 1
            continue
        assert got == rest, (pos, mask, errors)
        assert len(errors) == 1 and errors[0].startswith(where), (pos, mask, errors)
        assert "on /raw/can0" in errors[0] and "log time " in errors[0], errors
        if pos % 17 == 0:  # the decoded records' reader skips the chunk if it holds any
            rec_errors: list[str] = []
            notes = [r.summary for r in read_records(damaged, rec_errors)]
            assert is_subsequence(notes, [f"r{k}" for k in range(0, 120, 40)])
            assert all(e.startswith(where) for e in rec_errors), (pos, mask)
            assert bool(rec_errors) == (len(notes) < 3), (pos, mask)
    assert silent <= flips // 50, (silent, flips)


def test_the_lost_chunk_report_counts_every_topic(finished: Path, tmp_path: Path) -> None:
    data = finished.read_bytes()
    with finished.open("rb") as f:
        rec = Recording(f, len(data))
        assert rec.summary is not None
        channels = rec.summary.channels
        # a chunk holding a decoded record and an event besides raw input
        for ci in chunk_indexes(finished):
            counts = Counter(
                channels[m.channel_id].topic for m in rec.chunk_at(ci) if isinstance(m, Message)
            )
            if {"/decoded/can0", "/events/can0"} < set(counts):
                break
    assert {"/decoded/can0", "/events/can0"} < set(counts)
    pos = ci.chunk_start_offset + ci.chunk_length - 5  # inside its records
    damaged = tmp_path / "flipped.mcap"
    damaged.write_bytes(flip(data, pos, 0x10))
    _got, errors = replayed(damaged)
    assert len(errors) == 1
    per_topic = ", ".join(f"{counts[t]} on {t}" for t in sorted(counts))
    t0, t1 = ci.message_start_time / 1e9, ci.message_end_time / 1e9
    assert errors[0].endswith(
        f": lost {sum(counts.values())} messages ({per_topic}), log time {t0:.6f} to "
        f"{t1:.6f} s; read on after it"
    )


def test_a_flipped_byte_in_a_recording_left_unfinished(finished: Path, tmp_path: Path) -> None:
    """A killed recorder's file has no index: chunks are read one after the other. A flipped
    byte in a chunk's records fails its CRC: reported with its place, reading goes on. A flip
    in its header is reported too, and never yields anything that was not recorded."""
    compression = finished.stem
    items = many_items(120)
    path, copy = tmp_path / "live.mcap", tmp_path / "copy.mcap"
    rec = McapRecorder(path, META, chunk_size=600, compression=compression)
    write(rec, items)
    rec.flush()
    shutil.copyfile(path, copy)  # what SIGKILL leaves: everything flushed, no index
    rec.close()
    whole, baseline = replayed(copy)
    assert len(baseline) == 1 and "it was not finished" in baseline[0]
    assert [x for x in whole if isinstance(x, Item)] == items
    data = copy.read_bytes()
    ci = chunk_indexes(path)[3]  # the copy holds the finished file's chunks at the same places
    start, end = ci.chunk_start_offset, ci.chunk_start_offset + ci.chunk_length
    header = 9 + 8 + 8 + 8 + 4 + 4 + len(ci.compression) + 8  # the records start here
    lost = held_in(path, ci)
    rest = [x for x in whole if not (isinstance(x, Item) and x in lost)]
    damaged = tmp_path / "flipped.mcap"
    for pos, mask in flips_of(ci):
        damaged.write_bytes(flip(data, pos, mask))
        got, errors = replayed(damaged)
        assert is_subsequence(got, whole), (pos, mask)
        if errors == baseline and compression != "none":  # a bit the compression ignores
            assert got == whole and pos >= start + header, (pos, mask)
            continue
        assert errors, (pos, mask)
        if pos >= start + header:  # inside the records: the CRC; then the missing index
            assert got == rest and len(errors) == 2, (pos, mask, errors)
            assert errors[0].startswith(f"damaged chunk at bytes {start}-{end - 1} of ")
        elif len(errors) == 1:  # its framing is gone: reading stops there, and says so
            assert errors[0].startswith("recovered a damaged recording: read "), errors
            assert f" of {len(data)}" in errors[0] and "the rest is lost" in errors[0]


def test_a_damaged_index_is_reported_and_everything_read(finished: Path, tmp_path: Path) -> None:
    """The summary (schemas, channels, chunk index) and footer at the end have their own CRC:
    a flip there makes the reader distrust the index and read the chunks one by one."""
    data = finished.read_bytes()
    # the footer: opcode, length, summary start, summary offset start, CRC, then the magic
    summary_start = struct.unpack_from("<Q", data, len(data) - 8 - 20)[0]
    whole, _ = replayed(finished)
    damaged = tmp_path / "index.mcap"
    for pos in range(summary_start, len(data) - 8 - 4, 61):
        damaged.write_bytes(flip(data, pos, 0x04))
        got, errors = replayed(damaged)
        assert got == whole, pos
        assert errors[0].startswith("the index at the end of the recording is damaged"), pos
        assert len(errors) == 1 or "the end of the recording is damaged" in errors[1], errors


# -- files cut short ------------------------------------------------------------------------------


def test_open_recording_copied_mid_session_is_recovered(tmp_path: Path) -> None:
    """What a SIGKILL leaves: the file as it is while the recorder is still open, after a
    flush period; everything written before the flush is there, with one clear message."""
    items = many_items(300)
    path, copy = tmp_path / "live.mcap", tmp_path / "copy.mcap"
    rec = McapRecorder(path, META, flush_interval_s=3600)
    rec.on_raw(items[:200])
    rec.flush_interval_s = 0.0
    rec.tick(0.0)  # what the session does after every batch: the interval has passed
    rec.flush_interval_s = 3600
    rec.on_raw(items[200:])
    rec.tick(0.0)  # gathered and written to the chunk in progress: not on disk yet
    shutil.copyfile(path, copy)
    rec.close()
    assert_time_ordered(copy, finished=False)
    assert_time_ordered(path)
    size = copy.stat().st_size
    with McapCaptureReader(copy) as reader:
        assert reader.damaged
        assert reader.metadata["passive"] == "yes"
        assert reader.kind == "mixed"
        assert list(reader) == items[:200]
        assert reader.errors == [
            f"recovered a damaged recording: read all 200 /raw and /events messages in its "
            f"{size} bytes; it was not finished (no index: the recorder was killed or did not "
            "close it), so what it had not yet written is lost"
        ]
    with McapCaptureReader(path) as reader:
        assert list(reader) == items  # the finished file has it all


def test_a_cut_mid_record_says_so_once(tmp_path: Path) -> None:
    """Cut inside a chunk: one message that names the byte where the whole records end;
    never 'up to byte N of N' next to 'ends in the middle of a record'."""
    items = many_items(300)
    path = tmp_path / "whole.mcap"
    with McapRecorder(path, META, chunk_size=1500) as rec:
        write(rec, items)
    ci = chunk_indexes(path)[2]
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: ci.chunk_start_offset + ci.chunk_length // 2])
    size = cut.stat().st_size
    got, errors = replayed(cut)
    got_items = [x for x in got if isinstance(x, Item)]
    assert got_items and got_items == items[: len(got_items)]
    assert errors == [
        f"recovered a damaged recording: read {len(got)} /raw and /events messages; the file "
        f"is cut short in the middle of a record at byte {ci.chunk_start_offset} of {size} "
        "(the recorder was killed or the copy cut), so the rest is lost"
    ]


def test_truncated_at_any_offset_never_raises(tmp_path: Path) -> None:
    items = many_items(240)
    path = tmp_path / "whole.mcap"
    with McapRecorder(path, META, chunk_size=1500) as rec:
        write(rec, items)
    data = path.read_bytes()
    size = len(data)
    chunks = chunk_indexes(path)
    assert len(chunks) > 5
    data_end = max(c.chunk_start_offset + c.chunk_length for c in chunks)
    offsets = sorted(
        {0, 1, 7, 8, 9, 20, 60, size - 1, size - 8, size - 9, size - 30}
        | set(range(0, size, max(1, size // 37)))
        | {c.chunk_start_offset + d for c in chunks[:4] for d in (0, 1, 30)}
    )
    cut = tmp_path / "cut.mcap"
    previous = -1
    for off in offsets:
        cut.write_bytes(data[:off])
        got, errors = replayed(cut)
        got_items = [x for x in got if isinstance(x, Item)]
        assert got_items == items[: len(got_items)], off  # a prefix, in order
        assert len(errors) == 1, (off, errors)  # one message, whatever the cut
        message = errors[0]
        assert not ("ends in the middle" in message and f"of {off}" in message), message
        assert len(got) >= previous, off  # more bytes never give fewer items
        previous = len(got)
        if off > data_end + 64:  # only the summary/footer is cut: nothing lost
            assert len(got_items) == len(items), off
            assert "all " in message, message
        recs_errors: list[str] = []
        recs = list(read_records(cut, recs_errors))
        evs = list(read_events(cut, recs_errors))
        assert [r.seq for r in recs] == list(range(0, 40 * len(recs), 40))
        assert [e.message for e in evs] == [f"e{40 * k}" for k in range(len(evs))]
        assert recs_errors


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "the recording is empty"),
        (b"not an mcap file at all, just some bytes " * 3, "not an MCAP file"),
        (bytes(range(256)) * 4, "not an MCAP file"),
        (b"\x89MCAP", "the recording is cut short: it has only 5 bytes"),
        (b"\x89MCAP0\r\n", "recovered a damaged recording: read all 0"),
    ],
)
def test_what_is_not_a_recording(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "x.mcap"
    path.write_bytes(content)
    got, errors = replayed(path)
    assert got == [] and len(errors) == 1 and errors[0].startswith(message), errors
    assert "killed" not in errors[0] or content.startswith(b"\x89MCAP0")
    rec_errors: list[str] = []
    assert list(read_records(path, rec_errors)) == [] and len(rec_errors) == 1
    assert rec_errors[0].startswith(message)
