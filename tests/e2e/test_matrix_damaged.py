"""Every input kind cut short (its first 60 % of bytes), through decode on each engine, stats,
batch and cycles: exit 3 where the file itself is damaged (a container or a line cut off), 0
for a raw dump (whose cut frame is a record of its own, docs/contracts.md); stderr says what,
naming the file once; and every record before the damage is decoded as it is in the whole
file."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import orjson
import pyarrow.dataset as ds
import pytest
from e2e_checks import Decoded, Prefetch, Ran, eg2scope_runs
from e2e_inputs import IDS

from analyzer.cli import main
from analyzer.fleet import layout

RAW_DUMPS = {"serial-dump", "modbus-dump"}
KEPT = 0.6  # of the file's bytes


@pytest.fixture(scope="module")
def cut(inputs, tmp_path_factory: pytest.TempPathFactory):
    folder = tmp_path_factory.mktemp("cut")
    made: dict[str, Path] = {}

    def make(kind: str) -> Path:
        if kind not in made:
            whole = inputs[kind].read_bytes()
            made[kind] = folder / f"cut-{inputs[kind].name}"
            made[kind].write_bytes(whole[: int(len(whole) * KEPT)])
        return made[kind]

    return make


def damaged_exit(kind: str) -> int:
    return 0 if kind in RAW_DUMPS else 3


def places(records: list[dict[str, Any]]) -> list[tuple[int, str | None]]:
    """Each record's place in its bus's input (its offset, or its index for CAN) and name: a
    recording numbers its records (``seq``) in the order it reads them, which differs when it
    has to be recovered."""
    return [(r["index"] if r["offset"] is None else r["offset"], r["name"]) for r in records]


def check_prefix(kind: str, damaged: Decoded, reference) -> None:
    """Per bus, the records before the last one (which the cut may have changed) are the whole
    file's first records."""
    whole = reference.decoded(kind).by_bus()
    got = damaged.by_bus()
    assert got, "nothing before the damage was decoded"
    for bus, records in got.items():
        before = places(records)[:-1]
        assert before == places(whole[bus])[: len(before)], bus


@pytest.fixture(scope="module")
def decodes(request, cut, tmp_path_factory) -> Iterator[Prefetch[Ran]]:
    def argv(kind: str, engine: str) -> list[str]:
        return ["decode", str(cut(kind)), "--format", "jsonl", "--engine", engine]

    with eg2scope_runs(request, test_decode_of_a_cut_file, tmp_path_factory, argv) as runs:
        yield runs


@pytest.mark.parametrize("engine", ["python", "auto"])
@pytest.mark.parametrize("kind", IDS)
def test_decode_of_a_cut_file(kind: str, engine: str, cut, decodes, reference) -> None:
    path, proc = cut(kind), decodes(kind=kind, engine=engine).proc
    err = proc.stderr.decode()
    assert proc.returncode == damaged_exit(kind), err
    if proc.returncode:
        assert path.name in err, err
        doubled = [line for line in err.splitlines() if line.count(path.name) > 1]
        assert not doubled, f"the file is named twice: {doubled}"
    check_prefix(kind, Decoded.parse(proc.stdout), reference)


@pytest.mark.parametrize("kind", IDS)
def test_stats_of_a_cut_file(kind: str, cut, capsys) -> None:
    assert main(["stats", str(cut(kind)), "--format", "json", "--no-progress"]) == damaged_exit(
        kind
    ), capsys.readouterr().err


@pytest.mark.parametrize("kind", IDS)
def test_batch_of_a_cut_file(kind: str, cut, tmp_path: Path, capsys) -> None:
    out = tmp_path / "fleet"
    argv = ["batch", str(cut(kind)), "-o", str(out), "--workers", "1", "--no-progress"]
    assert main(argv) == damaged_exit(kind), capsys.readouterr().err
    [row] = ds.dataset(out / layout.CAPTURES, partitioning="hive").to_table().to_pylist()
    assert row["damaged"] is (kind not in RAW_DUMPS), row["damage"]


@pytest.mark.parametrize("kind", IDS)
def test_cycles_of_a_cut_file(kind: str, cut, inputs, capsys) -> None:
    """The cycles before the cut are the whole file's (a recording numbers its records as it
    reads them, so only the other kinds are compared by seq); those the cut ends end there."""
    argv = ["cycles", str(cut(kind)), "--format", "jsonl", "--no-progress"]
    assert main(argv) == damaged_exit(kind), capsys.readouterr().err
    cut_cycles = [orjson.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert main(["cycles", str(inputs[kind]), "--format", "jsonl", "--no-progress"]) == 0
    whole = [orjson.loads(line) for line in capsys.readouterr().out.splitlines()]
    if not kind.endswith("recording"):
        assert {c["start_seq"] for c in cut_cycles} <= {c["start_seq"] for c in whole}
    assert len(cut_cycles) <= len(whole)
