"""``stats.LatencyHistogram``: ``add_many`` (a batch at once, as the cycle statistics add
their times) counts exactly what ``add`` one value at a time counts."""

from __future__ import annotations

import random

from analyzer.stats import LatencyHistogram


def test_add_many_equals_add_one_by_one() -> None:
    rng = random.Random(3)
    values = [0.0, 1e-9, 0.5, 1.0, 1.0, 250.0, *(rng.uniform(0, 5000) for _ in range(500))]
    one, many = LatencyHistogram(), LatencyHistogram()
    for ms in values:
        one.add(ms)
    many.add_many(values[:7])
    many.add_many(values[7:])
    many.add_many([])
    assert (many.count, many.max, many.buckets) == (one.count, one.max, one.buckets)
    assert many.summary() == one.summary()
