"""Replay pacing: items come out at the original timing divided by the speed."""

from __future__ import annotations

import time

import pytest

from analyzer.model import Item
from analyzer.sources.pacing import paced, parse_speed
from decoders.model import CanFrame, Chunk


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0
        self.sleeps: list[float] = []

    def __call__(self) -> float:
        return self.now

    def sleep(self, s: float) -> None:
        self.sleeps.append(s)
        self.now += s


def items(times: list[float | None]) -> list[Item]:
    return [
        Item("can0", CanFrame(t, 1)) if i % 2 else Item("s", Chunk(b"x", t))
        for i, t in enumerate(times)
    ]


def emitted_at(its: list[Item], speed: float | None, **kw: float) -> list[float]:
    clock = FakeClock()
    out = []
    for _item in paced(its, speed, clock=clock, sleep=clock.sleep, **kw):
        out.append(round(clock.now - 100.0, 6))
    return out


def test_original_timing_divided_by_speed() -> None:
    its = items([10.0, 10.5, 11.0, 13.0])
    assert emitted_at(its, 1.0) == [0.0, 0.5, 1.0, 3.0]
    assert emitted_at(its, 10.0) == [0.0, 0.05, 0.1, 0.3]
    assert emitted_at(its, 0.5) == [0.0, 1.0, 2.0, 6.0]


def test_max_speed_never_sleeps() -> None:
    its = items([10.0, 20.0, 30.0])
    for speed in (None, float("inf")):
        assert emitted_at(its, speed) == [0.0, 0.0, 0.0]
        assert list(paced(its, speed)) == its


def test_untimed_items_and_clock_steps_back() -> None:
    assert emitted_at(items([None, 10.0, None, 11.0]), 1.0) == [0.0, 0.0, 0.0, 1.0]
    # the capture clock jumps back 5 s: no wait, then timing resumes from there
    assert emitted_at(items([10.0, 11.0, 6.0, 6.5]), 1.0) == [0.0, 1.0, 1.0, 1.5]


def test_max_gap_skips_idle_time() -> None:
    assert emitted_at(items([0.0, 0.1, 3600.0, 3600.2]), 1.0, max_gap_s=1.0) == [
        0.0,
        0.1,
        1.1,
        1.3,
    ]


def test_slow_consumer_is_not_slowed_further() -> None:
    clock = FakeClock()
    its = items([0.0, 0.1, 0.2, 0.3])
    for _ in paced(its, 1.0, clock=clock, sleep=clock.sleep):
        clock.now += 0.5  # each item takes 0.5 s to handle: always behind
    assert clock.sleeps == []


def test_real_clock_roughly() -> None:
    its = items([0.0, 0.05, 0.1])
    start = time.monotonic()
    assert list(paced(its, 2.0)) == its
    assert 0.04 <= time.monotonic() - start < 0.5


@pytest.mark.parametrize(
    ("text", "speed"),
    [
        ("max", None),
        ("inf", None),
        ("0", None),
        (None, None),
        ("1", 1.0),
        ("10", 10.0),
        ("10x", 10.0),
        ("0.5", 0.5),
        (4, 4.0),
    ],
)
def test_parse_speed(text: str | float | None, speed: float | None) -> None:
    assert parse_speed(text) == speed


@pytest.mark.parametrize("bad", ["fast-ish", "-1", "nan"])
def test_parse_speed_rejects(bad: str) -> None:
    with pytest.raises(ValueError):
        parse_speed(bad)
