"""The load figures' definitions (docs/contracts.md): the mean over the span, p95 and max over
the seconds the span covers whole, silent seconds at 0 %, a span under a whole second."""

from __future__ import annotations

import pytest

from analyzer.health.figures import Spread, load_pct


def test_whole_seconds_only_and_silent_ones_count() -> None:
    # span 9.5 .. 14.5: whole seconds 10, 11, 12, 13; 12 is silent; 9 and 14 partial
    seconds = {9: 400_000, 10: 100_000, 11: 250_000, 13: 50_000, 14: 400_000}
    got = load_pct(seconds, 9.5, 14.5, sum(seconds.values()), 500_000)
    assert got == {"mean": pytest.approx(48.0), "p95": 50.0, "max": 50.0}
    many = {s: 5_000 * s for s in range(100)}  # 1 % .. 99 %
    got = load_pct(many, 0.0, 100.0, sum(many.values()), 500_000)
    assert (got["p95"], got["max"]) == (94.0, 99.0)


def test_a_span_without_a_whole_second_gives_its_mean() -> None:
    got = load_pct({5: 100_000}, 5.2, 5.7, 100_000, 500_000)
    assert got == {"mean": 40.0, "p95": 40.0, "max": 40.0}
    assert load_pct({}, 5.0, 5.0, 0, 500_000) == {"mean": None, "p95": None, "max": None}


def test_spread() -> None:
    spread = Spread()
    for ms in (1.0, 2.0, 3.0, 4.0, 100.0):
        spread.add(ms)
    spread.add(None)
    got = spread.summary()
    assert (got["count"], got["min"], got["max"], got["unmeasured"]) == (5, 1.0, 100.0, 1)
    assert got["median"] == pytest.approx(3.0, rel=0.01)
    assert Spread().summary()["median"] is None


def test_a_clock_that_jumps_makes_no_second_of_every_second_between() -> None:
    # a stamp a year off: 31.5 million silent seconds, counted, not listed
    seconds = {0: 250_000, 31_536_000: 250_000}
    got = load_pct(seconds, -0.5, 31_536_000.5, 500_000, 500_000)
    assert got["p95"] == 0.0 and got["max"] == 50.0
