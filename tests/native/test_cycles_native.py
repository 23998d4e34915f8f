"""The native engine's grip cycles (``_native.CycleSegmenter``, native/src/cycles/) against the
Python ``Segmenter``, the reference: the same CAN items through real sessions on both engines,
in batches of several sizes (a command and its readings fall in different batches), must give
equal cycles. The inputs: random hosts written by cycle_script (every command kind, broadcasts,
stops, unanswered writes, faults, readings of any subset of state, opening and force, several
grippers), the benchmark's realistic and rule-breaking traffic, and two buses with foreign,
error, remote and untimed frames."""

from __future__ import annotations

import random
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import pytest
from native_core import needs_native

from analyzer.cycles.listener import CyclesListener
from analyzer.cycles.model import Cycle, CycleCounts, counts_of
from analyzer.cycles.outputs import CycleOutput
from analyzer.model import Item
from analyzer.session.capture import FilteredListener
from analyzer.session.listener import Listener
from analyzer.session.session import Session, SessionOptions
from decoders.model import EG2_CAN, CanFrame

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests" / "benchmarks"))
sys.path.insert(0, str(ROOT / "tests" / "cycles"))
from cycle_script import BROADCAST, Kept, Replay, Script, replay  # noqa: E402
from traffic import can_frames, warning_can_frames  # noqa: E402

pytestmark = needs_native
SIZES = (1, 7, 64, 2000)


def random_host(seed: int, steps: int = 400) -> list[Item]:
    """A host that commands and polls three grippers (and all of them at once) at random."""
    rng = random.Random(seed)
    s = Script(EG2_CAN)
    for _ in range(steps):
        device = rng.choice((1, 2, 3, 1, 2, 3, BROADCAST[EG2_CAN]))
        answer = rng.choice(("ok", "ok", "ok", "none"))
        roll = rng.random()
        if roll < 0.08:
            s.catch(device, answer)
        elif roll < 0.14:
            s.release(device, answer)
        elif roll < 0.2:
            s.seek(rng.choice((0, 300, 500, 700, 1000, rng.randint(0, 1000))), device, answer)
        elif roll < 0.23:
            s.stop(device, answer)
        elif roll < 0.25:
            s.wait(rng.choice((0.0, 0.5, 2.0)))
        else:
            s.poll(
                device=min(device, 3),
                state=rng.choice((None, 1, 2, 3, 4, 5, 6, 6, 4)),
                opening=rng.choice((None, 0, 1000, rng.randint(0, 1000), rng.randint(290, 310))),
                force=rng.choice((None, 0, 40, 60, 100)),
                fault=rng.choice((0,) * 30 + (4, 1)),
            )
    return s.items()


def bench(frames: list[CanFrame]) -> list[Item]:
    return [Item("can0", f) for f in frames]


def on_two_buses(frames: Iterable[CanFrame], seed: int, nan: bool = False) -> list[Item]:
    """``frames`` on two buses, with the frames real buses also carry (foreign and standard
    ids, error and remote frames, lost replies, frames without a time; with ``nan``, some
    with NaN for a time)."""
    rng = random.Random(seed)
    items = []
    for k, f in enumerate(frames):
        roll = rng.random()
        if roll < 0.02:
            continue
        if roll < 0.03:
            f = CanFrame(f.t, 0x123, b"\x01\x02", False)
        elif roll < 0.04:
            f = CanFrame(f.t, 0x20000004, bytes(8), is_error=True)
        elif roll < 0.05:
            f = CanFrame(f.t, f.arbitration_id, b"", is_remote=True, dlc=4)
        elif roll < 0.06:
            f = CanFrame(None, f.arbitration_id, f.data)
        elif nan and roll < 0.065:
            f = CanFrame(float("nan"), f.arbitration_id, f.data)
        items.append(Item("can0" if k % 5 else "can1", f))
    return items


def two_buses(n: int) -> list[Item]:
    """Polls on two buses with the frames real buses also carry."""
    return on_two_buses(can_frames(n, seed=5), seed=5)


INPUTS = {
    **{f"random-host-{seed}": (lambda seed=seed: random_host(seed)) for seed in range(6)},
    "bench": lambda: bench(list(can_frames(20_000))),
    "bench-warnings": lambda: bench(list(warning_can_frames(20_000))),
    "two-buses": lambda: two_buses(20_000),
}


@pytest.mark.parametrize("name", list(INPUTS))
def test_native_cycles_equal_the_python_ones(name: str) -> None:
    items = INPUTS[name]()
    reference = replay(items, EG2_CAN, "python", size=500)
    assert reference, "an input without cycles compares nothing"
    for size in SIZES:
        found = replay(items, EG2_CAN, "native", size=size)
        assert [c.to_dict() for c in found] == [c.to_dict() for c in reference], size


def test_the_random_hosts_reach_every_outcome() -> None:
    """The random hosts are worth comparing: between them they decide every outcome a CAN
    host can cause (no refusal exists on CAN)."""
    outcomes = {
        c.outcome for seed in range(6) for c in replay(random_host(seed), EG2_CAN, "python", 500)
    }
    assert outcomes >= {
        "gripped", "closed_empty", "opened", "positioned", "stopped", "faulted", "unanswered",
        "unfinished", "unknown",
    }  # fmt: skip


class WholeStates(Listener):
    """A listener of whole states, beside the cycles: the tracker makes samples for it."""

    wants_states = True

    def __init__(self) -> None:
        self.samples = 0

    def on_records(self, records: object) -> None:
        pass

    def on_states(self, samples: Any) -> None:
        self.samples += len(samples)


def native_session(items: list[Item], listeners: list[Listener]) -> Session:
    session = Session(Replay(items, "can", 64), listeners, SessionOptions(engine="native"))
    session.run()
    return session


def test_the_native_segmenter_reads_the_tracker_not_samples() -> None:
    """On the native engine the segmenter reads the session's tracker itself: cycles alone
    make no state sample, and give the Python engine's cycles."""
    items = bench(list(can_frames(5000)))
    reference = [c.to_dict() for c in replay(items, EG2_CAN, "python", 500)]
    kept = Kept()
    session = native_session(items, [CyclesListener(kept)])
    assert session.counts.samples == 0
    assert [c.to_dict() for c in kept.cycles] == reference


def test_the_native_segmenter_beside_a_listener_of_samples() -> None:
    """With a listener of whole states beside them, the samples are made for it alone and the
    cycles stay the same."""
    items = bench(list(can_frames(5000)))
    reference = [c.to_dict() for c in replay(items, EG2_CAN, "python", 500)]
    kept, whole = Kept(), WholeStates()
    session = native_session(items, [whole, CyclesListener(kept)])
    assert whole.samples == session.counts.samples > 0
    assert [c.to_dict() for c in kept.cycles] == reference


def test_cycles_behind_a_filter_read_the_native_samples() -> None:
    """A cycles listener the session cannot hand its tracker (behind a filter) reads the native
    samples with the Python segmenter: the same cycles."""
    items = bench(list(can_frames(5000)))
    reference = [c.to_dict() for c in replay(items, EG2_CAN, "python", 500)]
    kept = Kept()
    inner = CyclesListener(kept)
    session = native_session(items, [FilteredListener(inner, lambda r: list(range(len(r))))])
    assert session.counts.samples > 0 and inner.native is None
    assert [c.to_dict() for c in kept.cycles] == reference


class Counted(CycleOutput):
    """An output that only counts (as ``stats``' does): the native segmenter hands it counts."""

    counts_only = True

    def __init__(self) -> None:
        self.found: dict[tuple[str, int], tuple[list[str], list[float], list[float]]] = {}

    def write(self, cycles: list[Cycle]) -> None:
        self.write_counts(counts_of(cycles))

    def write_counts(self, counts: list[CycleCounts]) -> None:
        for bus, device, outcomes, durations, settles in counts:
            mine = self.found.setdefault((bus, device), ([], [], []))
            for kept, more in zip(mine, (outcomes, durations, settles), strict=True):
                kept += more


@pytest.mark.parametrize("name", ["random-host-0", "random-host-3", "bench", "two-buses"])
@pytest.mark.parametrize("device", [None, 2])
def test_native_counts_equal_the_python_cycles_counted(name: str, device: int | None) -> None:
    """An output that only counts gets from the native segmenter, in any batch size, what
    ``counts_of`` counts of the Python engine's cycles (and of one gripper's, with a device);
    no ``Cycle`` is made for it."""
    items = INPUTS[name]()
    reference = [c for c in replay(items, EG2_CAN, "python", 500) if device in (None, c.device)]
    expected = {(bus, dev): rest for bus, dev, *rest in counts_of(reference)}
    assert all(outcomes and durations for outcomes, durations, _ in expected.values())
    for size in (1, 64, 2000):
        counted = Counted()
        listener = CyclesListener(counted, device)
        Session(Replay(items, "can", size), [listener], SessionOptions(engine="native")).run()
        assert listener.native is not None and listener.count == len(reference)
        assert {key: list(found) for key, found in counted.found.items()} == expected, size
