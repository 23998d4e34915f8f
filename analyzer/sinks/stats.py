"""Statistics as a listener: what ``eg2scope stats`` prints, gathered in constant memory."""

from __future__ import annotations

from collections.abc import Sequence

from decoders.model import Record

from ..model import SourceEvent
from ..session.listener import Listener
from ..stats import CaptureStats


class StatsListener(Listener):
    def __init__(self) -> None:
        self.stats = CaptureStats()
        self.label = "statistics"

    def on_records(self, records: Sequence[Record]) -> None:
        add = self.stats.add
        for rec in records:
            add(rec)

    def on_event(self, event: SourceEvent) -> None:
        self.stats.add_event(event)
