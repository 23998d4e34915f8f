"""What a demo's taps give, said before the demo starts (``DemoOptions.kind``, so that an
engine that cannot decode it is a usage error before anything opens): the kind its started
rig's taps have (``sources.source.live_kind``), for each choice of buses."""

from __future__ import annotations

import pytest

from analyzer.sim.demo_options import DemoOptions
from analyzer.sim.rig import DemoRig
from analyzer.sources.source import live_kind


@pytest.mark.parametrize(
    ("buses", "kind"),
    [
        (("can",), "can"),
        (("serial",), "bytes"),
        (("serial", "modbus"), "bytes"),
        (("modbus", "can"), "mixed"),
        (("serial", "modbus", "can"), "mixed"),
    ],
)
def test_the_demo_says_what_its_taps_give(buses: tuple[str, ...], kind: str) -> None:
    options = DemoOptions(buses=buses, noise=0.0)
    assert options.kind == kind
    with DemoRig.of(options) as rig:
        assert len(rig.taps) == len(buses)
        assert live_kind(rig.taps) == kind
