"""The captures python-can and cantools test their readers with (tests/data/third_party/, see its
README), and the layouts of issue 18 (tests/data/candump_layouts.txt): each decodes with both
engines to the same bytes and to what its ``<file>.json`` says (frame count, error frames, the
first and last frame's identifier, data, time and bus, the exit code). Where python-can reads a
file itself, our frames are also python-can's own (its reader is the reference there)."""

from __future__ import annotations

import gzip
import io
import json
import logging
import time
from collections.abc import Iterator
from contextlib import redirect_stderr
from pathlib import Path
from typing import Any

import can
import pytest

from analyzer import cli
from analyzer.session import engine as native
from analyzer.sources.can_files import PythonCanFileReader, open_can_file
from analyzer.sources.can_message import message_to_frame

DATA = Path(__file__).resolve().parents[1] / "data"
THIRD_PARTY = DATA / "third_party"
CAPTURES = sorted(
    p
    for p in [*THIRD_PARTY.glob("*/*"), DATA / "candump_layouts.txt"]
    if p.suffix != ".json" and not p.name.startswith(("LICENSE", "README"))
)
# candump -tA stamps are local time: read in this zone (CET in December, UTC+1)
TZ = "CET-1CEST,M3.5.0,M10.5.0/3"
ENGINES = ["python", "native"] if native.available() else ["python"]


@pytest.fixture(autouse=True)
def central_european_time(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    monkeypatch.setenv("TZ", TZ)
    time.tzset()
    yield
    monkeypatch.undo()
    time.tzset()


def decode(capture: Path, engine: str, tmp_path: Path) -> tuple[int, bytes, str]:
    """(exit code, JSONL, stderr) of ``eg2scope decode CAPTURE --engine ENGINE``."""
    out = tmp_path / f"{capture.name}.{engine}.jsonl"
    argv = ["decode", str(capture), "-f", "jsonl", "-o", str(out), "--no-progress"]
    err = io.StringIO()
    with redirect_stderr(err):
        code = cli.main([*argv, "--engine", engine])
    return code, out.read_bytes() if out.exists() else b"", err.getvalue()


def summary(code: int, jsonl: bytes) -> dict[str, Any]:
    records = [json.loads(line) for line in jsonl.splitlines()]

    def frame(rec: dict[str, Any]) -> dict[str, Any]:
        return {"id": rec["fields"].get("id"), "data": rec["raw"], "t": rec["t"], "bus": rec["bus"]}

    return {
        "exit": code,
        "frames": len(records),
        "error_frames": sum("can_error_frame" in r["flags"] for r in records),
        "first": frame(records[0]),
        "last": frame(records[-1]),
    }


@pytest.mark.parametrize("capture", CAPTURES, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_decodes_to_its_expectation_with_both_engines(capture: Path, tmp_path: Path) -> None:
    expected = json.loads(capture.with_name(capture.name + ".json").read_text())
    results = {engine: decode(capture, engine, tmp_path) for engine in ENGINES}
    code, jsonl, stderr = results["python"]
    assert summary(code, jsonl) == expected, stderr
    assert code == 0 and stderr == ""  # every one of them is complete
    for engine, result in results.items():
        assert result == results["python"], f"{engine} differs from python"


def test_every_capture_has_its_expectation() -> None:
    assert len(CAPTURES) >= 40
    for capture in CAPTURES:
        assert capture.with_name(capture.name + ".json").is_file(), capture


# python-can reads these itself (we read TRC, every version of it, ourselves)
PYTHON_CAN_READ = [p for p in CAPTURES if p.suffix in (".asc", ".blf", ".gz")]
PYTHON_CAN_TRC = [
    p for p in CAPTURES if p.suffix == ".trc" and p.name not in ("pcan_v1_0.trc", "pcan_v1_2.trc")
]


@pytest.mark.parametrize("capture", PYTHON_CAN_READ + PYTHON_CAN_TRC, ids=lambda p: p.name)
def test_frames_are_python_cans_own(capture: Path) -> None:
    """Where python-can reads a file, our frames are its messages, converted; our TRC reader
    adds the error frames python-can drops and gives an FD frame its length in bytes (python-can
    gives it the DLC code)."""
    logging.disable(logging.CRITICAL)
    try:
        theirs = [message_to_frame(m) for m in _python_can_reader(capture)]
    finally:
        logging.disable(logging.NOTSET)
    with open_can_file(capture) as reader:
        ours = list(reader)
    assert reader.errors == []
    if capture.suffix == ".trc":
        assert not isinstance(reader, PythonCanFileReader)
        ours = [f for f in ours if not f.is_error]
        theirs = [f if not f.is_fd else _with_length(f) for f in theirs]
    assert ours == theirs


def _python_can_reader(capture: Path) -> Any:
    """python-can's reader for a capture, with ASC times absolute (from the file's start
    date) as we read them."""
    if capture.suffix == ".gz":
        return can.ASCReader(gzip.open(capture, "rt"), relative_timestamp=False)
    if capture.suffix == ".asc":
        return can.ASCReader(str(capture), relative_timestamp=False)
    return can.LogReader(str(capture))


def _with_length(frame: Any) -> Any:
    frame.dlc = len(frame.data)
    return frame


@pytest.mark.parametrize(
    "name,cantools_ids",
    [
        ("candump_default.txt", [0x0C8, 0x064, 0x1F4, 0x1F3]),
        ("candump_errorframe.log", [0x0C8, 0x064]),
        ("candump_L.log", [0x0C8, 0x064, 0x1F4, 0x1F3]),
        ("candump_L_errorframe.log", [0x0C8, 0x064]),
        ("candump_tA.log", [0x0C8, 0x064, 0x1F4, 0x1F3]),
        ("candump_tz", [0x0C8, 0x064, 0x1F4, 0x1F3]),
        ("candump_L_fd.log", [0x102]),
        ("pcan_v1_0.trc", [0x001, 0x100, 0x300]),
        ("pcan_v1_1.trc", [0x300, 0x300, 0x400, 0x300, 0x100]),
        ("pcan_v1_2.trc", [0x300, 0x300, 0x400, 0x300, 0x100]),
        ("pcan_v1_3.trc", [0x401, 0x4A1, 0x400, 0x4A0]),
        ("pcan_v2_0.trc", [0x300, 0x300, 0x400, 0x300, 0x500, 0x18EFC034, 0x100]),
        ("pcan_v2_1.trc", [0x300, 0x300, 0x400, 0x300, 0x500, 0x18EFC034, 0x100]),
    ],
)
def test_cantools_streams_give_cantools_frames(name: str, cantools_ids: list[int]) -> None:
    """The identifiers cantools' own test asserts for each stream, in order; the error frames
    it skips are ours besides (flagged can_error_frame)."""
    with open_can_file(THIRD_PARTY / "cantools" / name) as reader:
        frames = list(reader)
    assert reader.errors == []
    assert [f.arbitration_id for f in frames if not f.is_error] == cantools_ids
