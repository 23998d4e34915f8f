"""``eg2scope batch CAPTURE -o DATASET --workers 1`` on every input kind, as a real process (a
few at a time): it exits 0 and the dataset holds decode's records (per bus and seq), the
reference session's state samples and one undamaged capture row counting them."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pyarrow as pa
import pyarrow.dataset as ds
import pytest
from e2e_checks import Prefetch, Ran, eg2scope_runs
from e2e_inputs import IDS

from analyzer.fleet import layout

DUMP_BUS = {"serial-dump": "rs232", "modbus-dump": "rs485"}


def table(root: Path, name: str) -> pa.Table:
    return ds.dataset(root / name, format="parquet", partitioning="hive").to_table()


@pytest.fixture(scope="module")
def batches(request, inputs, tmp_path_factory) -> Iterator[Prefetch[Ran]]:
    def argv(kind: str) -> list[str]:
        return ["batch", str(inputs[kind]), "-o", "fleet", "--workers", "1", "--no-progress"]

    with eg2scope_runs(request, test_batch_one_worker, tmp_path_factory, argv) as runs:
        yield runs


@pytest.mark.parametrize("kind", IDS)
def test_batch_one_worker(kind: str, batches, reference) -> None:
    ran = batches(kind=kind)
    out = ran.cwd / "fleet"
    assert ran.proc.returncode == 0, ran.proc.stderr.decode()
    decoded = reference.decoded(kind).records
    records = table(out, layout.RECORDS)
    assert records.num_rows == len(decoded)
    stored = sorted(zip(records["bus"].to_pylist(), records["seq"].to_pylist(), strict=True))
    # a raw dump's bus is named by its protocol in the dataset, as a live serial line is
    bus = DUMP_BUS.get(kind)
    assert stored == sorted((bus or r["bus"], r["seq"]) for r in decoded)
    assert table(out, layout.STATES).num_rows == len(reference.samples(kind))
    [row] = table(out, layout.CAPTURES).to_pylist()
    assert (row["records"], row["damaged"]) == (len(decoded), False)
