"""The dataset is the same whichever engine decodes: ``batch --engine python`` (the Python
decoders and Tracker for every capture) against the native core (``--engine native``: its
columns of records and state samples for candump logs and raw dumps, its CAN decoding and
Tracker in the sessions of the other CAN captures), file by file and row by row, on every kind
of capture: candump (plain and gzipped), python-can .asc and .blf, eg2scope recordings (one
bus, and the three buses of ``record --demo``), raw serial and Modbus dumps, a damaged log, and
the sample captures."""

from __future__ import annotations

import shutil
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from native_core import needs_native

from analyzer import cli
from analyzer.fleet import layout
from analyzer.fleet.inputs import expand

ROOT = Path(__file__).resolve().parents[2]

pytestmark = needs_native


@pytest.fixture(scope="module")
def inputs(fleet: dict[str, Path], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The fleet folder and the sample captures, in one folder."""
    folder = tmp_path_factory.mktemp("inputs")
    shutil.copytree(fleet["candump"].parents[2], folder / "fleet")
    shutil.copytree(ROOT / "captures", folder / "samples")
    return folder


def dataset(inputs: Path, engine: str, out: Path) -> Path:
    code = cli.main(
        [
            "batch",
            str(inputs),
            "-o",
            str(out),
            "--workers",
            "1",
            "--engine",
            engine,
            "--no-progress",
        ]
    )
    assert code == 1  # the unreadable file; every other capture is in
    return out


def files(root: Path) -> dict[Path, Path]:
    return {p.relative_to(root): p for p in root.rglob("*.parquet")}


def test_both_engines_write_the_same_dataset(inputs: Path, tmp_path: Path) -> None:
    python = files(dataset(inputs, "python", tmp_path / "python"))
    natively = files(dataset(inputs, "native", tmp_path / "native"))
    assert python.keys() == natively.keys()
    tables = {name: 0 for name in layout.TABLES}
    for name, path in sorted(python.items()):
        want, got = pq.read_table(path), pq.read_table(natively[name])
        if name.parts[0] == layout.CAPTURES:  # when each was decoded
            want, got = want.drop_columns(["decoded_at"]), got.drop_columns(["decoded_at"])
        assert got.schema.equals(want.schema, check_metadata=True), name
        assert got.num_rows == want.num_rows > 0, name
        for column in want.column_names:
            assert got[column].to_pylist() == want[column].to_pylist(), (name, column)
        tables[name.parts[0]] += 1
    # every table of every capture was compared: the captures of the folder, and their records
    # and states on each of their days and buses
    # but the unreadable one
    assert tables[layout.CAPTURES] == len(expand([str(inputs)]).paths) - 1
    assert tables[layout.RECORDS] >= tables[layout.CAPTURES] + 2  # the demo's three buses
    assert tables[layout.STATES] >= tables[layout.CAPTURES]
