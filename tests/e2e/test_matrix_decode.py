"""``eg2scope decode --format jsonl`` on every input kind, as a real process, on each engine:
the Python decoders, the native core, and ``auto`` (what users get: the native core where it
applies, and for CAN input that no native reader takes, a natively decoded session)."""

from __future__ import annotations

from collections.abc import Iterator

import orjson
import pytest
from e2e_checks import Decoded, Prefetch, Ran, eg2scope, eg2scope_runs, skip_unless_native
from e2e_inputs import IDS

# the native core reads candump -L logs and raw dumps; --engine native refuses the rest as a
# usage error that says why (README, "The native core")
NATIVE_READS = {"serial-dump", "modbus-dump", "candump"}


@pytest.mark.parametrize("kind", IDS)
def test_decode_python(kind: str, reference) -> None:
    decoded = reference.decoded(kind)  # exit 0 is asserted there
    assert decoded.records, "no records"
    assert all(r["seq"] is not None for r in decoded.records)


@pytest.fixture(scope="module")
def decodes(request, inputs, tmp_path_factory) -> Iterator[Prefetch[Ran]]:
    def argv(kind: str, engine: str) -> list[str]:
        return ["decode", str(inputs[kind]), "--format", "jsonl", "--engine", engine]

    with eg2scope_runs(request, test_decode_on_each_engine, tmp_path_factory, argv) as runs:
        yield runs


@pytest.mark.parametrize("engine", ["native", "auto"])
@pytest.mark.parametrize("kind", IDS)
def test_decode_on_each_engine(kind: str, engine: str, decodes, reference) -> None:
    if engine == "native":
        skip_unless_native()
    proc = decodes(kind=kind, engine=engine).proc
    if engine == "native" and kind not in NATIVE_READS and proc.returncode == 2:
        assert b"--engine native: " in proc.stderr and not proc.stdout  # says why, writes none
        return
    assert proc.returncode == 0, proc.stderr.decode()
    assert Decoded.parse(proc.stdout).records
    assert proc.stdout == reference.decoded(kind).jsonl


def backwards_steps(lines: list[dict]) -> list[tuple[int, float]]:
    """Where the time column runs backwards across buses: (line, by how many seconds). Each
    bus keeps its stream order, so a line is placed at the latest time its bus has reached
    (a bus's own frames finished at the stop, after its ``closed`` event, stay after it)."""
    out: list[tuple[int, float]] = []
    reached: dict[str, float] = {}
    last = None
    for i, line in enumerate(lines):
        if line["t"] is None:
            continue
        t = reached[line["bus"]] = max(line["t"], reached.get(line["bus"], line["t"]))
        if last is not None and t < last:
            out.append((i, last - t))
        last = t if last is None else max(last, t)
    return out


@pytest.mark.parametrize("kind", IDS)
def test_decode_is_in_capture_time_order(kind: str, reference) -> None:
    """Records and events come in capture-time order across buses (a serial frame finished
    after CAN frames captured meanwhile is put back in its place), each bus in its stream
    order: the time column never runs backwards (docs/contracts.md)."""
    decoded = reference.decoded(kind)
    lines = [orjson.loads(line) for line in decoded.jsonl.splitlines()]
    assert backwards_steps(lines) == []
    first_rows = {r["bus"] for r in decoded.records[:50]}
    assert first_rows == set(decoded.by_bus())  # every bus begins at its own time


def test_replay_at_speed_is_in_capture_time_order(inputs, reference) -> None:
    path = inputs["mixed-recording"]
    proc = eg2scope("decode", str(path), "-f", "jsonl", "--speed", "10", cwd=path.parent)
    assert proc.returncode == 0, proc.stderr.decode()
    lines = [orjson.loads(line) for line in proc.stdout.splitlines()]
    assert backwards_steps(lines) == []
    records = [x for x in lines if x["kind"] != "event"]
    assert records == reference.decoded("mixed-recording").records


@pytest.mark.parametrize("command", ["decode", "stats"])
def test_protocol_on_a_recording_is_a_usage_error(command: str, inputs) -> None:
    """A recording says each serial bus's protocol: --protocol would decode it as another."""
    path = inputs["mixed-recording"]
    proc = eg2scope(command, str(path), "--protocol", "modbus", cwd=path.parent)
    assert proc.returncode == 2 and not proc.stdout
    err = proc.stderr.decode()
    assert "rs232: serial, rs485: modbus" in err and "--protocol modbus" in err


def test_one_bus_name_for_a_recording_of_several_is_a_usage_error(inputs) -> None:
    path = inputs["mixed-recording"]
    proc = eg2scope("decode", str(path), "--bus", "foo", cwd=path.parent)
    assert proc.returncode == 2 and not proc.stdout
    assert b"recording of 3 buses (can0, rs232, rs485)" in proc.stderr
