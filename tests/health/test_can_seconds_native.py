"""The native ``can_seconds`` against the Python reference (``python_can_seconds``): the same
seconds, bits, times and error frames for Items of every kind of frame, byte chunks among them,
and for a candump log's ``FrameBatch`` read natively."""

from __future__ import annotations

import math
import random
from pathlib import Path

import pytest

from analyzer.health.can_load import python_can_seconds
from analyzer.model import Item
from analyzer.session import engine
from analyzer.sources.capture import open_capture
from decoders.model import CanFrame, Chunk

pytestmark = pytest.mark.usefixtures("native_core")


def random_items(rng: random.Random, n: int) -> list[Item]:
    items = []
    for _ in range(n):
        bus = rng.choice(("can0", "can1", "serial"))
        t = rng.choice((None, math.nan, rng.uniform(-2.0, 5.0), rng.uniform(1e9, 1e9 + 3)))
        if bus == "serial":
            items.append(Item(bus, Chunk(bytes([rng.randrange(256)]), t)))
            continue
        items.append(Item(bus, random_frame(rng, t)))
    return items


def random_frame(rng: random.Random, t: float | None) -> CanFrame:
    extended = rng.random() < 0.7
    aid = rng.randrange(1 << (29 if extended else 11))
    if rng.random() < 0.02:
        aid = 1 << 30  # no frame a controller sends: not counted
    data = bytes(rng.choice((0, 0xFF, rng.randrange(256))) for _ in range(rng.randint(0, 8)))
    kind = rng.random()
    if kind < 0.1:
        return CanFrame(t, rng.randrange(0x200), bytes(8), is_error=True, dlc=8)
    if kind < 0.2:
        return CanFrame(t, aid, b"", extended, is_remote=True, dlc=rng.randint(0, 15))
    if kind < 0.25:
        return CanFrame(t, aid, bytes(rng.randint(9, 64)), extended, is_fd=True)
    if kind < 0.3 and len(data) == 8:
        return CanFrame(t, aid, data, extended, dlc=rng.randint(9, 15))
    return CanFrame(t, aid, data, extended)


def same(a: object, b: object) -> bool:
    """Equal, NaN aside (there is none: a NaN time is no time)."""
    return repr(a) == repr(b)


@pytest.mark.parametrize("seed", range(5))
def test_items_natively_as_in_python(seed: int) -> None:
    items = random_items(random.Random(seed), 3000)
    native = engine._native.can_seconds(items)  # type: ignore[union-attr]
    assert same(native, python_can_seconds(items))
    assert native[2] == sum(1 for x in items if x.bus == "serial")


def test_a_frame_batch_natively_as_its_items_in_python(tmp_path: Path) -> None:
    rng = random.Random(3)
    lines = []
    for i in range(5000):
        t = 1_700_000_000 + i * 0.0007
        aid = rng.randrange(1 << 29)
        data = bytes(rng.randrange(256) for _ in range(rng.randint(0, 8)))
        bus = rng.choice(("can0", "can1"))
        if i % 97 == 0:
            lines.append(f"({t:.6f}) {bus} {0x20000000 | rng.randrange(0x200):08X}#{'00' * 8}")
        else:
            lines.append(f"({t:.6f}) {bus} {aid:08X}#{data.hex()}")
    path = tmp_path / "two.log"
    path.write_text("\n".join(lines) + "\n")
    frames = engine._native.CandumpFrames(str(path))  # type: ignore[union-attr]
    batch = frames.read(10_000)
    with open_capture(str(path)) as reader:
        items = list(reader)
    assert same(engine._native.can_seconds(batch), python_can_seconds(items))  # type: ignore[union-attr]


def test_an_int_time_is_read_in_python() -> None:
    from analyzer.health.can_load import can_seconds

    items = [Item("can0", CanFrame(5, 0x123, b"\x01", False))]  # type: ignore[arg-type]
    assert can_seconds(items) == python_can_seconds(items)
