"""The rate of each bus of a live TUI session (its bus load's measure), from its taps; no
Textual here (``launch`` imports it before the app is asked for)."""

from __future__ import annotations

from dataclasses import replace

from ..health.rates import BusRates, rates_of_capture
from ..live_runner import metadata
from ..sources.live import Tap
from ..sources.naming import BUS_BY_PROTOCOL


def live_rates(taps: list[Tap]) -> BusRates:
    """Each live bus's rate as its tap was opened at (what a recording of the taps would say);
    a serial tap named later by its protocol (rs232 or rs485) has no name yet: the only such
    tap lends its baud to both names."""
    rates = rates_of_capture(metadata(taps))
    bauds = {t.settings.get("baudrate") for t in taps if t.named_by_protocol}
    baud = bauds.pop() if len(bauds) == 1 else None
    if not isinstance(baud, int):
        return rates
    return replace(rates, known={**dict.fromkeys(BUS_BY_PROTOCOL.values(), baud), **rates.known})
