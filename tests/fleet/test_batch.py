"""``eg2scope batch``: a folder of generated captures of every kind into one Parquet dataset,
checked against what ``decode --format parquet`` and ``stats`` give for each file."""

from __future__ import annotations

import datetime as dt
import json
import shutil
from collections import Counter
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest

from analyzer import cli
from analyzer.fleet import layout
from analyzer.fleet.inputs import content_hash, expand
from analyzer.model import StateSample
from analyzer.parquet.schema import SCHEMA
from analyzer.session import engine as native
from analyzer.session.listener import Listener
from analyzer.session.session import Session
from analyzer.sources.capture import open_capture
from analyzer.sources.source import CaptureSource

GOOD = ("candump", "candump_gz", "asc", "blf", "mcap", "demo", "serial", "modbus")
#: a raw dump's bus in the dataset: named by its protocol, as a live serial line is (decode's
#: records of a dump say "serial")
RAW_BUS = {"serial": "rs232", "modbus": "rs485"}


def dataset_bus(kind: str, bus: str) -> str:
    return RAW_BUS.get(kind, bus)


def batch(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = cli.main(["batch", *argv, "--no-progress"])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def dataset(fleet: dict[str, Path], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The folder in one run, in this process (--workers 1)."""
    out = tmp_path_factory.mktemp("dataset") / "fleet"
    code = cli.main(["batch", str(fleet["candump"].parents[2]), "-o", str(out), "--workers", "1"])
    assert code == 1  # the unreadable file; the rest are in
    return out


def table(root: Path, name: str) -> pa.Table:
    return ds.dataset(root / name, format="parquet", partitioning="hive").to_table()


def rows_of(root: Path, name: str, path: Path) -> pa.Table:
    t = table(root, name)
    mine = t.filter(pa.compute.equal(t["capture_hash"], content_hash(path)))
    return mine.sort_by("seq") if "seq" in mine.column_names else mine


def decoded(path: Path, tmp_path: Path) -> pa.Table:
    out = tmp_path / f"{path.name}.parquet"
    code = cli.main(["decode", str(path), "-f", "parquet", "-o", str(out), "--no-progress"])
    assert code in (0, 3)
    return pq.read_table(out).sort_by("seq")


def stats_of(path: Path, capsys: pytest.CaptureFixture[str]) -> dict[str, Any]:
    capsys.readouterr()
    cli.main(["stats", str(path), "-f", "json", "--no-progress"])
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("kind", [*GOOD, "damaged"])
def test_records_equal_decode_parquet_row_for_row(
    kind: str, fleet: dict[str, Path], dataset: Path, tmp_path: Path
) -> None:
    got = rows_of(dataset, layout.RECORDS, fleet[kind])
    want = decoded(fleet[kind], tmp_path)
    assert got.num_rows == want.num_rows > 100
    rows = want.to_pylist()
    for row in rows:
        row["bus"] = dataset_bus(kind, row["bus"])
    assert got.select(SCHEMA.names).to_pylist() == rows
    assert set(got["capture_path"].to_pylist()) == {str(fleet[kind].resolve())}


@pytest.mark.parametrize("kind", [*GOOD, "damaged"])
def test_captures_counts_match_stats(
    kind: str, fleet: dict[str, Path], dataset: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    row = rows_of(dataset, layout.CAPTURES, fleet[kind]).to_pylist()
    stats = stats_of(fleet[kind], capsys)
    assert len(row) == 1
    (row0,) = row
    for key in ("records", "frames", "valid_frames", "garbage_bytes", "truncated"):
        assert row0[key] == stats[key], key
    for key in ("requests", "responses", "unanswered", "retransmissions", "errors", "warnings"):
        assert row0[key] == sum(d[key] for d in stats["devices"]), key
    assert dict(row0["flags"]) == stats["flags"]
    assert sorted(row0["protocols"]) == sorted(stats["protocols"])
    devices = [(d["bus"], d["protocol"], d["device"]) for d in row0["devices"]]
    assert devices == [
        (dataset_bus(kind, d["bus"]), d["protocol"], d["device"]) for d in stats["devices"]
    ]
    assert row0["damaged"] == (kind == "damaged") == bool(row0["damage"])
    assert row0["size"] == fleet[kind].stat().st_size
    assert row0["capture_hash"] == content_hash(fleet[kind])
    if row0["t_start"] is None:  # a raw dump has no clock: no latency
        assert row0["latency_p50_ms"] is None
    else:
        assert 0 < row0["latency_p50_ms"] <= row0["latency_p95_ms"] <= row0["latency_max_ms"]
        worst = max(d["max_ms"] for d in stats["devices"] if d["max_ms"] is not None)
        assert row0["latency_max_ms"] == worst


class Samples(Listener):
    wants_states = True

    def __init__(self) -> None:
        self.samples: list[StateSample] = []

    def on_records(self, records: list[Any]) -> None:
        pass

    def on_states(self, samples: list[StateSample]) -> None:
        self.samples += samples


@pytest.mark.parametrize("kind", GOOD)
def test_states_are_every_sample_of_the_session(
    kind: str, fleet: dict[str, Path], dataset: Path
) -> None:
    listener = Samples()
    reader = open_capture(fleet[kind])
    with reader:
        Session(CaptureSource(reader, None), [listener]).run()
    # in seq order, as rows_of reads the dataset: a recording of several buses comes in
    # capture-time order, in which a serial frame's record may follow a later-numbered one
    want = sorted((s.to_dict() for s in listener.samples), key=lambda d: d["seq"])
    got = rows_of(dataset, layout.STATES, fleet[kind])
    assert got.num_rows == len(want) > 50
    keys = [k for k in want[0] if k != "bus"]
    assert [{k: r[k] for k in keys} for r in got.to_pylist()] == [
        {k: w[k] for k in keys} for w in want
    ]
    assert got["bus"].to_pylist() == [dataset_bus(kind, w["bus"]) for w in want]


def test_partitions_are_day_and_bus(fleet: dict[str, Path], dataset: Path) -> None:
    records = table(dataset, layout.RECORDS)
    days = Counter(zip(records["day"].to_pylist(), records["bus"].to_pylist(), strict=True))
    assert ("2025-11-21", "can0") in days and ("2025-11-22", "can0") in days
    assert ("2025-11-24", "can1") in days  # the MCAP recording's bus
    for path in (dataset / layout.RECORDS).rglob("*.parquet"):
        assert "bus" not in pq.read_schema(path).names  # the partition key is the folder
    # the UTC day of each record's time (the demo's and python-can's have fractions of a
    # microsecond), in records/ and states/
    for name in (layout.RECORDS, layout.STATES):
        whole = table(dataset, name)
        timed = whole.filter(pa.compute.is_valid(whole["t"]))
        assert timed.num_rows > 1000
        for t, day in zip(timed["t"].to_pylist(), timed["day"].to_pylist(), strict=True):
            assert str(day) == dt.datetime.fromtimestamp(t, dt.UTC).strftime("%Y-%m-%d")
    demo = rows_of(dataset, layout.RECORDS, fleet["demo"])
    assert set(demo["t"].to_pylist()) != {round(t, 6) for t in demo["t"].to_pylist()}
    # raw dumps have no clock: the day their file was written
    serial_day = rows_of(dataset, layout.RECORDS, fleet["serial"])
    assert serial_day.num_rows and serial_day["t"].null_count == serial_day.num_rows


def test_unreadable_is_reported_and_the_rest_go_on(
    fleet: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _out, err = batch(
        capsys,
        str(fleet["unreadable"]),
        str(fleet["serial"]),
        "-o",
        str(tmp_path / "d"),
        "--workers",
        "1",
    )
    assert code == 1
    assert f"{fleet['unreadable'].resolve()}: unreadable: not an MCAP file" in err
    assert layout.done_hashes(tmp_path / "d") == {content_hash(fleet["serial"])}


def test_a_folder_scan_takes_captures_only(fleet: dict[str, Path]) -> None:
    root = fleet["candump"].parents[2]
    found = expand([str(root)]).paths
    assert {p.name for p in found} == {p.name for p in fleet.values()}
    assert not any(p.name == "README.txt" for p in found)
    pattern = expand([f"{root}/site-a/**/*.log*"]).paths
    assert {p.name for p in pattern} == {"can_day1.log", "can_day2.log.gz"}


def test_a_second_run_skips_everything_and_changes_nothing(
    fleet: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = tmp_path / "d"
    inputs = [str(fleet[k]) for k in GOOD]
    assert batch(capsys, *inputs, "-o", str(root), "--workers", "1")[0] == 0
    before = {p: p.stat().st_mtime_ns for p in root.rglob("*.parquet")}
    code, out, _ = batch(capsys, *inputs, "-o", str(root), "--workers", "1")
    assert code == 0
    assert f"already in the dataset │     {len(GOOD)}" in out
    assert {p: p.stat().st_mtime_ns for p in root.rglob("*.parquet")} == before
    # a copy of a capture elsewhere has the same content: skipped too
    copy = tmp_path / "copy.bin"
    shutil.copy(fleet["serial"], copy)
    code, out, _ = batch(capsys, str(copy), "-o", str(root), "--workers", "1")
    assert code == 0 and "already in the dataset │     1" in out


def test_the_rates_given_count_the_health_table(
    fleet: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--bitrate`` and ``--baud`` (over the recording's own): every health row of the CAN
    bus is counted at the bit rate given, of a serial line at the baud given, and says so in
    ``rate`` and ``rate_from``, adding up to ``stats`` at the same options. The rates are part
    of the capture's decode options: a run at the same rates skips it, one without them
    decodes it again at its own."""
    mcap, root = fleet["demo"], tmp_path / "d"
    given = ("--bitrate", "1000000", "--baud", "9600")
    assert batch(capsys, str(mcap), "-o", str(root), "--workers", "1", *given)[0] == 0
    capsys.readouterr()
    assert cli.main(["stats", str(mcap), "-f", "json", "--no-progress", *given]) == 0
    buses = {b["bus"]: b for b in json.loads(capsys.readouterr().out)["buses"]}
    seconds = table(root, layout.HEALTH).to_pylist()
    assert {r["bus"] for r in seconds} == set(buses) == {"rs232", "rs485", "can0"}
    for bus, figures in buses.items():
        mine = [r for r in seconds if r["bus"] == bus]
        said = ("can", 1_000_000, "--bitrate") if bus == "can0" else ("serial", 9600, "--baud")
        assert {(r["kind"], r["rate"], r["rate_from"]) for r in mine} == {said}
        assert sum(r["bits"] for r in mine) == figures["bits"]
        for r in mine:
            assert r["load_pct"] == pytest.approx(100.0 * r["bits"] / said[1], abs=1e-3)
    [row] = table(root, layout.CAPTURES).to_pylist()
    assert row["decode_options"] == "--protocol auto --bitrate 1000000 --baud 9600"
    code, out, _ = batch(capsys, str(mcap), "-o", str(root), "--workers", "1", *given)
    assert code == 0 and "already in the dataset │     1" in out
    code, out, err = batch(capsys, str(mcap), "-o", str(root), "--workers", "1")
    assert code == 0 and "decoded                │     1" in out
    assert "decoded again (the dataset held it decoded with --protocol auto --bitrate" in err
    own = {(r["kind"], r["rate_from"]) for r in table(root, layout.HEALTH).to_pylist()}
    assert own == {("can", "default"), ("serial", "recording")}  # a virtual CAN bus has none


def test_force_decodes_again_without_duplicates(
    fleet: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = tmp_path / "d"
    inputs = [str(fleet["candump"]), str(fleet["modbus"])]
    assert batch(capsys, *inputs, "-o", str(root), "--workers", "1")[0] == 0
    first = table(root, layout.RECORDS).num_rows
    code, out, _ = batch(capsys, *inputs, "-o", str(root), "--workers", "1", "--force")
    assert code == 0 and "decoded                │     2" in out
    records = table(root, layout.RECORDS)
    assert records.num_rows == first
    keys = Counter(
        zip(records["capture_hash"].to_pylist(), records["seq"].to_pylist(), strict=True)
    )
    assert max(keys.values()) == 1


def test_a_killed_attempt_is_cleaned_up_by_the_next(
    fleet: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A worker that died after renaming some partitions but before the captures/ row: the
    next attempt removes them first, so nothing is duplicated; temporary files are removed."""
    root = tmp_path / "d"
    assert batch(capsys, str(fleet["candump"]), "-o", str(root), "--workers", "1")[0] == 0
    digest = content_hash(fleet["candump"])
    (row,) = (root / layout.CAPTURES).glob(f"day=*/{digest}.parquet")
    row.unlink()  # as if the worker died before its commit
    stray = next((root / layout.RECORDS).rglob("*.parquet")).with_name(".x.parquet.tmp-1")
    stray.write_bytes(b"half")
    assert batch(capsys, str(fleet["candump"]), "-o", str(root), "--workers", "1")[0] == 0
    assert not stray.exists()
    assert table(root, layout.RECORDS).num_rows == decoded(fleet["candump"], tmp_path).num_rows


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["nothing-here/*.log", "-o", "{tmp}/d"], "no file matches 'nothing-here/*.log'"),
        (["missing.log", "-o", "{tmp}/d"], "capture not found: missing.log"),
        (["{capture}", "-o", "{capture}"], "is a file; batch writes a dataset folder"),
        (
            ["{capture}", "-o", "{tmp}/d", "--scheduler", "tcp://h:8786", "--workers", "2"],
            "--workers is for a local cluster",
        ),
        (["{capture}", "-o", "{tmp}/d", "--workers", "0"], "must be 1 or more"),
        (["{capture}", "-o", "{tmp}/d", "--baud", "0"], "must be 1 or more"),
    ],
)
def test_usage_errors_fail_at_once(
    argv: list[str],
    message: str,
    fleet: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    argv = [a.format(tmp=tmp_path, capture=fleet["serial"]) for a in argv]
    with pytest.raises(SystemExit) as exit_:
        cli.main(["batch", *argv])
    assert exit_.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "d").exists()


def test_one_run_per_dataset_at_a_time(
    fleet: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = tmp_path / "d"
    with layout.run_lock(root), pytest.raises(SystemExit) as exit_:
        cli.main(["batch", str(fleet["serial"]), "-o", str(root), "--workers", "1"])
    assert exit_.value.code == 2
    assert "another 'eg2scope batch' is writing" in capsys.readouterr().err


def test_inputs_are_never_changed(
    fleet: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    def snapshot() -> dict[Path, tuple[str, int]]:
        return {p: (content_hash(p), p.stat().st_mtime_ns) for p in fleet.values()}

    before = snapshot()
    root = fleet["candump"].parents[2]
    assert batch(capsys, str(root), "-o", str(tmp_path / "d"), "--workers", "1")[0] == 1
    assert snapshot() == before


def test_engine_native_without_the_core_is_a_usage_error(
    fleet: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(native, "_native", None)  # as on a machine without Rust
    monkeypatch.setattr(native, "WHY_NOT", "not built: no Rust toolchain at install time")
    with pytest.raises(SystemExit) as exit_:
        cli.main(["batch", str(fleet["candump"]), "-o", str(tmp_path / "d"), "--engine", "native"])
    assert exit_.value.code == 2
    assert "--engine native: the native core is not built" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()
    # the default goes on in Python, with the same dataset as the native core's (elsewhere)
    code = cli.main(["batch", str(fleet["candump"]), "-o", str(tmp_path / "d"), "--workers", "1"])
    assert code == 0
    assert layout.done_hashes(tmp_path / "d") == {content_hash(fleet["candump"])}
