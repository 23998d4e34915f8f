"""The hand-over from capture threads to the session (``TapQueue``): nothing lost or reordered
between threads, bounded, the consumer woken as soon as something arrives and never kept
longer than its timeout when nothing does."""

from __future__ import annotations

import threading
import time

import pytest

from analyzer.model import Item
from analyzer.sources.live import TapQueue
from decoders.model import Chunk


def item(producer: int, n: int) -> Item:
    return Item(f"bus{producer}", Chunk(n.to_bytes(4, "little"), float(n)))


@pytest.mark.parametrize("producers", [1, 2, 4])
def test_concurrent_producers_lose_nothing_and_keep_their_order(producers: int) -> None:
    q = TapQueue(maxsize=10**6)
    per_producer = 20_000
    threads = [
        threading.Thread(target=lambda p=p: [q.put(item(p, n)) for n in range(per_producer)])
        for p in range(producers)
    ]
    got: list[Item] = []
    for t in threads:
        t.start()
    deadline = time.monotonic() + 30
    while len(got) < producers * per_producer and time.monotonic() < deadline:
        got += q.get_batch(0.05, max_items=997)  # odd batches: boundaries fall anywhere
    for t in threads:
        t.join()
    assert q.dropped == 0
    for p in range(producers):
        mine = [x.payload.t for x in got if x.bus == f"bus{p}"]
        assert mine == [float(n) for n in range(per_producer)]


@pytest.mark.parametrize(("maxsize", "puts"), [(1, 5), (10, 10), (10, 500), (1000, 999)])
def test_a_full_queue_drops_and_counts(maxsize: int, puts: int) -> None:
    q = TapQueue(maxsize)
    for n in range(puts):
        q.put(item(0, n))
    got = q.get_batch(0.0, max_items=10**9)
    kept = min(maxsize, puts)
    assert [x.payload.t for x in got] == [float(n) for n in range(kept)]  # the first ones
    assert q.dropped == puts - kept
    assert q.new_drops() == puts - kept
    assert q.new_drops() == 0  # reported once


def test_a_waiting_consumer_wakes_when_an_item_arrives() -> None:
    q = TapQueue()
    threading.Timer(0.2, q.put, args=(item(0, 1),)).start()
    start = time.monotonic()
    got = q.get_batch(timeout=10.0)
    waited = time.monotonic() - start
    assert [x.payload.t for x in got] == [1.0]
    assert 0.15 < waited < 2.0  # woken by the put, long before the timeout


@pytest.mark.parametrize("timeout", [0.0, 0.05, 0.3])
def test_an_empty_queue_returns_nothing_after_the_timeout(timeout: float) -> None:
    q = TapQueue()
    start = time.monotonic()
    assert q.get_batch(timeout) == []
    waited = time.monotonic() - start
    assert timeout * 0.9 <= waited < timeout + 1.0


def test_max_items_leaves_the_rest_in_order() -> None:
    q = TapQueue()
    for n in range(25):
        q.put(item(0, n))
    batches = [q.get_batch(0.0, max_items=10) for _ in range(4)]
    assert [len(b) for b in batches] == [10, 10, 5, 0]
    assert [x.payload.t for b in batches for x in b] == [float(n) for n in range(25)]
