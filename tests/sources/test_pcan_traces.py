"""PCAN traces of every version read here (analyzer/sources/pcan_trc.py): each version's
columns, error frames, FD lengths, remote frames, what is no frame, damage reported where it is,
a whole last line read and a cut one not, a version we do not know refused in one line."""

from __future__ import annotations

import gzip
from pathlib import Path

import pytest
from capture_helpers import decode_both, records

from analyzer.sources.can_files import TrcReader, open_can_file

HEADERS = {
    "1.0": "",
    "1.1": ";$FILEVERSION=1.1\n;$STARTTIME=44548.5\n",
    "1.2": ";$FILEVERSION=1.2\n;$STARTTIME=44548.5;\n",
    "1.3": ";$FILEVERSION=1.3\n;$STARTTIME=44548.5\n",
    "2.0": ";$FILEVERSION=2.0\n;$STARTTIME=44548.5\n;$COLUMNS=N,O,T,I,d,l,D\n",
    "2.1": ";$FILEVERSION=2.1\n;$STARTTIME=44548.5\n;$COLUMNS=N,O,T,B,I,d,R,L,D\n",
}
# one data frame (0x123: 11 22), one extended remote frame, one error frame, per version
LINES = {
    "1.0": ["1) 1000 0123 2 11 22", "2) 1500 00000456 3 RTR", "3) 2000 0008 4 ERROR 00 19 08 08"],
    "1.1": ["1) 1000.0 Rx 0123 2 11 22", "2) 1500.0 Tx 00000456 3 RTR",
            "3) 2000.0 Error 0008 4 00 19 08 08"],
    "1.2": ["1) 1000.000 2 Rx 0123 2 11 22", "2) 1500.000 2 Rx 00000456 3 RTR",
            "3) 2000.000 2 Error 0008 4 00 19 08 08"],
    "1.3": ["1) 1000.000 2 Rx 0123 - 2 11 22", "2) 1500.000 2 Rx 00000456 - 3 RTR",
            "3) 2000.000 2 Error 0008 - 4 00 19 08 08"],
    "2.0": ["1 1000.000 DT 0123 Rx 2 11 22", "2 1500.000 RR 00000456 Rx 3",
            "3 2000.000 ER Rx 04 00 02 00 00"],
    "2.1": ["1 1000.000 DT 2 0123 Rx - 2 11 22", "2 1500.000 RR 2 00000456 Rx - 3",
            "3 2000.000 ER 2 - Rx - 5 04 00 02 00 00"],
}  # fmt: skip
START = 1639828800.0  # 44548.5 days after 1899-12-30: 2021-12-18 12:00 UTC


@pytest.mark.parametrize("version", sorted(HEADERS))
def test_every_version(tmp_path: Path, version: str) -> None:
    path = tmp_path / "trace.trc"
    path.write_text(HEADERS[version] + "\n".join(LINES[version]) + "\n")
    with open_can_file(path) as reader:
        frames = list(reader)
    assert isinstance(reader, TrcReader) and reader.errors == []
    data, remote, error = frames
    start = 0.0 if version == "1.0" else START
    bus = "1" if version in ("1.0", "1.1", "2.0") else "2"
    assert (data.arbitration_id, data.data, data.is_extended, data.channel) == (
        0x123, b"\x11\x22", False, bus,
    )  # fmt: skip
    assert data.t == pytest.approx(start + 1.0, abs=1e-6)
    assert (remote.arbitration_id, remote.is_remote, remote.is_extended, remote.dlc) == (
        0x456, True, True, 3,
    )  # fmt: skip
    assert remote.t == pytest.approx(start + 1.5, abs=1e-6)
    assert (
        error.is_error
        and error.arbitration_id == 0
        and error.t == pytest.approx(start + 2.0, abs=1e-6)
    )
    assert error.data in (bytes.fromhex("00190808"), bytes.fromhex("0400020000"))
    code, text, err = decode_both(path)
    assert (code, err) == (0, "")
    assert [("can_error_frame" in r["flags"]) for r in records(text)] == [False, False, True]


def test_fd_frames_length_and_dlc_columns(tmp_path: Path) -> None:
    data = " ".join(f"{i:02X}" for i in range(12))
    v20 = HEADERS["2.0"] + f"1 1.000 FD 0500 Tx 12 {data}\n2 2.000 FB 0500 Tx 12 {data}\n"
    v21 = HEADERS["2.1"] + f"1 1.000 FD 1 0500 Tx - 9 {data}\n"  # DLC 9: 12 bytes
    for text in (v20, v21):
        path = tmp_path / "fd.trc"
        path.write_text(text)
        with open_can_file(path) as reader:
            frames = list(reader)
        assert reader.errors == []
        assert all(f.is_fd and f.dlc == 12 and f.data == bytes(range(12)) for f in frames)


def test_what_is_no_frame_is_skipped_and_damage_reported(tmp_path: Path) -> None:
    path = tmp_path / "trace.trc"
    path.write_text(
        HEADERS["2.1"] + "1 1.000 DT 1 0100 Rx - 1 01\n"
        "2 1.100 ST 1 - Rx - 4 00 00 00 08\n"  # status
        "3 1.200 EC 1 - Rx - 2 02 02\n"  # error counters
        "4 1.300 EV 1 User-defined event for bus 1\n"
        "5 1.400 DT 1 0100 Rx - 3 01 02\n"  # damaged: DLC 3, 2 bytes
        "6 1.500 XX 1 0100 Rx - 1 01\n"  # damaged: no such type
        "7 1.600 DT 1 0800 Rx - 1 01\n"  # damaged: 11-bit identifier out of range
        "8 1.700 DT 1 0100 Rx - 1 02\n"
    )
    code, text, err = decode_both(path)
    assert [r["raw"] for r in records(text)] == ["01", "02"]
    assert code == 3
    lines = err.splitlines()
    assert [line.split(": ")[2] for line in lines] == ["line 8", "line 9", "line 10"]
    assert "DLC 3 but 2 data bytes" in lines[0] and "unknown message type 'XX'" in lines[1]


@pytest.mark.parametrize(
    "last,read", [("2 2.000 DT 0100 Rx 2 01 02", True), ("2 2.000 DT 0100 Rx 2 01 0", False),
                  ("2 2.000 DT 0100 Rx 2 01", False), ("2 2.000 RR 0100 Rx 2", True)],
)  # fmt: skip
def test_a_last_line_without_its_end(tmp_path: Path, last: str, read: bool) -> None:
    path = tmp_path / "trace.trc.gz"
    path.write_bytes(gzip.compress((HEADERS["2.0"] + "1 1.000 DT 0100 Rx 1 01\n" + last).encode()))
    code, text, err = decode_both(path)
    assert len(records(text)) == 1 + read
    assert (code == 0) == read
    if not read:
        assert "line 5: cannot parse" in err and "truncated" in err


def test_a_version_we_do_not_know(tmp_path: Path) -> None:
    path = tmp_path / "future.trc"
    path.write_text(";$FILEVERSION=3.0\n1 1.000 DT 0100 Rx 1 01\n")
    code, text, err = decode_both(path)
    assert (code, text) == (3, "")
    assert err.count("\n") == 1 and "unknown trace version '3.0'" in err
