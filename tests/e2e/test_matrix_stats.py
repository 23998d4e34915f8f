"""``eg2scope stats --format json`` on every input kind agrees with decode's records: the
command as a real process (its default engine), and in this process on each session engine;
its bus health (``buses``) too, and each engine's is the process's, figure for figure."""

from __future__ import annotations

from collections.abc import Iterator

import orjson
import pytest
from e2e_checks import (
    Prefetch,
    Ran,
    buses_of,
    buses_view,
    eg2scope_runs,
    force_session_engine,
    skip_unless_native,
    stats_of,
    stats_view,
)
from e2e_inputs import IDS, KINDS, NATIVE_IDS

from analyzer.cli import main

SESSION_CELLS = [(k, "python") for k in IDS] + [(k, "native") for k in NATIVE_IDS]
RAW_DUMPS = {k.id for k in KINDS if k.file.endswith(".bin")}  # no times at all


@pytest.fixture(scope="module")
def stats(request, inputs, tmp_path_factory) -> Iterator[Prefetch[Ran]]:
    def argv(kind: str) -> list[str]:
        return ["stats", str(inputs[kind]), "--format", "json"]

    with eg2scope_runs(request, test_stats_process, tmp_path_factory, argv) as runs:
        yield runs


@pytest.mark.parametrize("kind", IDS)
def test_stats_process(kind: str, stats, reference) -> None:
    proc = stats(kind=kind).proc
    assert proc.returncode == 0, proc.stderr.decode()
    data = orjson.loads(proc.stdout)
    assert stats_view(data) == stats_of(reference.decoded(kind))
    assert buses_view(data) == buses_of(reference.decoded(kind), kind not in RAW_DUMPS)


@pytest.mark.parametrize(("kind", "engine"), SESSION_CELLS)
def test_stats_on_each_engine(
    kind: str, engine: str, inputs, reference, stats, monkeypatch, capsys
) -> None:
    if engine == "native":
        skip_unless_native()
    force_session_engine(monkeypatch, engine)
    assert main(["stats", str(inputs[kind]), "--format", "json", "--no-progress"]) == 0
    data = orjson.loads(capsys.readouterr().out)
    assert stats_view(data) == stats_of(reference.decoded(kind))
    assert buses_view(data) == buses_of(reference.decoded(kind), kind not in RAW_DUMPS)
    assert data["buses"] == orjson.loads(stats(kind=kind).proc.stdout)["buses"]
