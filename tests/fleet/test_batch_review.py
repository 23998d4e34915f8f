"""What a new user of ``eg2scope batch`` ran into, on the sample captures and on both engines:
a wrong ``--protocol`` (decode's hint, and the options in the capture's key, so the next run
without it decodes it again), raw dumps named by protocol (``rs232``/``rs485``, as live serial
lines are), the day of a capture without calendar time (its file's modification day), and the
messages of the folder walk, of ``--protocol`` on a CAN capture and of an output folder that
cannot be made."""

from __future__ import annotations

import datetime as dt
import gzip
import os
import shutil
from pathlib import Path

import can
import pyarrow.dataset as ds
import pytest

from analyzer import cli
from analyzer.fleet import layout
from analyzer.fleet.inputs import content_hash

ROOT = Path(__file__).resolve().parents[2]
SERIAL = ROOT / "captures/serial_session.bin"
MODBUS = ROOT / "captures/modbus_session.bin"
CAN_LOG = ROOT / "captures/can_pick_place.log"

ENGINES = [
    "python",
    "native",  # needs the core (tests/conftest.py: native_engine_case)
]

# a modification time no test run has: 2024-03-05 12:00 UTC
MTIME = dt.datetime(2024, 3, 5, 12, tzinfo=dt.UTC).timestamp()


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    capsys.readouterr()
    try:
        code = cli.main([*argv, "--no-progress"])
    except SystemExit as exc:  # a usage error exits through argparse
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


def batch(
    capsys: pytest.CaptureFixture[str], out: Path, engine: str, *argv: str
) -> tuple[int, str, str]:
    return run(capsys, "batch", *argv, "-o", str(out), "--workers", "1", "--engine", engine)


def partitions(root: Path, table: str) -> set[str]:
    """The partition folders a table's files are in ("day=.../bus=...")."""
    return {str(p.parent.relative_to(root / table)) for p in (root / table).rglob("*.parquet")}


def captures_rows(root: Path) -> list[dict[str, object]]:
    return ds.dataset(root / layout.CAPTURES, partitioning="hive").to_table().to_pylist()


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize(
    ("dump", "wrong", "right"), [(SERIAL, "modbus", "serial"), (MODBUS, "serial", "modbus")]
)
def test_a_wrong_protocol_gets_decodes_hint_and_the_next_run_decodes_it_again(
    dump: Path,
    wrong: str,
    right: str,
    engine: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    out = tmp_path / "f"
    # decode's hint, word for word (one home: decode's protocol_hint)
    _, _, decode_err = run(capsys, "decode", str(dump), "-p", wrong, "-f", "jsonl")
    hint = next(line for line in decode_err.splitlines() if "hint:" in line)
    assert f"leave --protocol out, or give --protocol {right}" in hint
    code, _, err = batch(capsys, out, engine, str(dump), "--protocol", wrong)
    assert code == 0
    assert hint in err.splitlines()
    (first,) = captures_rows(out)
    assert first["decode_options"] == f"--protocol {wrong}"
    assert first["frames"] == 0  # what was asked: the garbage is in, said so

    # without --protocol: decoded again, the old rows replaced (not added to)
    code, stdout, err = batch(capsys, out, engine, str(dump))
    assert code == 0
    assert f"decoded again (the dataset held it decoded with --protocol {wrong})" in err
    assert "already in the dataset │     0" in stdout
    (row,) = captures_rows(out)
    assert row["decode_options"] == "--protocol auto"
    assert row["valid_frames"] > 10  # the frames detection finds
    records = ds.dataset(out / layout.RECORDS, partitioning="hive").to_table()
    assert records.num_rows == row["records"]
    assert set(records["capture_hash"].to_pylist()) == {content_hash(dump)}

    # the same options again: skipped, by path, size and time, and by content from elsewhere
    code, stdout, _ = batch(capsys, out, engine, str(dump))
    assert "already in the dataset │     1" in stdout
    copy = tmp_path / "copy.bin"
    shutil.copy(dump, copy)
    assert "already in the dataset │     1" in batch(capsys, out, engine, str(copy))[1]
    # and --protocol as detection finds it is another key: decoded again, once
    code, stdout, _ = batch(capsys, out, engine, str(dump), "-p", right)
    assert "already in the dataset │     0" in stdout
    assert [r["decode_options"] for r in captures_rows(out)] == [f"--protocol {right}"]


@pytest.mark.parametrize("engine", ENGINES)
def test_raw_dumps_are_named_by_protocol_and_filed_under_their_files_day(
    engine: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "bin_in"
    folder.mkdir()
    for dump in (SERIAL, MODBUS):
        shutil.copy(dump, folder / dump.name)
    (folder / "modbus_session.raw.gz").write_bytes(gzip.compress(MODBUS.read_bytes()))
    for path in folder.iterdir():
        os.utime(path, (MTIME, MTIME))
    out = tmp_path / "fleet1"
    code, _, err = batch(capsys, out, engine, str(folder))
    assert code == 0, err
    want = {"day=2024-03-05/bus=rs232", "day=2024-03-05/bus=rs485"}
    assert partitions(out, layout.RECORDS) == want
    assert partitions(out, layout.STATES) == want
    buses = {Path(str(r["capture_path"])).name: r["buses"] for r in captures_rows(out)}
    assert buses == {
        "serial_session.bin": ["rs232"],
        "modbus_session.bin": ["rs485"],
        "modbus_session.raw.gz": ["rs485"],
    }
    # a protocol given names the bus as it decodes it (and the hint says it is wrong)
    code, _, err = batch(capsys, tmp_path / "forced", engine, str(MODBUS), "-p", "serial")
    assert "hint: --protocol serial finds" in err
    assert {p.split("/")[1] for p in partitions(tmp_path / "forced", layout.RECORDS)} == {
        "bus=rs232"
    }


def _relative_blf(path: Path) -> None:
    """A BLF log whose times count from its start (0.5 s on), as some loggers write them."""
    with can.BLFWriter(str(path)) as writer:
        for i in range(200):
            t = 0.5 + i / 100
            msg = can.Message(timestamp=t, arbitration_id=0x01180001, data=b"\x08", channel=0)
            writer.on_message_received(msg)


def _relative_candump(path: Path) -> None:
    """A candump log of ``candump -tz`` times (seconds since its start), from the sample."""
    frames = []
    for i, line in enumerate(CAN_LOG.read_text().splitlines()):
        _, rest = line.split(")", 1)
        frames.append(f"({i * 0.001:.6f}){rest}")
    path.write_text("\n".join(frames) + "\n")


def _default_layout(log: str) -> str:
    """A candump -L log in candump's default columns, as ``candump can0 > run.txt`` writes."""
    lines = []
    for line in log.splitlines():
        _, channel, frame = line.split()
        ident, data = frame.split("#")
        octets = " ".join(data[i : i + 2] for i in range(0, len(data), 2))
        lines.append(f"  {channel}  {ident}   [{len(data) // 2}]  {octets}")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("engine", ENGINES)
def test_captures_without_calendar_time_go_under_their_files_modification_day(
    engine: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "in"
    folder.mkdir()
    _relative_blf(folder / "logfile.blf")
    _relative_candump(folder / "relative.log")
    shutil.copy(SERIAL, folder / "dump.bin")
    shutil.copy(CAN_LOG, folder / "absolute.log")
    for path in folder.iterdir():
        os.utime(path, (MTIME, MTIME))
    out = tmp_path / "d"
    code, _, err = batch(capsys, out, engine, str(folder))
    assert code == 0, err
    days = {Path(str(r["capture_path"])).name: str(r["day"]) for r in captures_rows(out)}
    absolute_day = dt.datetime.fromtimestamp(
        float(CAN_LOG.read_text().split(")", 1)[0].lstrip("(")), dt.UTC
    ).date()
    assert days == {
        "logfile.blf": "2024-03-05",
        "relative.log": "2024-03-05",
        "dump.bin": "2024-03-05",
        "absolute.log": absolute_day.isoformat(),  # a calendar time keeps its own day
    }
    records_days = {p.split("/")[0] for p in partitions(out, layout.RECORDS)}
    assert records_days == {"day=2024-03-05", f"day={absolute_day.isoformat()}"}
    assert "day=1970-01-01" not in records_days


def test_protocol_on_a_can_capture_is_decodes_usage_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _, _, decode_err = run(capsys, "decode", str(CAN_LOG), "-p", "serial")
    code, _, err = batch(capsys, tmp_path / "g", "auto", str(CAN_LOG), "-p", "serial")
    assert code == 2
    assert err == decode_err  # the same line, the file named once
    assert err.count(str(CAN_LOG)) == 1 and "unreadable" not in err
    assert not (tmp_path / "g").exists()  # nothing written


def test_an_output_folder_that_cannot_be_made_is_said_in_words(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = batch(capsys, Path("/proc/nope"), "auto", str(CAN_LOG))
    assert code == 1
    assert err.strip() == (
        "eg2scope: error: cannot write the dataset folder /proc/nope: No such file or directory"
    )
    (tmp_path / "file").write_text("")
    code, _, err = batch(capsys, tmp_path / "file" / "d", "auto", str(CAN_LOG))
    assert code == 1 and "[Errno" not in err and "Not a directory" in err


def test_a_folder_takes_candump_logs_by_content_and_says_what_it_passed_over(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "in"
    folder.mkdir()
    text = CAN_LOG.read_text()
    (folder / "run.txt").write_text(_default_layout(text))  # candump can0 > run.txt
    (folder / "candump-2024-03-05").write_text(text)  # no suffix at all
    (folder / "README.txt").write_text("cell 1: gripper on can0, 1 Mbit/s\n")
    (folder / "notes.md").write_text("# notes\n")
    (folder / ".hidden.log").write_text(text)  # hidden: never taken, never counted
    out = tmp_path / "d"
    code, _, err = batch(capsys, out, "auto", str(folder))
    assert code == 0, err
    assert {Path(str(r["capture_path"])).name for r in captures_rows(out)} == {
        "run.txt",
        "candump-2024-03-05",
    }
    assert (
        "eg2scope: passed over 2 files in the folders that are no capture by suffix or content "
        "(README.txt, notes.md); name a file, or a pattern, to take it as a raw serial dump"
    ) in err.splitlines()
    # a folder of notes only: the same words, then the usage error
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "a.txt").write_text("hello\n")
    code, _, err = batch(capsys, tmp_path / "e", "auto", str(notes))
    assert code == 2
    assert "passed over 1 file in the folders" in err and "no captures in" in err
