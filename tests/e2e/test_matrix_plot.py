"""``eg2scope plot CAPTURE --save x.rrd`` on every input kind, read back: each gripper's
opening samples are the readings a Python-engine session tracks from decode's records (same
frames, same millimetres), its grip cycles lane and log hold the cycles ``cycles`` finds, each
bus's health second by second adds up to what ``stats`` reports, and every view of the saved
blueprint shows data. As a real process (its default engine; a few at a time), and in this
process on each session engine; and the live demo plotted beside its own recording."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import orjson
import pytest
from e2e_checks import (
    GIVEN_RATES,
    RATES_KINDS,
    Prefetch,
    Ran,
    Rrd,
    check_given_rates,
    eg2scope,
    eg2scope_runs,
    empty_views,
    force_session_engine,
    opening_series,
    plotted_series,
    read_rrd,
    recorded_openings,
    skip_unless_native,
)
from e2e_inputs import IDS, LIVE_PLOT, NATIVE_IDS
from plot_checks import check_bus_health, check_cycles

from analyzer.cli import main

SESSION_CELLS = [(k, "python") for k in IDS] + [(k, "native") for k in NATIVE_IDS]


def check_plot(rrd_path: Path, kind: str, reference) -> None:
    expected = opening_series(reference.samples(kind))
    decoded = {(r["bus"], r["seq"]) for r in reference.decoded(kind).records}
    for entity, rows in expected.items():
        bus = entity.split("/")[1]
        assert {(bus, seq) for seq, _ in rows} <= decoded  # readings of decoded records
    rrd = read_rrd(rrd_path)
    check_rrd(rrd, expected)
    check_cycles_and_health(rrd, reference.cycles(kind), reference.stats(kind))


def check_cycles_and_health(rrd: Rrd, cycles: list, stats: dict, live: bool = False) -> None:
    """The cycles ``cycles`` finds, on their lanes and logs; each timed bus's seconds adding up
    to ``stats``' figures (a raw dump has no time: no health rows). ``live``: a live plot
    against its recording (``plot_checks.check_cycles``; a serial frame within 10 ms)."""
    assert cycles, "the input has grip cycles"
    check_cycles(rrd, cycles, 10_000_000 if live else 0, live)
    timed = [b for b in stats["buses"] if b["timing"] is None]
    for figures in timed:
        check_bus_health(rrd, figures)
    assert not any("/health/load_pct" in p for p in rrd.entities) or timed


def check_rrd(rrd: Rrd, expected: dict[str, list[tuple[int, float]]]) -> None:
    """Every gripper's opening samples are ``expected`` (frame, mm); every view has data."""
    assert expected, "the input has opening readings"
    for entity, rows in expected.items():
        assert plotted_series(rrd, entity) == [(seq, pytest.approx(mm)) for seq, mm in rows], entity
    empty = empty_views(rrd)
    assert not empty, f"{len(empty)} views without data: {'; '.join(empty)}"


@pytest.fixture(scope="module")
def plots(request, inputs, tmp_path_factory) -> Iterator[Prefetch[Ran]]:
    def argv(kind: str) -> list[str]:
        return ["plot", str(inputs[kind]), "--save", "plot.rrd", "--no-progress"]

    with eg2scope_runs(request, test_plot_process, tmp_path_factory, argv) as runs:
        yield runs


@pytest.mark.parametrize("kind", IDS)
def test_plot_process(kind: str, plots, reference) -> None:
    ran = plots(kind=kind)
    assert ran.proc.returncode == 0, ran.proc.stderr.decode()
    check_plot(ran.cwd / "plot.rrd", kind, reference)


@pytest.mark.parametrize(("kind", "engine"), SESSION_CELLS)
def test_plot_on_each_engine(kind: str, engine: str, inputs, reference, tmp_path, monkeypatch):
    if engine == "native":
        skip_unless_native()
    force_session_engine(monkeypatch, engine)
    out = tmp_path / "plot.rrd"
    assert main(["plot", str(inputs[kind]), "--save", str(out), "--no-progress"]) == 0
    check_plot(out, kind, reference)


@pytest.mark.parametrize("kind", RATES_KINDS)
def test_plot_at_the_rates_given(kind: str, inputs, tmp_path) -> None:
    """``plot PATH -b 1000000 --baud 9600``: each bus's seconds add up to ``stats``' figures at
    the same options, which count every bus at the rate given."""
    out = tmp_path / "plot.rrd"
    assert main(["plot", str(inputs[kind]), "--save", str(out), "--no-progress", *GIVEN_RATES]) == 0
    stats = eg2scope("stats", str(inputs[kind]), "--format", "json", *GIVEN_RATES, cwd=tmp_path)
    assert stats.returncode == 0, stats.stderr.decode()
    buses = orjson.loads(stats.stdout)["buses"]
    check_given_rates(buses)
    rrd = read_rrd(out)
    for figures in buses:
        check_bus_health(rrd, figures)


def test_plot_live_demo_beside_its_recording(inputs, reference) -> None:
    """``record --demo --rerun live.rrd``: the live plot holds every opening reading the
    session's recording holds on ``/state``, the grip cycles and bus health its replay gives
    (the live session numbers its records its own way, and times a serial frame within 10 ms
    of its replay: mostly one byte time apart)."""
    mcap = inputs[LIVE_PLOT.id]
    rrd = read_rrd(mcap.with_suffix(".rrd"))
    check_rrd(rrd, recorded_openings(mcap))
    cycles, stats = reference.cycles(LIVE_PLOT.id), reference.stats(LIVE_PLOT.id)
    check_cycles_and_health(rrd, cycles, stats, live=True)
