"""``eg2scope cycles`` as a real process on the project's sample captures, on each engine, in
every format read back (Parquet with pyarrow), and its exit codes; ``stats`` counting the same
cycles."""

from __future__ import annotations

import csv
import io
import subprocess
import sys
from pathlib import Path
from typing import Any

import orjson
import pyarrow.parquet as pq
import pytest
from native_core import needs_native

from analyzer.cycles.model import KEYS

ROOT = Path(__file__).resolve().parents[2]
CAPTURES = ROOT / "captures"
CAN = CAPTURES / "can_pick_place.log"
SERIAL = CAPTURES / "serial_session.bin"
MODBUS = CAPTURES / "modbus_session.bin"


def eg2scope(*argv: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[bytes]:
    return subprocess.run(
        [sys.executable, "-m", "analyzer", *argv], capture_output=True, cwd=cwd, timeout=120
    )


def jsonl(*argv: str) -> list[dict[str, Any]]:
    proc = eg2scope("cycles", *argv, "--format", "jsonl")
    assert proc.returncode == 0, proc.stderr.decode()
    return [orjson.loads(line) for line in proc.stdout.splitlines()]


def brief(cycles: list[dict[str, Any]]) -> list[tuple[Any, ...]]:
    return [(c["device"], c["start_seq"], c["end_seq"], c["outcome"]) for c in cycles]


# -- what it says about the sample captures ----------------------------------------------------


@pytest.mark.parametrize("engine", ["python", "native"])
def test_can_pick_place(engine: str) -> None:
    """Two grippers close on a part (state 6); gripper 1 is then told to open and a broadcast
    stop comes before any reading: stopped. The stop ends gripper 2's grip too."""
    cycles = jsonl(str(CAN), "--engine", engine)
    assert brief(cycles) == [  # in the order they ended (the stop ends two: then by start)
        (1, 8, 84, "gripped"),
        (2, 10, 87, "gripped"),
        (1, 84, 87, "stopped"),
    ]
    first, second, stopped = cycles
    assert (first["width_mm"], first["force_peak"]) == (21.7, 480)
    assert (second["width_mm"], second["force_peak"]) == (19.6, 480)
    assert first["time_to_contact_ms"] == pytest.approx(119.493)
    assert first["settle_ms"] == pytest.approx(125.893)
    assert first["evidence"] == [8, 9, 49, 51]  # the write, its answer, contact, state 6
    assert stopped["evidence"] == [84, 85, 87] and stopped["unknown"] == [
        "state",
        "opening",
        "force",
    ]


@pytest.mark.parametrize("engine", ["python", "native"])
def test_serial_session(engine: str) -> None:
    """A host that reads only the position during a catch: the cycle cannot know it gripped.
    The release with a failed checksum starts nothing; its good copy does. A broadcast stop ends
    the seek. A raw dump has no times."""
    cycles = jsonl(str(SERIAL), "--engine", engine)
    assert brief(cycles) == [
        (1, 35, 92, "unknown"),
        (1, 92, 130, "unknown"),
        (1, 130, 160, "stopped"),
    ]
    assert cycles[0]["unknown"] == ["state", "force", "time"]
    assert cycles[0]["command"] == "catch speed=500 force=100 g"
    assert all(c["start_t"] is None and c["settle_ms"] is None for c in cycles)


@pytest.mark.parametrize("engine", ["python", "native"])
def test_modbus_session(engine: str) -> None:
    """The catch written at 1010-1012 reaches state 6; two moves follow with no reading between
    them (unknown); a move to 864 (short register numbers) is read back at its target; a write
    to device 2 is never answered."""
    cycles = jsonl(str(MODBUS), "--engine", engine)
    assert brief(cycles) == [  # those the end of the capture ended last, by start
        (1, 0, 115, "gripped"),
        (1, 115, 131, "unknown"),
        (1, 131, 147, "unknown"),
        (1, 147, 210, "positioned"),
        (2, 215, 215, "unanswered"),
    ]
    assert cycles[0]["command"] == "move to 0.0 mm speed=1000 force=1000 g"
    assert cycles[3]["unknown"] == ["state", "force", "time"]
    assert cycles[4]["evidence"] == [215]


def test_device_picks_one_grippers_cycles() -> None:
    assert [c["device"] for c in jsonl(str(CAN), "--device", "2")] == [2]
    assert jsonl(str(CAN), "--device", "7") == []


@pytest.fixture(scope="module")
def demo_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``record --demo`` for 3 s: the simulated grippers on all three buses."""
    path = tmp_path_factory.mktemp("demo") / "x.mcap"
    proc = eg2scope("record", "--demo", "-o", str(path), "--duration", "3", cwd=path.parent)
    assert proc.returncode == 0, proc.stderr.decode()
    return path


def test_the_demo_recording(demo_recording: Path) -> None:
    """The grippers close on their parts and open again on every bus; the stop ends the rest
    (a loaded machine may garble a line's frames: a cycle then says what it could not read)."""
    cycles = jsonl(str(demo_recording))
    assert {c["bus"] for c in cycles} == {"rs232", "rs485", "can0"}
    gripped = [c for c in cycles if c["outcome"] == "gripped"]
    assert gripped and all(c["time_to_contact_ms"] > 0 for c in gripped)
    assert all(c["width_mm"] in (29.4, 17.5) for c in gripped)  # the demo's parts


@needs_native
def test_the_native_engine_says_why_not_on_serial_lines(demo_recording: Path) -> None:
    """A recording of serial lines is decoded in Python (a raw dump's one stream is not): the
    native engine says why not, and writes nothing."""
    proc = eg2scope("cycles", str(demo_recording), "--engine", "native")
    assert proc.returncode == 2 and not proc.stdout
    assert b"CAN input and single byte streams" in proc.stderr


@needs_native
@pytest.mark.parametrize("command", ["cycles", "plot"])
def test_the_engine_asked_for_applies_to_the_demo(command: str, tmp_path: Path) -> None:
    """``--engine`` holds for a live session too: the demo's serial lines are no input of the
    native engine, a usage error before anything is opened or written (the scenario's truth
    file kept as it was, nothing on stdout); its CAN bus alone is."""
    out = tmp_path / ("out.jsonl" if command == "cycles" else "out.rrd")
    where = ["-o", str(out), "--format", "jsonl"] if command == "cycles" else ["--save", str(out)]
    truth = tmp_path / "truth.jsonl"
    truth.write_text("kept\n")
    live = [command, "--demo", "--engine", "native", "--duration", "2"]
    refused = [*live, "--scenario", "grip", "--truth", str(truth)]
    attempts = [[*refused, *where]]
    if command == "cycles":
        attempts.append([*refused, "--format", "csv"])  # to stdout: not even its header
    for argv in attempts:
        proc = eg2scope(*argv, cwd=tmp_path)
        assert proc.returncode == 2, proc.stderr.decode()
        assert b"--engine native" in proc.stderr and b"CAN input" in proc.stderr
        assert b"simulated" not in proc.stderr and not proc.stdout
        assert truth.read_text() == "kept\n" and sorted(tmp_path.iterdir()) == [truth]
    proc = eg2scope(*live, *where, "--buses", "can", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr.decode()
    if command == "cycles":
        assert {c["bus"] for c in map(orjson.loads, out.read_bytes().splitlines())} == {"can0"}
    else:
        assert out.stat().st_size > 0


# -- every format, read back --------------------------------------------------------------------


@pytest.mark.parametrize("capture", [CAN, SERIAL, MODBUS, "demo"], ids=str)
def test_every_format_holds_the_same_cycles(
    capture: Path | str, tmp_path: Path, request: pytest.FixtureRequest
) -> None:
    if capture == "demo":
        capture = request.getfixturevalue("demo_recording")
    expected = jsonl(str(capture))
    assert expected
    for fmt in ("csv", "parquet", "text"):
        out = tmp_path / f"cycles.{fmt}"
        proc = eg2scope("cycles", str(capture), "--format", fmt, "-o", str(out))
        assert proc.returncode == 0, proc.stderr.decode()
        if fmt == "csv":
            assert csv_cycles(out.read_text(encoding="utf-8")) == expected
        elif fmt == "parquet":
            table = pq.read_table(out)
            assert tuple(table.column_names) == KEYS
            assert table.schema.metadata[b"eg2scope"] == b"cycles"
            assert table.schema.field("settle_ms").metadata == {b"unit": b"ms"}
            assert table.to_pylist() == expected
        else:
            lines = out.read_text(encoding="utf-8").splitlines()
            assert len(lines) == len(expected)
            for line, cycle in zip(lines, expected, strict=True):
                assert f"ID {cycle['device']}" in line and cycle["outcome"] in line
                assert f"frames {cycle['start_seq']}-{cycle['end_seq']}" in line


def csv_cycles(text: str) -> list[dict[str, Any]]:
    """The CSV rows as the JSONL objects they say (docs/contracts.md: lists joined with "; ",
    an empty cell a null)."""
    rows = list(csv.DictReader(io.StringIO(text)))
    out = []
    for row in rows:
        cycle: dict[str, Any] = {}
        for key in KEYS:
            cell = row[key]
            if key in ("faults", "warnings", "unknown"):
                cycle[key] = cell.split("; ") if cell else []
            elif key == "evidence":
                cycle[key] = [int(x) for x in cell.split("; ")] if cell else []
            elif cell == "":
                cycle[key] = None
            elif key in ("bus", "command", "outcome"):
                cycle[key] = cell
            else:
                cycle[key] = orjson.loads(cell)
        out.append(cycle)
    return out


def test_parquet_of_no_cycles_is_a_file_with_the_columns(tmp_path: Path) -> None:
    out = tmp_path / "none.parquet"
    proc = eg2scope("cycles", str(CAN), "-f", "parquet", "-o", str(out), "--device", "9")
    assert proc.returncode == 0, proc.stderr.decode()
    table = pq.read_table(out)
    assert table.num_rows == 0 and tuple(table.column_names) == KEYS
    assert b"no grip cycles of device 9" in proc.stderr


# -- exit codes ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        ([], b"no cycles to find"),
        ([str(CAN), "--demo"], b"not both"),
        ([str(CAN), "-o", str(CAN)], b"is the input"),
        ([str(CAN), "--format", "xml"], b"invalid choice"),
    ],
)
def test_usage_errors_write_nothing(argv: list[str], words: bytes) -> None:
    proc = eg2scope("cycles", *argv)
    assert proc.returncode == 2 and not proc.stdout
    assert words in proc.stderr


def test_a_missing_capture_is_an_error() -> None:
    proc = eg2scope("cycles", "no-such-capture.log")
    assert proc.returncode == 1 and not proc.stdout


def test_a_damaged_capture_gives_its_cycles_and_exit_3(tmp_path: Path) -> None:
    damaged = tmp_path / "damaged.log"
    damaged.write_bytes(CAN.read_bytes() + b"(1763700001.000000) can0 this is no frame\n")
    proc = eg2scope("cycles", str(damaged), "-f", "jsonl")
    assert proc.returncode == 3
    assert brief([orjson.loads(x) for x in proc.stdout.splitlines()]) == brief(jsonl(str(CAN)))


def test_a_capture_without_motion_commands_says_so(tmp_path: Path) -> None:
    polls = tmp_path / "polls.log"
    lines = CAN.read_text().splitlines()[:8]  # the first polls, before the moves
    polls.write_text("\n".join(lines) + "\n")
    proc = eg2scope("cycles", str(polls))
    assert proc.returncode == 0 and not proc.stdout
    assert b"no grip cycles in this capture" in proc.stderr


# -- stats ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("capture", [CAN, SERIAL, MODBUS], ids=lambda p: p.name)
def test_stats_counts_the_same_cycles(capture: Path) -> None:
    cycles = jsonl(str(capture))
    proc = eg2scope("stats", str(capture), "--format", "json")
    assert proc.returncode == 0, proc.stderr.decode()
    rows = orjson.loads(proc.stdout)["cycles"]
    expected: dict[tuple[str, int], dict[str, int]] = {}
    for c in cycles:
        counts = expected.setdefault((c["bus"], c["device"]), {})
        counts[c["outcome"]] = counts.get(c["outcome"], 0) + 1
    assert {(r["bus"], r["device"]): r["outcomes"] for r in rows} == expected
    for row in rows:
        assert row["cycles"] == sum(row["outcomes"].values())


def test_stats_cycle_times() -> None:
    proc = eg2scope("stats", str(CAN), "--format", "json", "--errors-only")
    [g1, g2] = orjson.loads(proc.stdout)["cycles"]  # found in every record, not the filtered
    assert g2["duration"]["max_ms"] == pytest.approx(244.335, abs=0.01)
    assert g2["settle"]["max_ms"] == pytest.approx(160.295, abs=0.01)
    assert g1["cycles"] == 2 and g1["settle"]["max_ms"] == pytest.approx(125.893, abs=0.01)
    text = eg2scope("stats", str(CAN)).stdout.decode()
    assert "Grip cycles" in text and "gripped 1, stopped 1" in text
