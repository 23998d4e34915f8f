"""The TUI's grip cycles: ``CycleFeed`` is the ``CycleOutput`` the session's ``CyclesListener``
writes to (on the session's thread, each cycle once it has ended); it posts them to the app in
batches (``CyclesUpdate``, at most every ``POST_INTERVAL_S``), never one message per cycle.
The rules are the cycles package's (analyzer/cycles/): nothing here decides an outcome.

``cycle_frames`` finds a cycle's frames in the store: records are known by bus and ``seq``
(a capture numbers each stream's records by their place in it, so two buses may share a
number)."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from ..cycles.listener import CyclesListener
from ..cycles.outputs import CycleOutput
from .feed import POST_INTERVAL_S, Poster
from .messages import CyclesUpdate

if TYPE_CHECKING:
    from ..cycles.model import Cycle
    from .store import RecordStore


class CycleFeed(CycleOutput):
    """See the module doc. ``target``: where the updates go (the app)."""

    label = "the TUI's cycles panel"

    def __init__(self) -> None:
        self.target: Poster | None = None
        self._held: list[Cycle] = []
        self._next_post = 0.0

    def write(self, cycles: list[Cycle]) -> None:
        self._held.extend(cycles)

    def flush(self) -> None:
        """On the session's ticks: post what ended, at most every ``POST_INTERVAL_S``."""
        if self._held and time.monotonic() >= self._next_post:
            self._post()

    def close(self) -> None:
        if self._held:
            self._post()

    def _post(self) -> None:
        self._next_post = time.monotonic() + POST_INTERVAL_S
        cycles, self._held = self._held, []
        if self.target is not None:
            self.target.post_message(CyclesUpdate(cycles))


def cycles_listener() -> tuple[CyclesListener, CycleFeed]:
    """The session's cycles listener for the TUI, and the output it writes to."""
    output = CycleFeed()
    return CyclesListener(output), output


def find_frame(store: RecordStore, bus: str, seq: int) -> int | None:
    """The store index of the record ``seq`` of ``bus`` (None: not stored, or not yet)."""
    bus_id = store.buses.get(bus)
    if bus_id is None:
        return None
    seqs, buses, n = store.seq, store.bus, store.count
    start = 0
    while True:
        try:
            i = seqs.index(seq, start, n)
        except ValueError:
            return None
        if buses[i] == bus_id:
            return i
        start = i + 1


def cycle_frames(store: RecordStore, cycle: Cycle) -> list[int]:
    """The store indices of a cycle's evidence frames (its command first), in store order;
    those not stored (yet) are left out."""
    seqs = dict.fromkeys([cycle.start_seq, *cycle.evidence])
    found = (find_frame(store, cycle.bus, seq) for seq in seqs)
    return sorted(i for i in found if i is not None)
