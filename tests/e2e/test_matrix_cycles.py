"""``eg2scope cycles --format jsonl`` on every input kind: as a real process (its default
engine), and in this process on each session engine, which must agree; every cell checked
against decode's records (the reference), with the motion commands found there again by this
test's own reading of docs/contracts.md ("Grip cycles"); and live on the simulated grippers."""

from __future__ import annotations

import contextlib
import io
from collections.abc import Iterator
from functools import cache
from pathlib import Path
from typing import Any

import orjson
import pytest
from e2e_checks import Prefetch, Ran, eg2scope, eg2scope_runs, skip_unless_native
from e2e_inputs import IDS, NATIVE_IDS

from analyzer.cli import main
from analyzer.cycles.model import KEYS, OUTCOMES, QUANTITIES

SESSION_CELLS = [(k, "python") for k in IDS] + [(k, "native") for k in NATIVE_IDS]
BROADCAST = {"eg2-serial": 255, "modbus-rtu": 0, "eg2-can": 16383}
SERIAL_MOTIONS = {0x10, 0x11, 0x18, 0x54}  # catch, release, continuous catch, seek
REGISTER_WRITES = {"modbus-rtu": {6, 16}, "eg2-can": {1}}


def parse(jsonl: bytes) -> list[dict[str, Any]]:
    return [orjson.loads(line) for line in jsonl.splitlines()]


def is_motion(r: dict[str, Any]) -> bool:
    """A request without errors that moves a gripper (contracts.md: a cycle starts there)."""
    if r["direction"] != "request" or r["errors"] or r["kind"] != "frame":
        return False
    if r["protocol"] == "eg2-serial":
        return r["code"] in SERIAL_MOTIONS
    if r["code"] not in REGISTER_WRITES.get(r["protocol"], set()):
        return False
    fields = r["fields"]
    return "CMD_OPENLEN_SET" in (fields.get("values") or {}) or fields.get("name") == (
        "CMD_OPENLEN_SET"
    )


def check_against_records(cycles: list[dict[str, Any]], records: list[dict[str, Any]]) -> None:
    """Every cycle starts at a motion command of its gripper (or a broadcast one), its evidence
    is frames of its gripper, and every motion command to a gripper starts one of its cycles or
    is a retry in one."""
    by_seq = {(r["bus"], r["seq"]): r for r in records}
    motions: dict[tuple[str, int], set[int]] = {}
    for r in records:
        if is_motion(r) and r["device"] != BROADCAST[r["protocol"]]:
            motions.setdefault((r["bus"], r["device"]), set()).add(r["seq"])
    copies: dict[tuple[str, int], set[int]] = {}
    for c in cycles:
        assert tuple(c) == KEYS
        assert c["outcome"] in OUTCOMES and set(c["unknown"]) <= set(QUANTITIES)
        start = by_seq[(c["bus"], c["start_seq"])]
        assert is_motion(start), start
        theirs = (c["device"], BROADCAST[start["protocol"]])  # its frames, and broadcasts
        assert start["device"] in theirs
        assert c["start_t"] == start["t"] and c["end_seq"] >= c["start_seq"]
        assert ("time" in c["unknown"]) == (c["start_t"] is None)
        assert c["start_seq"] in c["evidence"]
        for seq in c["evidence"]:
            assert by_seq[(c["bus"], seq)]["device"] in theirs
        sent = {s for s in c["evidence"] if is_motion(by_seq[(c["bus"], s)])}
        assert len(sent) == c["retries"] + 1
        if start["device"] == c["device"]:
            copies.setdefault((c["bus"], c["device"]), set()).update(sent)
    assert copies == motions


@pytest.fixture(scope="module")
def cycle_runs(request, inputs, tmp_path_factory) -> Iterator[Prefetch[Ran]]:
    def argv(kind: str) -> list[str]:
        return ["cycles", str(inputs[kind]), "--format", "jsonl", "--no-progress"]

    with eg2scope_runs(request, test_cycles_process, tmp_path_factory, argv) as runs:
        yield runs


@pytest.mark.parametrize("kind", IDS)
def test_cycles_process(kind: str, cycle_runs, reference) -> None:
    proc = cycle_runs(kind=kind).proc
    assert proc.returncode == 0, proc.stderr.decode()
    cycles = parse(proc.stdout)
    assert cycles, "no cycles"
    check_against_records(cycles, reference.decoded(kind).records)


@cache
def in_process(path: Path, engine: str) -> bytes:
    """The command in this process on one session engine (its JSONL)."""
    out = io.TextIOWrapper(io.BytesIO(), encoding="utf-8")
    with contextlib.redirect_stdout(out):
        code = main(["cycles", str(path), "-f", "jsonl", "--no-progress", "--engine", engine])
        out.flush()
    assert code == 0
    data: bytes = out.buffer.getvalue()  # type: ignore[attr-defined]
    return data


@pytest.mark.parametrize(("kind", "engine"), SESSION_CELLS)
def test_cycles_on_each_engine(kind: str, engine: str, inputs, reference) -> None:
    if engine == "native":
        skip_unless_native()
    found = in_process(inputs[kind], engine)
    check_against_records(parse(found), reference.decoded(kind).records)
    assert found == in_process(inputs[kind], "python")


def test_cycles_live_on_the_simulated_grippers(tmp_path: Path) -> None:
    """The demo's hosts close both grippers on their parts and open them again, on every bus:
    each cycle is written as it ends, and the stop ends the rest."""
    proc = eg2scope("cycles", "--demo", "--duration", "4", "-f", "jsonl", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr.decode()
    cycles = parse(proc.stdout)
    assert {c["bus"] for c in cycles} == {"rs232", "rs485", "can0"}
    assert all(tuple(c) == KEYS and c["outcome"] in OUTCOMES for c in cycles)
    assert {(c["bus"], c["device"]) for c in cycles if c["outcome"] == "gripped"}, cycles
