"""Statistics as a listener: what ``eg2scope stats`` prints, gathered in constant memory."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..model import SourceEvent
from ..session.listener import Listener
from ..stats import CaptureStats

if TYPE_CHECKING:
    from ..session.batches import RecordSequence


class StatsListener(Listener):
    def __init__(self) -> None:
        self.stats = CaptureStats()
        self.label = "statistics"

    def on_records(self, records: RecordSequence) -> None:
        self.stats.add_groups(records.stats_groups())

    def on_event(self, event: SourceEvent) -> None:
        self.stats.add_event(event)
