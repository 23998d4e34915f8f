"""``eg2scope batch CAPTURE -o DATASET --workers 1`` on every input kind and both engines, as a
real process (a few at a time), read back with pyarrow's datasets: it exits 0 and the dataset
holds decode's records (per bus and seq), the reference session's state samples, one undamaged
capture row counting them; the grip cycles ``cycles --format jsonl`` finds in the capture, one
for one and key for key (``cycles/``); and each bus's health second by second (``health/``),
which adds up to what ``stats --format json`` says of the bus: its frames, bits and errors, the
rate it was counted at, the mean load over its span and the max and p95 over its whole seconds.
A scenario recording's cycles in the dataset are held against the simulator's truth, and its
bus-off against the controller state of the seconds."""

from __future__ import annotations

import datetime as dt
import hashlib
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import orjson
import pyarrow as pa
import pyarrow.dataset as ds
import pytest
from e2e_checks import (
    GIVEN_RATES,
    RATES_KINDS,
    Prefetch,
    check_given_rates,
    eg2scope,
    skip_unless_native,
)
from e2e_inputs import IDS
from scenario_capture import read_truth, record_scenarios
from scenario_truth import ALL_BUSES, check, pairs

from analyzer.cycles.model import KEYS
from analyzer.fleet import layout
from analyzer.sources.candump import RELATIVE_LIMIT

DUMP_BUS = {"serial-dump": "rs232", "modbus-dump": "rs485"}
ENGINES = ("python", "native")
RATE_OF = {"can": ("bitrate", "bitrate_from"), "serial": ("baud", "baud_from")}
PERCENT = 1e-3  # load figures are rounded to 0.001 %


def table(root: Path, name: str) -> pa.Table:
    """A table of the dataset with its partition keys (empty: a table no capture has rows of)."""
    if not (root / name).exists():
        return pa.table({})
    return ds.dataset(root / name, format="parquet", partitioning="hive").to_table()


def rows(root: Path, name: str) -> list[dict[str, Any]]:
    return table(root, name).to_pylist()


@dataclass(frozen=True)
class BatchRun:
    """A batch of one capture, and the references of the same capture: ``cycles --format
    jsonl`` and ``stats --format json`` (real processes, each command's default engine)."""

    capture: Path
    root: Path
    batch: Any
    cycles: list[dict[str, Any]]
    stats: dict[str, Any]


def run_all(path: Path, engine: str, cwd: Path, *rates: str) -> BatchRun:
    """``batch``, ``cycles`` and ``stats`` of the capture; ``rates``: batch's and stats'."""
    argv = ["batch", str(path), "-o", "fleet", "--workers", "1", "--no-progress", *rates]
    batch = eg2scope(*argv, "--engine", engine, cwd=cwd)
    cycles = eg2scope("cycles", str(path), "--format", "jsonl", "--no-progress", cwd=cwd)
    stats = eg2scope("stats", str(path), "--format", "json", "--no-progress", *rates, cwd=cwd)
    assert cycles.returncode == 0, cycles.stderr.decode()
    assert stats.returncode == 0, stats.stderr.decode()
    found = [orjson.loads(line) for line in cycles.stdout.splitlines()]
    return BatchRun(path, cwd / "fleet", batch, found, orjson.loads(stats.stdout))


@pytest.fixture(scope="module")
def batches(request, inputs, tmp_path_factory) -> Iterator[Prefetch[BatchRun]]:
    def start(kind: str, engine: str) -> Callable[[], BatchRun]:
        path, cwd = inputs[kind], tmp_path_factory.mktemp("batch")
        return lambda: run_all(path, engine, cwd)

    with Prefetch(request, test_batch_one_worker, start) as runs:
        yield runs


def batched(batches: Prefetch[BatchRun], kind: str, engine: str) -> BatchRun:
    if engine == "native":
        skip_unless_native()
    ran = batches(kind=kind, engine=engine)
    assert ran.batch.returncode == 0, ran.batch.stderr.decode()
    return ran


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("kind", IDS)
def test_batch_one_worker(kind: str, engine: str, batches, reference) -> None:
    ran = batched(batches, kind, engine)
    decoded = reference.decoded(kind).records
    records = table(ran.root, layout.RECORDS)
    assert records.num_rows == len(decoded)
    stored = sorted(zip(records["bus"].to_pylist(), records["seq"].to_pylist(), strict=True))
    # a raw dump's bus is named by its protocol in the dataset, as a live serial line is
    bus = DUMP_BUS.get(kind)
    assert stored == sorted((bus or r["bus"], r["seq"]) for r in decoded)
    assert table(ran.root, layout.STATES).num_rows == len(reference.samples(kind))
    [row] = rows(ran.root, layout.CAPTURES)
    assert (row["records"], row["damaged"]) == (len(decoded), False)
    summary = ran.batch.stdout.decode()
    assert f"grip cycles: {len(ran.cycles):,}," in summary
    assert "records/, states/, cycles/, health/, captures/" in summary


def _identity(ran: BatchRun) -> tuple[str, str]:
    return str(ran.capture), hashlib.sha256(ran.capture.read_bytes()).hexdigest()


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("kind", IDS)
def test_the_cycles_table_is_what_cycles_finds(kind: str, engine: str, batches) -> None:
    ran = batched(batches, kind, engine)
    stored = rows(ran.root, layout.CYCLES)
    assert {(r["capture_path"], r["capture_hash"]) for r in stored} <= {_identity(ran)}
    got = sorted(({k: r[k] for k in KEYS} for r in stored), key=_cycle_order)
    bus = DUMP_BUS.get(kind)
    want = sorted(({**c, "bus": bus or c["bus"]} for c in ran.cycles), key=_cycle_order)
    assert got == want
    for r in stored:  # filed by the day of its start, else of the file's modification
        when = r["start_t"] if r["start_t"] is not None else ran.capture.stat().st_mtime
        if when < RELATIVE_LIMIT:
            when = ran.capture.stat().st_mtime
        assert r["day"] == str(dt.datetime.fromtimestamp(when, dt.UTC).date())


def _cycle_order(c: dict[str, Any]) -> tuple[str, int, int]:
    return c["bus"], c["device"], c["start_seq"]


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("kind", IDS)
def test_the_health_table_adds_up_to_stats(kind: str, engine: str, batches) -> None:
    ran = batched(batches, kind, engine)
    stored = rows(ran.root, layout.HEALTH)
    assert {(r["capture_path"], r["capture_hash"]) for r in stored} <= {_identity(ran)}
    by_bus: dict[str, list[dict[str, Any]]] = {}
    for r in stored:
        by_bus.setdefault(r["bus"], []).append(r)
    buses = ran.stats["buses"]
    assert buses
    for bus in buses:
        name = DUMP_BUS.get(kind) or bus["bus"]
        check_seconds(sorted(by_bus.pop(name, []), key=lambda r: r["second"]), bus, ran.capture)
    assert not by_bus  # no rows of a bus stats does not know


@pytest.mark.parametrize("kind", RATES_KINDS)
def test_the_health_table_at_the_rates_given(kind: str, inputs, tmp_path) -> None:
    """``batch PATH -b 1000000 --baud 9600``: each bus's rows are counted at the rate given,
    ``rate_from`` the option, adding up to ``stats``' figures at the same options."""
    ran = run_all(inputs[kind], "auto", tmp_path, *GIVEN_RATES)  # candump: native, where built
    assert ran.batch.returncode == 0, ran.batch.stderr.decode()
    check_given_rates(ran.stats["buses"])
    stored = rows(ran.root, layout.HEALTH)
    for bus in ran.stats["buses"]:
        seconds = sorted((r for r in stored if r["bus"] == bus["bus"]), key=lambda r: r["second"])
        check_seconds(seconds, bus, ran.capture)


def check_seconds(seconds: list[dict[str, Any]], bus: dict[str, Any], capture: Path) -> None:
    """One bus's rows against its ``stats --format json`` figures; each filed by the day of
    its second, else (the capture's own clock) of the file's modification."""
    if bus["timing"] is not None:  # a raw dump: no times, no seconds
        assert not seconds
        return
    assert seconds, bus["bus"]
    rate_key, source_key = RATE_OF[bus["kind"]]
    rate = bus[rate_key]
    kinds = {(r["kind"], r["rate"], r["rate_from"]) for r in seconds}
    assert kinds == {(bus["kind"], rate, bus[source_key])}
    mtime = capture.stat().st_mtime
    numbers = [r["second"] for r in seconds]
    assert numbers == sorted(set(numbers))  # one row per second
    assert sum(r["bits"] for r in seconds) == bus["bits"]
    assert sum(r["frames"] for r in seconds) == bus["frames"]
    assert sum(r["errors"] for r in seconds) == bus["error_frames"]["total"]
    for r in seconds:
        assert r["load_pct"] == pytest.approx(100.0 * r["bits"] / rate, abs=PERCENT)
        calendar = r["second"] >= RELATIVE_LIMIT
        stamp = dt.datetime.fromtimestamp(r["second"] if calendar else mtime, dt.UTC)
        assert r["timestamp"] == (stamp if calendar else None)
        assert r["day"] == str(stamp.date())
    load = bus["load_pct"]
    if bus["duration_s"]:
        mean = 100.0 * bus["bits"] / rate / bus["duration_s"]
        assert load["mean"] == pytest.approx(mean, abs=PERCENT, rel=1e-5)
    assert (load["max"], load["p95"]) in _whole_second_loads(seconds, load["mean"])


def _whole_second_loads(seconds: list[dict[str, Any]], mean: float | None) -> list[tuple]:
    """(max, p95) over the whole seconds the bus's span covers (a silent one at 0 %): the span
    runs from its first frame's start, which is in its first second or (a frame across the
    turn of a second) the one before; with none whole, the mean for both."""
    load = {r["second"]: r["load_pct"] for r in seconds}
    first, last = seconds[0]["second"], seconds[-1]["second"]
    out = []
    for start in (first, first + 1):
        loads = sorted(load.get(s, 0.0) for s in range(start, last))
        if not loads:
            out.append((mean, mean))
            continue
        rank = max(1, math.ceil(0.95 * len(loads)))
        out.append((loads[-1], loads[rank - 1]))
    return out


# -- a scenario recording: the simulator's truth -----------------------------------------------

SCENARIOS = ("tour", "bus-off")


@pytest.fixture(scope="module")
def scenario_batches(tmp_path_factory) -> dict[tuple[str, str], BatchRun]:
    """Each scenario recorded on all three buses (``record --demo --scenario``), then batched
    on each engine."""
    folder = tmp_path_factory.mktemp("scenarios")
    record_scenarios(list(SCENARIOS), folder)
    out = {}
    for name in SCENARIOS:
        for engine in ENGINES:
            cwd = tmp_path_factory.mktemp(f"{name}-{engine}")
            out[name, engine] = run_all(folder / f"{name}.mcap", engine, cwd)
    return out


@pytest.mark.parametrize("engine", ENGINES)
def test_a_scenarios_cycles_in_the_dataset_are_its_truth(engine: str, scenario_batches) -> None:
    if engine == "native":
        skip_unless_native()
    ran = scenario_batches["tour", engine]
    assert ran.batch.returncode == 0, ran.batch.stderr.decode()
    cycles = rows(ran.root, layout.CYCLES)
    truth = read_truth(ran.capture.parent, "tour")
    for bus in ALL_BUSES:
        checked = pairs(cycles, truth, bus)
        assert checked, f"no truth on {bus}"
        for told, seen in checked:
            check(told, seen)


@pytest.mark.parametrize("engine", ENGINES)
def test_a_bus_off_is_in_the_seconds_of_its_bus(engine: str, scenario_batches) -> None:
    if engine == "native":
        skip_unless_native()
    ran = scenario_batches["bus-off", engine]
    assert ran.batch.returncode == 0, ran.batch.stderr.decode()
    [can] = [b for b in ran.stats["buses"] if b["bus"] == "can0"]
    periods = [p for p in can["error_states"] if p["state"] == "bus_off"]
    assert periods, can["error_states"]
    seconds = {r["second"]: r for r in rows(ran.root, layout.HEALTH) if r["bus"] == "can0"}
    for period in periods:
        row = seconds[math.floor(period["start"])]
        assert row["state"] == "bus_off" and row["errors"] and row["worst"], row
    check_seconds(sorted(seconds.values(), key=lambda r: r["second"]), can, ran.capture)
