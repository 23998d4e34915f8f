"""The TUI's bus health: ``HealthFeed`` is the session's ``HealthListener`` (its second-by-second
rows, ``take_seconds``) that posts each bus's completed seconds to the app in batches
(``HealthUpdate``, at most every ``POST_INTERVAL_S``), on the session's thread, and at the end
every bus's figures over the whole session (``buses()``, what ``stats --format json`` says).
Nothing is counted here: the health package counts (one home for the figures)."""

from __future__ import annotations

import time
from typing import Any

from ..health.listener import HealthListener
from ..health.rates import BusRates
from .feed import POST_INTERVAL_S, Poster
from .messages import HealthUpdate


class HealthFeed(HealthListener):
    """See the module doc. ``target``: where the updates go (the app)."""

    def __init__(self, rates: BusRates | None = None) -> None:
        super().__init__(rates, seconds=True)
        self.label = "the TUI's health line"
        self.target: Poster | None = None
        self._untimed: set[str] = set()
        self._next_post = 0.0

    def tick(self, now: float) -> None:
        if time.monotonic() >= self._next_post:
            self._post(self.take_seconds())

    def close(self) -> None:
        super().close()
        self._post(self.take_seconds(final=True), whole=self.buses())

    def untimed(self) -> set[str]:
        """The buses whose frames have no times: no load or rate can be said of them."""
        every: list[Any] = [*self.can.values(), *self.serial.values()]
        return {health.bus for health in every if health.timing is not None}

    def _post(self, seconds: list[Any], whole: list[dict[str, Any]] | None = None) -> None:
        self._next_post = time.monotonic() + POST_INTERVAL_S
        untimed = self.untimed()
        if not (seconds or whole is not None or untimed != self._untimed):
            return
        self._untimed = untimed
        if self.target is not None:
            self.target.post_message(HealthUpdate(seconds, untimed, whole))
