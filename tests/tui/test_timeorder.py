"""The TUI's time order across buses (``analyzer.session.timeorder.TimeMerge``) on records the
real decoders make: a serial frame finished after CAN frames captured meanwhile is put back in
its place, a bus still detecting its protocol holds the others, a quiet bus does not, and each
bus keeps its own stream order."""

from __future__ import annotations

import math

from analyzer.model import Item
from analyzer.session.batches import PythonDecoding
from analyzer.session.timeorder import TimeMerge
from decoders import build as b
from decoders.eg2_serial import Cmd
from decoders.model import EG2_SERIAL, Chunk, Record


# responses: no request waits for them, so the decoding hands each over as soon as it is framed
def can_items(times: list[float]) -> list[Item]:
    data = b.u16le(100, 500, 0, 30)
    return [Item("can0", b.can_read_response(1, 1120, data, t=t)) for t in times]


def serial_frame() -> bytes:
    return b.serial_frame(1, Cmd.READ_ACTPOS, b.u16le(500), response=True)


def serial_items(frame_t: float, split: float) -> list[Item]:
    """A position reply whose first bytes came at ``frame_t`` and the rest at ``split``."""
    raw = serial_frame()
    return [Item("rs232", Chunk(raw[:3], frame_t)), Item("rs232", Chunk(raw[3:], split))]


def run(merge: TimeMerge, batches: list[list[Item]]) -> list[Record]:
    """The batches through a real decoding and the merge, as the TUI's feed runs them."""
    decoding = PythonDecoding(per_bus={"rs232": EG2_SERIAL})
    out: list[Record] = []
    for items in batches:
        merge.hear(items)
        out += merge.push(decoding.feed_items(items))
    merge.hear([])
    out += merge.push(decoding.finish())
    return out + merge.flush()


def times(records: list[Record]) -> list[float]:
    return [r.t for r in records if r.t is not None]


def test_a_frame_finished_late_is_put_back_in_time() -> None:
    merge = TimeMerge()
    serial = serial_items(1.000, 1.030)
    batches = [[serial[0]], can_items([1.005, 1.010, 1.020]), [serial[1]], can_items([1.040])]
    out = run(merge, batches)
    assert [r.bus for r in out] == ["rs232", "can0", "can0", "can0", "can0"]
    assert times(out) == sorted(times(out))


def test_records_wait_for_a_bus_heard_but_not_yet_decoded() -> None:
    """The serial bytes came first; until their frame is out, later CAN frames wait."""
    merge = TimeMerge()
    serial = serial_items(2.000, 2.050)
    merge.hear([serial[0]])
    can = can_items([2.010, 2.020])
    merge.hear(can)
    decoding = PythonDecoding(per_bus={"rs232": EG2_SERIAL})
    assert merge.push(decoding.feed_items([serial[0]])) == []
    assert merge.push(decoding.feed_items(can)) == []  # held: the serial frame began first
    merge.hear([serial[1]])
    out = merge.push(decoding.feed_items([serial[1]])) + merge.flush()
    assert [r.bus for r in out] == ["rs232", "can0", "can0"]


def test_a_quiet_bus_holds_nobody_back() -> None:
    merge = TimeMerge(hold_s=2.0)
    decoding = PythonDecoding(per_bus={"rs232": EG2_SERIAL})
    first = [Item("rs232", Chunk(serial_frame(), 10.0))]
    merge.hear(first)
    assert len(merge.push(decoding.feed_items(first))) == 1
    early = can_items([10.5, 11.0])
    merge.hear(early)
    assert merge.push(decoding.feed_items(early)) == []  # the serial line may still talk
    late = can_items([12.5])
    merge.hear(late)
    out = merge.push(decoding.feed_items(late))
    assert [r.t for r in out] == [10.5, 11.0, 12.5]  # quiet for 2 s: it holds nobody


def test_live_sessions_release_by_the_wall_clock() -> None:
    merge = TimeMerge(hold_s=0.3)
    decoding = PythonDecoding(per_bus={"rs232": EG2_SERIAL})
    serial = [Item("rs232", Chunk(serial_frame(), 100.0))]
    can = can_items([100.1])
    merge.hear(serial + can)
    assert len(merge.push(decoding.feed_items(serial + can), now=100.1)) == 1
    assert merge.advance(now=100.2) == []
    assert [r.bus for r in merge.advance(now=100.5)] == ["can0"]


def test_one_bus_is_handed_through_as_it_comes() -> None:
    merge = TimeMerge()
    decoding = PythonDecoding()
    items = can_items([3.0, 2.0, 4.0])  # a clock that steps back stays in stream order
    merge.hear(items)
    records = decoding.feed_items(items)
    assert merge.push(records) is records


def test_each_bus_keeps_its_stream_order_when_its_clock_steps_back() -> None:
    merge = TimeMerge()
    can = can_items([5.0, 4.0, 6.0])
    out = run(merge, [can[:2] + serial_items(4.5, 4.5) + can[2:]])
    assert [(r.bus, r.t) for r in out if r.bus == "can0"] == [
        ("can0", 5.0),
        ("can0", 4.0),
        ("can0", 6.0),
    ]
    assert [r.bus for r in out][:2] == ["rs232", "can0"]


def test_at_most_max_held_records_wait() -> None:
    merge = TimeMerge(max_held=10)
    decoding = PythonDecoding(per_bus={"rs232": EG2_SERIAL})
    serial = serial_items(0.0, math.nextafter(0.0, 1.0))
    merge.hear([serial[0]])
    merge.push(decoding.feed_items([serial[0]]))
    can = can_items([0.001 * k for k in range(1, 31)])
    merge.hear(can)
    out = merge.push(decoding.feed_items(can))
    assert len(out) == 20 and merge.held == 10  # the oldest went, in order
    assert times(out) == sorted(times(out))
