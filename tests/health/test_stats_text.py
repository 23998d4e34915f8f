"""``stats``' text output: a "Bus health" table per capture, what a row cannot say under it,
and for an empty capture no empty table at all (stderr says it is empty, once)."""

from __future__ import annotations

from pathlib import Path

from cli_process import eg2scope

ROOT = Path(__file__).resolve().parents[2]


def test_a_can_log_gets_its_bus_health_table() -> None:
    proc = eg2scope("stats", str(ROOT / "captures" / "can_pick_place.log"))
    assert proc.returncode == 0, proc.stderr
    table = proc.stdout[proc.stdout.index("Bus health") :]
    row = next(line for line in table.splitlines() if "can0" in line)
    assert "500 kbit/s (default)" in row and "1 (1 bus_error)" in row


def test_a_raw_dump_says_it_has_no_timing_once() -> None:
    proc = eg2scope("stats", str(ROOT / "captures" / "modbus_session.bin"), "--baud", "57600")
    assert proc.returncode == 0, proc.stderr
    assert "57600 baud (--baud)" in proc.stdout
    assert proc.stdout.count("no timing in this capture") == 1


def test_an_empty_capture_prints_no_empty_table(tmp_path: Path) -> None:
    empty = tmp_path / "empty.bin"
    empty.write_bytes(b"")
    proc = eg2scope("stats", str(empty))
    assert proc.returncode == 0
    header = f"{empty}: 0 records, 0 frames (0 valid), 0 garbage bytes, 0 truncated"
    assert proc.stdout.strip() == header  # and no table
    assert proc.stderr.count("empty file") == 1
    proc = eg2scope("stats", str(empty), "--format", "json")
    assert proc.returncode == 0 and '"buses": []' in proc.stdout


def test_rates_must_be_positive() -> None:
    proc = eg2scope("stats", str(ROOT / "captures" / "can_pick_place.log"), "--bitrate", "0")
    assert proc.returncode == 2 and "--bitrate" in proc.stderr
