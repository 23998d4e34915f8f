"""The queries docs/fleet.md shows run as they are in DuckDB on a dataset made from captures/."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import duckdb
import pytest

from analyzer import cli

ROOT = Path(__file__).resolve().parents[2]
QUERIES = re.findall(r"```sql\n(.*?)```", (ROOT / "docs" / "fleet.md").read_text(), re.S)


@pytest.fixture(scope="module")
def fleet_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder holding ``fleet/``, made from the sample captures, as the docs assume."""
    here = tmp_path_factory.mktemp("docs")
    shutil.copytree(ROOT / "captures", here / "captures")
    code = cli.main(["batch", str(here / "captures"), "-o", str(here / "fleet"), "--workers", "1"])
    assert code == 0
    return here


def run(query: str, folder: Path, monkeypatch: pytest.MonkeyPatch) -> list[tuple]:
    monkeypatch.chdir(folder)
    return duckdb.sql(query).fetchall()


def test_the_docs_show_three_queries() -> None:
    assert len(QUERIES) == 3


def test_unanswered_requests_and_faults_by_gripper_and_command(
    fleet_folder: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    rows = run(QUERIES[0], fleet_folder, monkeypatch)
    assert ("rs485", 2, "unanswered", "CMD_OPENLEN_SET", 1) in rows  # the Modbus dump's bus
    assert all(
        problem == "unanswered" or problem.startswith("fault: ") for _, _, problem, *_ in rows
    )


def test_latency_per_day_and_command(fleet_folder: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    rows = run(QUERIES[1], fleet_folder, monkeypatch)
    assert rows
    commands = {command for _, command, *_ in rows}
    assert "CMD_FORCE_ACT..CMD_TEMP" in commands
    for _, _, responses, p50, p95, worst in rows:
        assert responses > 0 and 0 < p50 <= p95 <= worst


def test_captures_that_need_a_look(fleet_folder: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    rows = run(QUERIES[2], fleet_folder, monkeypatch)
    names = {Path(row[0]).name for row in rows}
    assert names == {"can_pick_place.log", "serial_session.bin", "modbus_session.bin"}
    assert [row[4] for row in rows] == sorted((row[4] for row in rows), reverse=True)


def test_polars_and_pandas_read_it_as_the_docs_say(
    fleet_folder: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """As docs/fleet.md says (neither is a dependency of eg2scope; both are of its tests)."""
    import pandas as pd
    import polars as pl

    monkeypatch.chdir(fleet_folder)
    want = duckdb.sql(
        "SELECT count(*) FROM read_parquet('fleet/records/**/*.parquet', hive_partitioning = true)"
    ).fetchall()[0][0]
    assert want > 0
    frame = pl.scan_parquet("fleet/records/**/*.parquet", hive_partitioning=True).collect()
    assert frame.height == want and {"bus", "day", "capture_hash"} <= set(frame.columns)
    table = pd.read_parquet("fleet/records")
    assert len(table) == want and {"bus", "day", "capture_hash"} <= set(table.columns)
