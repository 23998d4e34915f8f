"""The fleet tables' partition day: the UTC day of a record's time in seconds, as Python's
``datetime.fromtimestamp`` tells it, for times with fractions of a microsecond (what
``record --demo`` and python-can's logs hold), and the capture's day where no calendar holds
the time: none, one before 1991 (a capture's own clock, counting from its start, as candump's
reader tells relative stamps), or one no calendar holds."""

from __future__ import annotations

import datetime as dt
import math
import random

import pyarrow as pa
import pytest

from analyzer.fleet.tables import days
from analyzer.sources.candump import RELATIVE_LIMIT


def python_day(t: float | None, fallback: str) -> str:
    if t is None or not math.isfinite(t) or t < RELATIVE_LIMIT:
        return fallback
    try:
        return dt.datetime.fromtimestamp(t, dt.UTC).strftime("%Y-%m-%d")
    except (OverflowError, ValueError, OSError):
        return fallback


def rows(values: list[float | None]) -> list[str]:
    got = days(pa.chunked_array([values], pa.float64()), "fallback")
    return [got] * len(values) if isinstance(got, str) else got.to_pylist()


def test_times_with_fractions_of_a_microsecond() -> None:
    rng = random.Random(5)
    times = [1_795_729_152.0421715, 1_763_700_000.6065897, 86_399.9999996, 86_399.9999994]
    times += [rng.uniform(-2e9, 4e9) for _ in range(5000)]
    assert rows(times) == [python_day(t, "fallback") for t in times]


def test_one_day_is_told_once() -> None:
    assert days(pa.chunked_array([[1_763_700_000.5, 1_763_700_100.25]]), "x") == "2025-11-21"
    assert days(pa.chunked_array([[None, None]], pa.float64()), "x") == "x"  # raw dumps


@pytest.mark.parametrize(
    "odd",
    [None, math.nan, math.inf, -math.inf, 1e300, -1e300, 253_402_300_800.0, -62_135_596_801.0],
)
def test_no_calendar_holds_it_the_capture_s_day(odd: float | None) -> None:
    assert rows([1_763_700_000.5, odd, 1_763_790_000.0]) == ["2025-11-21", "fallback", "2025-11-22"]


def test_the_last_day_a_calendar_holds() -> None:
    assert rows([253_402_300_799.0, RELATIVE_LIMIT]) == ["9999-12-31", "1991-01-01"]


@pytest.mark.parametrize(
    "relative", [0.0, 0.5, 86_400.25, 5_000_000.0, RELATIVE_LIMIT - 1e-6, -3.0]
)
def test_a_time_counted_from_the_capture_s_start_takes_the_capture_s_day(relative: float) -> None:
    assert rows([relative]) == ["fallback"]  # never 1970-01-01
    assert rows([relative, 1_763_700_000.5]) == ["fallback", "2025-11-21"]
