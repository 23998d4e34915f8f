"""``eg2scope decode --format jsonl`` on every input kind, as a real process, on each engine:
the Python decoders, the native core, and ``auto`` (what users get: the native core where it
applies, and for CAN input that no native reader takes, a natively decoded session)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from e2e_checks import Decoded, Prefetch, Ran, eg2scope_runs, skip_unless_native
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
