"""candump logs in every layout candump writes, read by both engines to the same bytes: the
sample capture printed as ``candump can0``, ``-ta``, ``-tz``, ``-td`` and ``-tA`` decodes to the
frames of its -L original with the times each layout carries; error frames, CAN FD lengths,
remote requests, the ASCII view and -e's explanation lines; a whole last line without its end;
a file that is no candump log gives one short error and stops."""

from __future__ import annotations

import gzip
import random
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from capture_helpers import (
    CAN_LOG,
    TZ,
    decode_both,
    records,
    sample_frames,
    write_layout,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from analyzer.sources.can_files import GIVE_UP, CandumpReader

KEYS = ("bus", "protocol", "kind", "index", "direction", "device", "code", "name", "fields", "raw")


@contextmanager
def tz(zone: str) -> Iterator[None]:
    """The process's local time zone, for the C library too (both engines' mktime)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("TZ", zone)
        time.tzset()
        try:
            yield
        finally:
            mp.undo()
            time.tzset()


@pytest.fixture
def central_european_time() -> Iterator[None]:
    with tz(TZ):
        yield


def _same_frames(layout: list[dict], original: list[dict]) -> None:
    assert len(layout) == len(original)
    for got, want in zip(layout, original, strict=True):
        assert {k: got[k] for k in KEYS} == {k: want[k] for k in KEYS}


@pytest.mark.parametrize("stamps", ["", "a", "z", "d", "A"], ids=lambda s: f"-t{s or ' none'}")
def test_every_layout_of_the_sample_capture(
    tmp_path: Path, stamps: str, central_european_time: None
) -> None:
    frames = sample_frames()
    code, text, err = decode_both(CAN_LOG)
    original = records(text)
    path = write_layout(tmp_path / "capture.txt", frames, stamps)  # .txt: found by its content
    code, text, err = decode_both(path)
    assert (code, err) == (0, "")
    got = records(text)
    _same_frames(got, original)
    t0 = frames[0].t
    assert t0 is not None
    for rec, frame in zip(got, frames, strict=True):
        assert frame.t is not None
        if stamps == "":
            assert rec["t"] is None  # no time in the file: none in the records
        elif stamps in ("a", "A"):  # Unix time (-tA: local time, read in TZ)
            assert rec["t"] == pytest.approx(frame.t, abs=1e-6)
        else:  # -tz since the start, -td the sum of the gaps: the capture's own clock
            assert rec["t"] == pytest.approx(frame.t - t0, abs=1e-6)
    if stamps:
        latencies = [(r["latency_ms"], o["latency_ms"]) for r, o in zip(got, original, strict=True)]
        assert all(a == pytest.approx(b, abs=1e-3) for a, b in latencies if b is not None)


# one of each: read as frames (native/native_corpus.py compares both engines on these)
LAYOUT_LINES = [
    "  can0  0C8   [8]  F0 00 00 00 00 00 00 00",
    "  vcan0  064   [10]  F0 01 FF FF FF FF FF FF FF FF",
    "  can0  ERROR",
    "(1594172462.127684) vcan0 ERROR",
    "(2020-12-19 12:04:45.485261)  vcan0  0C8   [8]  F0 00 00 00 00 00 00 00",
    "(000.000000)  vcan0  0C8   [8]  F0 00 00 00 00 00 00 00",
    "(1594172462.126542)  can0  1F4   [4]  01 02 03 04",
    "  vcan0  00000123   [0]  remote request",
    "  vcan0  20000004   [8]  00 04 00 00 00 00 00 00   ERRORFRAME",
    "  can1  123   [8]  31 30 30 2E 35 20 46 4D   '100.5 FM'",
    "(1613749650.388103)  can1       0AD  [08]  A6 55 3B CF 3F 1A F5 2A",
    "  can0  123  [64]  " + " ".join(["AB"] * 64),
    "  can0  04FF0001   [0] ",
    "(1594172462.126542) can0 064#F001FFFFFFFFFFFFFFFF",
]
FD_MARKS = {"[10]": 10, "[08]": 8, "[64]": 64, "064#": 10}  # CAN FD lines: their lengths
BAD_LAYOUT_LINES = [
    "  can0  0C8   [8]  F0 00 00",  # fewer bytes than the length
    "  can0  0C8   [2]  F0 00 00",  # more
    "  can0  0C8   [8]  F0 00 00 00 00 00 00 0",
    "  can0  0C8   [65]  00",
    "  can0  0C8   [x]  00",
    "  can0  800   [1]  00",
    "  can0  0C8   [08]  remote request",  # CAN FD has no remote frames
    "(2020-13-19 12:04:45.485261)  vcan0  0C8   [1]  F0",
    "(2020-12-19 12:04)  vcan0  0C8   [1]  F0",
    "(12.5  vcan0  0C8   [1]  F0",
    "  can0  ERROR  00",
    "(1.0) can0 123#" + "00" * 65,
]


@pytest.mark.parametrize("line", LAYOUT_LINES)
def test_layout_lines(tmp_path: Path, line: str, central_european_time: None) -> None:
    path = tmp_path / "one.log"
    path.write_text(f"{line}\n")
    code, text, err = decode_both(path)
    assert (code, err) == (0, "")
    (rec,) = records(text)
    is_error = "ERROR" in line
    assert ("can_error_frame" in rec["flags"]) == is_error
    fd_length = next((n for mark, n in FD_MARKS.items() if mark in line), None)
    assert rec["fields"].get("fd", False) == (fd_length is not None)
    if fd_length is not None:
        assert rec["length"] == fd_length


@pytest.mark.parametrize("line", BAD_LAYOUT_LINES)
def test_bad_layout_lines_are_reported_where_they_are(tmp_path: Path, line: str) -> None:
    path = tmp_path / "bad.log"
    path.write_text(f"  can0  0C8   [1]  01\n{line}\n  can0  0C8   [1]  02\n")
    code, text, err = decode_both(path)
    assert [r["raw"] for r in records(text)] == ["01", "02"]
    assert code == 3
    assert err.count("\n") == 1 and ": line 2: cannot parse: " in err


def test_td_times_are_summed_and_tz_times_kept(tmp_path: Path) -> None:
    gaps = "(000.000000)  can0  123   [1]  01\n(000.250000)  can0  123   [1]  02\n"
    gaps += "(000.100000)  can0  123   [1]  03\n"
    for name, text in (("td.log", gaps), ("tz.log", gaps.replace("(000.100000)", "(000.350000)"))):
        path = tmp_path / name
        path.write_text(text)
        code, out, err = decode_both(path)
        assert (code, err) == (0, "")
        assert [r["t"] for r in records(out)] == pytest.approx([0.0, 0.25, 0.35])


def test_error_frames_and_their_explanations(tmp_path: Path) -> None:
    """candump -e explains an error frame on TAB-indented lines after it: not frames, no
    damage."""
    path = tmp_path / "errors.log"
    path.write_text(
        "  can0  123   [1]  01\n"
        "  can0  20000004   [8]  00 04 00 00 00 00 00 00   ERRORFRAME\n"
        "\tcontroller-problem{rx-error-warning}\n"
        "\terror-counter-tx-rx{{0}{96}}\n"
        "  can0  123   [1]  02\n"
    )
    code, text, err = decode_both(path)
    recs = records(text)
    assert (code, err, len(recs)) == (0, "", 3)
    assert set(recs[1]["flags"]) == {"can_error_frame", "foreign"}
    assert recs[1]["fields"]["error_class"] == 4  # controller problem


@pytest.mark.parametrize(
    "last,read",
    [
        ("  can0  123   [2]  01 02", True),  # the length says it is whole
        ("  can0  123   [2]  01 0", False),
        ("  can0  123   [2]  01", False),
        ("(1.0) can0 123#0102 R", True),  # python-can ends its lines with the direction
        ("(1.0) can0 123#0102", False),  # a -L line states no length: it may be cut
        ("(1.0) can0 123#0102030405060708", True),  # ... unless it is full
        ("(1.0) can0 123#R5", True),
        ("  can0  ERROR", True),
    ],
)
def test_a_last_line_without_its_end(tmp_path: Path, last: str, read: bool) -> None:
    path = tmp_path / "last.log"
    path.write_text(f"(0.5) can0 123#00 R\n{last}")
    code, text, err = decode_both(path)
    assert len(records(text)) == 1 + read
    if read:
        assert (code, err) == (0, "")
    else:
        assert code == 3 and "line 2: cannot parse" in err and "truncated" in err


def test_random_bytes_named_log_give_one_short_error(tmp_path: Path) -> None:
    path = tmp_path / "random.log"
    path.write_bytes(random.Random(18).randbytes(100_000))
    code, text, err = decode_both(path)
    assert (code, text) == (3, "")
    assert err.count("\n") == 1 and len(err) < 300
    assert "does not look like a candump log" in err
    assert "nothing read" in err


def test_a_log_with_a_few_bad_lines_first_is_still_read(tmp_path: Path) -> None:
    path = tmp_path / "header.log"
    junk = "".join(f"junk {i}\n" for i in range(GIVE_UP - 1))
    path.write_text(junk + CAN_LOG.read_text())
    code, text, err = decode_both(path)
    assert code == 3 and len(records(text)) == len(CAN_LOG.read_text().splitlines())
    assert err.count("cannot parse") == GIVE_UP - 1
    assert "does not look like" not in err


def test_only_log_lines_are_split_for_parallel_decoding(tmp_path: Path) -> None:
    """The parallel Python decoder counts -L lines to number frames: a log in another layout,
    or with -td deltas (a running sum), is decoded in one piece."""
    frames = sample_frames()
    assert CandumpReader(CAN_LOG).splittable
    for stamps in ("", "a", "d"):
        path = write_layout(tmp_path / f"layout-{stamps}.log", frames, stamps)
        assert not CandumpReader(path).splittable


# -- both engines on generated logs in every layout ---------------------------------------------

_STAMPS = st.sampled_from(
    ["", "(000.{:06d}) ", "({:010d}.000000) ", "(2021-02-19 13:48:24.{:06d}) "]
)
_CHANNELS = st.sampled_from(["can0", "vcan1", "can-0", "can.1"])


@st.composite
def _layout_line(draw: st.DrawFn) -> str:
    stamp = draw(_STAMPS).format(draw(st.integers(0, 999_999)))
    chan = draw(_CHANNELS)
    what = draw(st.integers(0, 9))
    if what == 0:
        return f"{stamp}{chan}  ERROR"
    if what == 1:
        return draw(st.sampled_from([*BAD_LAYOUT_LINES, "junk", "\terror-counter{1}"]))
    ident = draw(st.sampled_from(["123", "0C8", "04FF0001", "01180001", "20000004", "7FF"]))
    fd = what == 2
    data = draw(st.binary(max_size=64 if fd else 8))
    length = f"[{len(data):02d}]" if fd else f" [{len(data)}]"
    tail = draw(st.sampled_from(["", "   ERRORFRAME", "   '....'"]))
    if what == 3:
        return f"{stamp}{chan}  {ident}  {length}  remote request"
    if what == 4:  # an -L line among the others
        return f"({draw(st.integers(0, 10**10))}.5) {chan} {ident}#{data.hex().upper()}"
    return f"{stamp}{chan}  {ident}  {length}  {' '.join(f'{b:02X}' for b in data)}{tail}"


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    lines=st.lists(_layout_line(), min_size=1, max_size=40),
    ending=st.sampled_from(["\n", "\r\n", "\r"]),
    cut=st.integers(0, 12),
    gz=st.booleans(),
)
def test_generated_logs_decode_the_same_with_both_engines(
    tmp_path: Path, lines: list[str], ending: str, cut: int, gz: bool
) -> None:
    body = ending.join(lines).encode() + ending.encode()
    body = body[: len(body) - cut] if cut < len(body) else body
    path = tmp_path / ("generated.txt.gz" if gz else "generated.txt")
    path.write_bytes(gzip.compress(body, mtime=0) if gz else body)
    with tz(TZ):
        for fmt in ("jsonl", "text"):
            decode_both(path, fmt=fmt)
