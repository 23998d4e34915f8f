"""CAN capture files: python-can's own writers, read back through open_can_file."""

from __future__ import annotations

import gzip
import random
import shutil
from pathlib import Path
from typing import Any

import can
import pytest

from analyzer.sources import mf4
from analyzer.sources.can_files import (
    CAN_READERS,
    MAX_ERRORS,
    CandumpReader,
    PythonCanFileReader,
    TrcReader,
    is_can_file,
    open_can_file,
)
from analyzer.sources.can_message import message_to_frame
from decoders.model import CanFrame

T0 = 1600000000.0


def _msg(dt: float, **kw: Any) -> can.Message:
    kw.setdefault("channel", "can0")
    return can.Message(timestamp=T0 + dt, **kw)


# every kind of frame a capture can hold: EG2 traffic, foreign, remote, error, FD, empty
MESSAGES = [
    _msg(0.123456, arbitration_id=0x04FF0001, data=bytes.fromhex("0000F401F401")),
    _msg(0.124001, arbitration_id=0x04FF0001, data=b"\x06"),
    _msg(0.125, arbitration_id=0x01180001, data=b"\x08"),
    _msg(
        0.125321,
        arbitration_id=0x01180001,
        data=bytes.fromhex("F3000300000022 00".replace(" ", "")),
    ),
    _msg(0.2, arbitration_id=0x011A3FFF, data=bytes.fromhex("0800000000000000")),
    _msg(0.3, arbitration_id=0x123, is_extended_id=False, data=b"\x01\x02\x03"),
    _msg(0.31, arbitration_id=0x7FF, is_extended_id=False, data=b""),
    _msg(0.32, arbitration_id=0x000, is_extended_id=False, data=bytes(8)),
    _msg(0.33, arbitration_id=0x01180002, data=b""),
    _msg(0.4, arbitration_id=0x123, is_extended_id=False, is_remote_frame=True, dlc=5),
    _msg(0.41, arbitration_id=0x04FF0001, is_remote_frame=True, dlc=6),
    _msg(0.5, is_error_frame=True),
    _msg(0.6, arbitration_id=0x1ABCDEF, is_fd=True, bitrate_switch=True, data=bytes(range(12))),
    _msg(0.61, arbitration_id=0x123, is_extended_id=False, is_fd=True, data=bytes(range(64))),
    _msg(1.0, arbitration_id=0x1FFFFFFF, data=b"\xff" * 8),
]

# what each format keeps: kinds of frame, timestamp precision, channel, remote DLC
FORMATS: dict[str, dict[str, Any]] = {
    ".log": {
        "kinds": {"data", "remote", "error", "fd"},
        "t_abs": 1e-6,
        "channel": "can0",
        "remote_dlc": False,
    },
    ".asc": {
        "kinds": {"data", "remote", "error", "fd"},
        "t_abs": 1e-3,
        "channel": "0",
        "remote_dlc": True,
    },
    ".blf": {
        "kinds": {"data", "remote", "error", "fd"},
        "t_abs": 1e-6,
        "channel": "0",
        "remote_dlc": True,
    },
    ".csv": {
        "kinds": {"data", "remote", "error", "fd"},
        "t_abs": 1e-6,
        "channel": None,
        "remote_dlc": True,
    },
    ".trc": {"kinds": {"data"}, "t_abs": 1e-6, "channel": "1", "remote_dlc": True},
}


def _kind(msg: can.Message) -> str:
    if msg.is_error_frame:
        return "error"
    if msg.is_remote_frame:
        return "remote"
    if msg.is_fd:
        return "fd"
    return "data"


def write_capture(path: Path, messages: list[can.Message]) -> None:
    with can.Logger(str(path)) as logger:
        for m in messages:
            logger.on_message_received(m)


def read_all(path: Path) -> tuple[list[CanFrame], Any]:
    with open_can_file(path) as reader:
        frames = list(reader)
    return frames, reader


@pytest.mark.parametrize("suffix", sorted(FORMATS))
def test_roundtrip_python_can_writers(tmp_path: Path, suffix: str) -> None:
    spec = FORMATS[suffix]
    path = tmp_path / f"capture{suffix}"
    write_capture(path, MESSAGES)
    frames, reader = read_all(path)
    assert reader.errors == []
    expected = [m for m in MESSAGES if _kind(m) in spec["kinds"]]
    assert len(frames) == len(expected)
    assert reader.frames == len(expected)
    start = frames[0].t
    assert start is not None
    assert abs(start - expected[0].timestamp) <= spec["t_abs"]
    for fr, m in zip(frames, expected, strict=True):
        assert isinstance(fr, CanFrame)
        assert fr.t is not None
        assert fr.t == pytest.approx(m.timestamp, abs=spec["t_abs"])
        # spacing between frames is kept to the microsecond in every format
        assert fr.t - start == pytest.approx(m.timestamp - expected[0].timestamp, abs=2e-6)
        assert fr.is_error == m.is_error_frame
        assert fr.is_remote == m.is_remote_frame
        assert fr.is_fd == m.is_fd
        assert fr.channel == spec["channel"]
        if m.is_error_frame:
            continue  # the identifier of an error frame is the error class, format-specific
        assert fr.arbitration_id == m.arbitration_id
        assert fr.is_extended == m.is_extended_id
        assert fr.data == bytes(m.data)
        if m.is_remote_frame:
            assert fr.data == b""
            assert fr.dlc == (m.dlc if spec["remote_dlc"] else 0)
        else:
            assert fr.dlc == m.dlc == len(fr.data)
            assert fr.length == len(m.data)


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf", ".csv", ".trc"])
def test_roundtrip_many_frames(tmp_path: Path, suffix: str) -> None:
    msgs = [
        _msg(
            i * 0.000731,
            arbitration_id=(0x01180001 + (i % 3)),
            data=(i * 7919).to_bytes(4, "little") * 2,
        )
        for i in range(5000)
    ]
    path = tmp_path / f"many{suffix}"
    write_capture(path, msgs)
    frames, reader = read_all(path)
    assert reader.errors == []
    assert [f.data for f in frames] == [bytes(m.data) for m in msgs]
    assert [f.arbitration_id for f in frames] == [m.arbitration_id for m in msgs]


def test_candump_matches_python_can_reader(tmp_path: Path) -> None:
    path = tmp_path / "capture.log"
    write_capture(path, MESSAGES)
    ours = list(CandumpReader(path))
    theirs = [message_to_frame(m) for m in can.CanutilsLogReader(str(path))]
    assert len(ours) == len(theirs)
    for a, b in zip(ours, theirs, strict=True):
        if b.is_error:
            assert a.is_error and a.arbitration_id == 0x80  # python-can drops the error class
            continue
        assert a == b


FF8 = b"\xff" * 8

# -- candump lines ----------------------------------------------------------------------------

CANDUMP_LINES = [
    (
        "(1600000000.123456) can0 04FF0001#0000F401F401",
        dict(
            t=1600000000.123456,
            arbitration_id=0x04FF0001,
            data=bytes.fromhex("0000F401F401"),
            dlc=6,
            channel="can0",
        ),
    ),
    (
        "(0.000000) vcan0 123#010203",
        dict(
            t=0.0,
            arbitration_id=0x123,
            is_extended=False,
            data=b"\x01\x02\x03",
            dlc=3,
            channel="vcan0",
        ),
    ),
    (
        "(1.5) can1 7FF#",
        dict(t=1.5, arbitration_id=0x7FF, is_extended=False, data=b"", dlc=0, channel="can1"),
    ),
    ("(1.5) can0 00000123#11", dict(arbitration_id=0x123, is_extended=True, data=b"\x11")),
    (
        "(1.5) can0 123#R",
        dict(arbitration_id=0x123, is_extended=False, is_remote=True, data=b"", dlc=0),
    ),
    ("(1.5) can0 123#R5", dict(arbitration_id=0x123, is_remote=True, dlc=5)),
    (
        "(1.5) can0 04FF0001#r8",
        dict(arbitration_id=0x04FF0001, is_extended=True, is_remote=True, dlc=8),
    ),
    (
        "(1.5) can0 20000080#0000000000000000",
        dict(arbitration_id=0x80, is_error=True, data=bytes(8), dlc=8),
    ),
    ("(1.5) can0 20000004#0004000000000000", dict(arbitration_id=0x04, is_error=True)),
    ("(1.5) can0 20000080#", dict(arbitration_id=0x80, is_error=True, data=b"", dlc=0)),
    (
        "(1.5) can0 123##1" + "AB" * 12,
        dict(arbitration_id=0x123, is_fd=True, data=b"\xab" * 12, dlc=12, is_extended=False),
    ),
    (
        "(1.5) can0 01ABCDEF##0" + "00" * 64,
        dict(arbitration_id=0x01ABCDEF, is_fd=True, data=bytes(64), dlc=64),
    ),
    ("(1.5) can0 123##3", dict(is_fd=True, data=b"", dlc=0)),
    ("(1.5) can0 123#1122334455667788_F", dict(data=bytes.fromhex("1122334455667788"), dlc=15)),
    # more than 8 bytes after one "#": CAN FD written without its "##" (cantools reads it)
    ("(1.5) can0 064#F001FFFFFFFFFFFFFFFF", dict(is_fd=True, dlc=10, data=b"\xf0\x01" + FF8)),
    ("(1.5) can0 04FF0001#06 R", dict(arbitration_id=0x04FF0001, data=b"\x06")),
    ("(1.5) can0 04FF0001#06 T", dict(arbitration_id=0x04FF0001, data=b"\x06")),
    ("(1.5) can0 04ff0001#0a0B", dict(arbitration_id=0x04FF0001, data=b"\x0a\x0b")),
    ("(1.5) can0 84FF0001#06", dict(arbitration_id=0x04FF0001, is_extended=True)),  # EFF flag
    ("  (1.5)   can0   123#01  ", dict(arbitration_id=0x123, data=b"\x01")),
    ("(1.5) can0 123#01\r", dict(arbitration_id=0x123, data=b"\x01")),
]


@pytest.mark.parametrize("line,expected", CANDUMP_LINES, ids=[c[0][:40] for c in CANDUMP_LINES])
def test_candump_lines(tmp_path: Path, line: str, expected: dict[str, Any]) -> None:
    path = tmp_path / "one.log"
    path.write_bytes(line.encode() + b"\n")
    with CandumpReader(path) as reader:
        frames = list(reader)
    assert reader.errors == []
    assert len(frames) == 1
    fr = frames[0]
    for key, want in expected.items():
        assert getattr(fr, key) == want, key


BAD_LINES = [
    "garbage line",
    "(1600000000.000003) can0 04FF0001#0G",
    "(1600000000.000004) can0 123456789#00",
    "(1600000000.000005) can0 800#00",
    "(1600000000.000006) can0 01180001#08 X",
    "1600000000.000007 can0 01180001#08",
    "(1600000000.000008) can0 01180001",
    "(1600000000.000009) can0 01180001#080",
    "(1600000000.000010) can0 01180001#" + "00" * 65,  # more than CAN FD's 64 bytes
    "(abc) can0 01180001#08",
    "(1.0) can0 -1180001#08",
    "(1.0) can0 #08",
    "(1.0) can0 123#R5X",
    "(1.0) can0 123##",
    "(1.0) can0 123##G00",
    "(1.0) can0 123#1122_F",
    "(1.0) can0 123#1122334455667788_3",
    "(1.0) can0",
    "(1.0) can0 123#01 R extra",
    "(1.0) can0 4FF00001#00",  # 31 bits: must not be masked to the EG2 frame 0FF00001
    "(1.0) can0 C4FF0001#00",  # bit 30 (no flag of candump's) with the EFF flag
]


@pytest.mark.parametrize("line", BAD_LINES)
def test_candump_bad_line(tmp_path: Path, line: str) -> None:
    path = tmp_path / "bad.log"
    path.write_text(f"(1.0) can0 123#01\n{line}\n(2.0) can0 123#02\n")
    with CandumpReader(path) as reader:
        frames = list(reader)
    assert [f.data for f in frames] == [b"\x01", b"\x02"]
    assert reader.bad_lines == 1
    assert len(reader.errors) == 1
    assert reader.errors[0].startswith("line 2: cannot parse:")


def test_candump_with_malformed_lines(tmp_path: Path) -> None:
    good = [
        "(1600000000.000001) can0 04FF0001#0000F401F401",
        "(1600000000.000002) can0 04FF0001#06",
        "(1600000000.000011) can0 01180001#08",
    ]
    lines = [good[0], "", "# a comment", "   ", *BAD_LINES[:5], good[1], *BAD_LINES[5:], good[2]]
    path = tmp_path / "damaged.log"
    body = "\n".join(lines).encode() + b"\n\xff\xfe not ascii \x00\n(1600000000.000012) can0 0118"
    path.write_bytes(body)
    with open_can_file(path) as reader:
        frames = list(reader)
    assert isinstance(reader, CandumpReader)
    assert [f.t for f in frames] == [1600000000.000001, 1600000000.000002, 1600000000.000011]
    assert [f.data for f in frames] == [bytes.fromhex("0000F401F401"), b"\x06", b"\x08"]
    assert reader.bad_lines == len(BAD_LINES) + 2
    assert len(reader.errors) == reader.bad_lines
    assert all(": cannot parse: " in e for e in reader.errors)
    assert reader.errors[0].startswith("line 5: ")  # after the blank and comment lines
    assert reader.errors[-1].startswith(f"line {len(lines) + 2}: ")  # the cut last line
    assert "truncated" in reader.errors[-1]


def test_candump_errors_are_capped(tmp_path: Path) -> None:
    path = tmp_path / "noise.log"
    path.write_text("(1.0) can0 123#01\n" + "junk\n" * 500)
    with CandumpReader(path) as reader:
        frames = list(reader)
    assert len(frames) == 1
    assert reader.bad_lines == 500
    assert len(reader.errors) == MAX_ERRORS + 1
    assert reader.errors[-1] == "further errors not listed"


def test_candump_gzip_and_cut_gzip(tmp_path: Path) -> None:
    lines = "".join(f"({T0 + i * 0.001:.6f}) can0 01180001#{i % 256:02X}\n" for i in range(20000))
    whole = tmp_path / "capture.log.gz"
    whole.write_bytes(gzip.compress(lines.encode()))
    frames, reader = read_all(whole)
    assert len(frames) == 20000 and reader.errors == []
    cut = tmp_path / "cut.log.gz"
    cut.write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])
    frames, reader = read_all(cut)
    assert 0 < len(frames) < 20000
    assert [f.data[0] for f in frames] == [i % 256 for i in range(len(frames))]
    assert reader.errors[-1].endswith(": the compressed file is cut short; the rest is lost")


def test_candump_tell_moves(tmp_path: Path) -> None:
    path = tmp_path / "big.log"
    path.write_text("".join(f"({i}.0) can0 123#{i % 256:02X}\n" for i in range(100000)))
    size = path.stat().st_size
    with CandumpReader(path) as reader:
        seen = []
        for i, _ in enumerate(reader):
            if i % 25000 == 0:
                seen.append(reader.tell())
    assert all(0 < p <= size for p in seen)
    assert seen == sorted(seen)


# -- damaged python-can formats ---------------------------------------------------------------


def _many(n: int) -> list[can.Message]:
    return [
        _msg(i * 0.001, arbitration_id=0x01180001, data=i.to_bytes(4, "little") * 2)
        for i in range(n)
    ]


def test_truncated_blf(tmp_path: Path) -> None:
    msgs = _many(3000)
    path = tmp_path / "whole.blf"
    write_capture(path, msgs)
    cut = tmp_path / "cut.blf"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    frames, reader = read_all(cut)  # must not raise
    assert 0 < len(frames) < len(msgs)
    for fr, m in zip(frames, msgs, strict=False):
        assert fr.data == bytes(m.data)
        assert fr.t == pytest.approx(m.timestamp, abs=1e-6)
    assert reader.errors
    assert "truncated" in reader.errors[0]


@pytest.mark.parametrize("keep", [100, 150, 160, 200])
def test_blf_cut_near_the_header(tmp_path: Path, keep: int) -> None:
    path = tmp_path / "whole.blf"
    write_capture(path, _many(100))
    cut = tmp_path / "cut.blf"
    cut.write_bytes(path.read_bytes()[:keep])
    frames, reader = read_all(cut)
    assert frames == []
    assert reader.errors


def test_blf_bad_header(tmp_path: Path) -> None:
    path = tmp_path / "bad.blf"
    write_capture(path, _many(10))
    path.write_bytes(b"XXXX" + path.read_bytes()[4:])
    frames, reader = read_all(path)
    assert frames == []
    assert reader.errors and "cannot open" in reader.errors[0]


def test_blf_never_finished(tmp_path: Path) -> None:
    """A writer killed before stop(): the header still states the bare header size."""
    path = tmp_path / "killed.blf"
    writer = can.BLFWriter(str(path))
    for m in _many(10):
        writer.on_message_received(m)
    writer._flush()  # what a periodic flush leaves on disk
    writer.file.flush()
    shutil.copy(path, tmp_path / "copy.blf")
    writer.stop()
    frames, reader = read_all(tmp_path / "copy.blf")
    assert len(frames) == 10
    assert reader.errors == []
    assert reader.warnings and "did not finish" in reader.warnings[0]


def test_csv_with_a_bad_row(tmp_path: Path) -> None:
    path = tmp_path / "bad.csv"
    write_capture(path, _many(20))
    lines = path.read_text().splitlines()
    lines.insert(11, "this,is,not,a,frame")
    path.write_text("\n".join(lines) + "\n")
    frames, reader = read_all(path)
    assert [f.data for f in frames] == [bytes(m.data) for m in _many(20)]  # read on after it
    assert len(reader.errors) == 1
    assert reader.errors[0].startswith("line 12: cannot parse: 'this,is,not,a,frame' (")


@pytest.mark.parametrize(
    "date", ["someday", "Mon someday at noon"], ids=["no date", "unreadable date"]
)
def test_asc_with_unreadable_start_date(tmp_path: Path, date: str) -> None:
    path = tmp_path / "odd.asc"
    write_capture(path, _many(5))
    text = path.read_text().splitlines()
    text = [f"Begin Triggerblock {date}" if ln.startswith("Begin Tr") else ln for ln in text]
    text = [f"date {date}" if ln.startswith("date") else ln for ln in text]
    path.write_text("\n".join(text) + "\n")
    frames, reader = read_all(path)
    assert len(frames) == 5
    assert reader.errors == []
    assert reader.warnings and "relative" in reader.warnings[0]
    assert frames[0].t == pytest.approx(0.0)
    assert frames[4].t == pytest.approx(0.004)


@pytest.mark.parametrize("suffix", [".asc", ".blf", ".csv", ".trc"])
def test_gzip_python_can_formats(tmp_path: Path, suffix: str) -> None:
    path = tmp_path / f"capture{suffix}"
    write_capture(path, _many(50))
    gz = tmp_path / f"capture{suffix}.gz"
    gz.write_bytes(gzip.compress(path.read_bytes()))
    frames, reader = read_all(gz)
    plain, _ = read_all(path)
    assert reader.errors == []
    assert frames == plain


# -- choosing a reader ------------------------------------------------------------------------


def test_registry() -> None:
    assert CAN_READERS[".log"] is CandumpReader
    for suffix in (".asc", ".blf", ".csv", ".mf4"):
        assert CAN_READERS[suffix] is PythonCanFileReader
    assert CAN_READERS[".trc"] is TrcReader  # every version, where python-can reads some
    assert is_can_file("x.ASC") and is_can_file("x.log.gz") and not is_can_file("x.txt")


@pytest.mark.parametrize("name", ["capture.txt", "capture", "capture.gz", "capture.db", "x.bin.gz"])
def test_unsupported_suffix(tmp_path: Path, name: str) -> None:
    path = tmp_path / name
    path.write_bytes(b"")
    with pytest.raises(ValueError, match=r"unsupported CAN capture suffix.*supported: \.asc"):
        open_can_file(path)


def test_upper_case_suffix(tmp_path: Path) -> None:
    path = tmp_path / "CAPTURE.BLF"
    write_capture(tmp_path / "capture.blf", _many(3))
    (tmp_path / "capture.blf").rename(path)
    frames, _ = read_all(path)
    assert len(frames) == 3


@pytest.mark.parametrize("name", ["missing.log", "missing.asc", "missing.blf"])
def test_missing_file(tmp_path: Path, name: str) -> None:
    with pytest.raises(FileNotFoundError):
        open_can_file(tmp_path / name)


def test_mf4(tmp_path: Path) -> None:
    path = tmp_path / "capture.mf4"
    try:
        import asammdf  # noqa: F401
    except ImportError:
        path.write_bytes(b"")
        with pytest.raises(ValueError, match="asammdf"):
            open_can_file(path)
        return
    mf4.load()  # python-can's MF4Writer, whose asammdf eg2scope defers to the first .mf4
    write_capture(path, _many(20))
    frames, reader = read_all(path)
    assert reader.errors == []
    assert [f.data for f in frames] == [bytes(m.data) for m in _many(20)]


def test_empty_files(tmp_path: Path) -> None:
    for name in ("empty.log", "empty.csv", "empty.asc"):
        path = tmp_path / name
        path.write_bytes(b"")
        frames, reader = read_all(path)
        assert frames == [], name
    path = tmp_path / "empty.blf"
    path.write_bytes(b"")
    frames, reader = read_all(path)
    assert frames == [] and reader.errors


def test_message_to_frame_marks_long_frames_fd() -> None:
    fr = message_to_frame(can.Message(arbitration_id=1, data=bytes(12), is_fd=False))
    assert fr.is_fd and fr.dlc == 12
    fr = message_to_frame(can.Message(arbitration_id=1, data=b"\x01", channel=3, timestamp=2.0))
    assert fr == CanFrame(2.0, 1, b"\x01", True, False, False, False, 1, "3")


# -- damaged text captures: nothing skipped in silence, nothing changed -----------------------

TEXT_FORMATS = [".log", ".asc", ".trc", ".csv"]
# data bytes that show a cut: "40 0D 01" cut after "40 0" must not become 40 00
EG2_MESSAGES = [
    _msg(
        i * 0.01, arbitration_id=0x04FF0001 + i % 2, data=bytes([0x40, 0x0D, 0x01, i][: 1 + i % 4])
    )
    for i in range(8)
]


def _is_frame_line(fmt: str, line: bytes) -> bool:
    text = line.decode().strip()
    if fmt == ".asc":
        return " Rx " in f" {text} "
    if fmt == ".trc":
        return bool(text) and not text.startswith(";")
    if fmt == ".csv":
        return bool(text) and not text.startswith("timestamp")
    return bool(text)


@pytest.mark.parametrize("fmt", TEXT_FORMATS)
def test_a_cut_never_changes_a_frame(tmp_path: Path, fmt: str) -> None:
    """Cut at every byte of the last frames: the frames read are the whole file's first ones,
    unchanged; a frame line cut short is reported as truncated, never read. A last line cut
    after its whole content (only its line end is missing) is read: its length shows it whole
    (candump -L states none, but python-can's writer ends the line with the direction)."""
    whole = tmp_path / f"whole{fmt}"
    write_capture(whole, EG2_MESSAGES)
    data = whole.read_bytes()
    want, reader = read_all(whole)
    assert reader.errors == [] and len(want) == len(EG2_MESSAGES)
    lines = data.splitlines(keepends=True)
    starts = [sum(len(x) for x in lines[:i]) for i in range(len(lines))]
    frame_lines = [i for i, line in enumerate(lines) if _is_frame_line(fmt, line)]
    # a line is whole once its first line-end byte is there (a CR alone ends a line)
    ends = [
        start + len(line.rstrip(b"\r\n")) + 1 for start, line in zip(starts, lines, strict=True)
    ]
    content_ends = [start + len(line.rstrip()) for start, line in zip(starts, lines, strict=True)]
    cut_path = tmp_path / f"cut{fmt}"
    for cut in range(starts[frame_lines[-3]], len(data)):
        cut_path.write_bytes(data[:cut])
        got, reader = read_all(cut_path)
        assert got == want[: len(got)], cut
        n = max(i for i, start in enumerate(starts) if start <= cut)  # the line cut in
        whole = n in frame_lines and content_ends[n] <= cut < ends[n]
        assert len(got) == sum(1 for i in frame_lines if ends[i] <= cut) + whole, cut
        partial = data[starts[n] : cut]
        if n in frame_lines and partial.strip() and cut < ends[n] and not whole:
            assert any(e.startswith(f"line {n + 1}: ") and "truncated" in e for e in reader.errors)


JUNK = {
    # (line to insert after frame k, kind of report)
    ".log": [("junk junk", "cannot parse"), ("(1.0) can0 4FF00001#00", "29 bits")],
    ".asc": [
        ("this is junk", "not a frame"),
        (" 1.000000 1  4FF0001x        Rx   d 3 4G 0D 01", "cannot parse"),
        (" 1.000000 1  4FF$001x        Rx   d 3 40 0D 01", "cannot parse"),  # frame-shaped
        (" 1.000000 1  4FF0001x        Rx   d 3 40", "DLC 3 but 1 data bytes"),
    ],
    ".trc": [
        ("junk junk", "cannot parse"),
        ("      9      9.000 DT  1  4FF0001 Rx -  3    4G 0D 01", "cannot parse"),
        ("      9      9.000 DT  1  4FF0001 Rx -  3    40", "DLC 3 but 1 data bytes"),
    ],
    ".csv": [("this,is,not,a,frame", "cannot parse"), ("1.0,0x1,1,0,0,3,QA==", "DLC 3 but 1")],
}


@pytest.mark.parametrize("fmt", TEXT_FORMATS)
def test_every_bad_line_is_reported_where_it_is(
    tmp_path: Path, fmt: str, capfd: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / f"junk{fmt}"
    write_capture(path, EG2_MESSAGES)
    want, _ = read_all(path)
    lines = path.read_text().splitlines()
    frame_lines = [i for i, line in enumerate(lines) if _is_frame_line(fmt, line.encode())]
    expected = []
    for k, (junk, kind) in reversed(list(enumerate(JUNK[fmt]))):
        at = frame_lines[2 * k + 1] + 1  # after every other frame, from the end
        lines.insert(at, junk)
        expected.append((at, kind))
    numbers = {}  # final line number of each inserted line
    for at, kind in expected:
        shift = sum(1 for a, _ in expected if a < at)
        numbers[at + shift + 1] = kind
    path.write_text("\n".join(lines) + "\n")
    got, reader = read_all(path)
    assert got == want  # every good frame, before and after the bad lines
    assert len(reader.errors) == len(numbers), reader.errors
    for error, (number, kind) in zip(reader.errors, sorted(numbers.items()), strict=True):
        assert error.startswith(f"line {number}: "), error
        assert kind in error, error
    out, err = capfd.readouterr()
    assert out == err == ""  # python-can's own log lines stay out of the terminal
    assert not [r for r in caplog.records if r.name.startswith("can")]


@pytest.mark.parametrize("fmt", [".log", ".asc", ".trc", ".csv"])
def test_random_bytes_are_reported(
    tmp_path: Path, fmt: str, capfd: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / f"random{fmt}"
    path.write_bytes(random.Random(7).randbytes(20000))
    frames, reader = read_all(path)
    assert frames == []
    assert reader.errors and all(e.startswith("line ") for e in reader.errors[:-1])
    assert capfd.readouterr() == ("", "")


@pytest.mark.parametrize("fmt", TEXT_FORMATS)
@pytest.mark.parametrize("ending", ["bom", "cr", "crlf"])
def test_byte_order_mark_and_line_ends(tmp_path: Path, fmt: str, ending: str) -> None:
    path = tmp_path / f"capture{fmt}"
    write_capture(path, EG2_MESSAGES)
    want, _ = read_all(path)
    data = path.read_bytes().replace(b"\r\n", b"\n")  # python-can writes .trc with CRLF
    if ending == "bom":
        data = b"\xef\xbb\xbf" + data
    else:
        data = data.replace(b"\n", b"\r" if ending == "cr" else b"\r\n")
    path.write_bytes(data)
    got, reader = read_all(path)
    assert reader.errors == []
    assert got == want


def test_cr_only_candump_log_large(tmp_path: Path) -> None:
    """Line ends found beyond the first block too."""
    path = tmp_path / "cr.log"
    path.write_bytes(b"".join(b"(%d.0) can0 01180001#%02X\r" % (i, i % 256) for i in range(20000)))
    frames, reader = read_all(path)
    assert reader.errors == [] and len(frames) == 20000
    assert [f.data[0] for f in frames] == [i % 256 for i in range(20000)]


@pytest.mark.parametrize(
    "content,words",
    [
        (b"", "the file is empty: not a BLF capture"),
        (b"LOGG" + bytes(20), "too short for a BLF file header"),
        (bytes(range(256)) * 4, "not a BLF capture (it does not start with the BLF signature"),
    ],
    ids=["empty", "short", "random"],
)
def test_blf_that_is_not_one_says_so_in_words(tmp_path: Path, content: bytes, words: str) -> None:
    path = tmp_path / "x.blf"
    path.write_bytes(content)
    frames, reader = read_all(path)
    assert frames == []
    assert len(reader.errors) == 1 and words in reader.errors[0]
    assert "struct" not in reader.errors[0]
