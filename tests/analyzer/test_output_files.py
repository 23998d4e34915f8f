"""Output files a user can trust, through real processes: a recording never replaces a file
that is there unless ``--force``; a command whose source never opened, or whose capture held
nothing readable at all, leaves no output file behind; a damaged capture that yielded records
keeps its plot."""

from __future__ import annotations

from pathlib import Path

import pytest
from cli_process import eg2scope

from analyzer.recording.reader import McapCaptureReader

ROOT = Path(__file__).resolve().parents[2]
CAPTURES = ROOT / "captures"


@pytest.mark.parametrize("command", ["record", "demo", "plot"])
def test_a_recording_refuses_an_existing_file(command: str, tmp_path: Path) -> None:
    mine = tmp_path / "mine.mcap"
    mine.write_bytes(b"the user's own recording")
    proc = eg2scope(command, "--demo" if command != "demo" else "--noise", *(
        ["0.01"] if command == "demo" else []), "-o", "mine.mcap", "--duration", "1",
        *(["--save", "p.rrd"] if command == "plot" else []), cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    assert "mine.mcap already exists: give --force to replace it" in proc.stderr
    assert "simulated grippers" not in proc.stderr  # refused before anything started
    assert mine.read_bytes() == b"the user's own recording"
    assert not (tmp_path / "p.rrd").exists()


def test_force_replaces_a_recording(tmp_path: Path) -> None:
    mine = tmp_path / "mine.mcap"
    mine.write_bytes(b"old")
    proc = eg2scope("record", "--demo", "--buses", "can", "-o", "mine.mcap", "--duration", "1",
                    "--force", cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    with McapCaptureReader(mine) as reader:
        assert sum(1 for _ in reader) > 10 and not reader.errors


def test_a_recording_into_a_missing_folder_says_so_before_starting(tmp_path: Path) -> None:
    proc = eg2scope("record", "--demo", "-o", "nowhere/x.mcap", "--duration", "1", cwd=tmp_path)
    assert proc.returncode == 1
    assert "cannot write nowhere/x.mcap: there is no folder nowhere" in proc.stderr
    assert "Errno" not in proc.stderr and "simulated grippers" not in proc.stderr


def test_plot_of_a_source_that_never_opened_makes_no_file(tmp_path: Path) -> None:
    proc = eg2scope("plot", "--serial", str(tmp_path / "ttyUSB9"), "--save", "nope.rrd",
                    cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 1 and "no such port" in proc.stderr
    assert not (tmp_path / "nope.rrd").exists()


def test_plot_of_an_unreadable_capture_makes_no_file(tmp_path: Path) -> None:
    (tmp_path / "random.log").write_bytes(bytes(range(256)) * 20)
    proc = eg2scope("plot", "random.log", "--save", "r.rrd", cwd=tmp_path)
    assert proc.returncode == 3 and "nothing read" in proc.stderr
    assert not (tmp_path / "r.rrd").exists()
    assert "written to" not in proc.stderr


def test_plot_of_a_damaged_capture_keeps_what_it_read(tmp_path: Path) -> None:
    lines = (CAPTURES / "can_pick_place.log").read_text().splitlines(keepends=True)
    (tmp_path / "cut.log").write_text("".join(lines[:60]) + "not a frame\n" + lines[60])
    proc = eg2scope("plot", "cut.log", "--save", "c.rrd", cwd=tmp_path)
    assert proc.returncode == 3 and "line 61" in proc.stderr
    assert (tmp_path / "c.rrd").stat().st_size > 1000
