"""``stats.LatencyHistogram``: ``add_many`` and ``add_counted`` (a batch at once, as the cycle
statistics and the record groups add their times) count exactly what ``add`` one value at a
time counts, NaN included (never the maximum)."""

from __future__ import annotations

import random
from collections import Counter

from analyzer.stats import LatencyHistogram


def test_add_many_equals_add_one_by_one() -> None:
    rng = random.Random(3)
    values = [float("nan"), 0.0, 1e-9, 0.5, 1.0, 1.0, 250.0, float("nan")]
    values += [round(rng.uniform(0, 5000), rng.choice((0, 1, 3))) for _ in range(500)]
    one, many = LatencyHistogram(), LatencyHistogram()
    for ms in values:
        one.add(ms)
    many.add_many(values[:7])
    many.add_many(values[7:])
    many.add_many([])
    counted = LatencyHistogram()
    counted.add_counted(Counter(values))
    for found in (many, counted):
        assert (found.count, found.max, found.buckets) == (one.count, one.max, one.buckets)
        assert found.summary() == one.summary()
    assert one.max == max(v for v in values if v == v)
