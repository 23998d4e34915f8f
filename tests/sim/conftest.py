"""Fixtures of the simulator tests: a pty line with a gripper drop and a host drop."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import serial

from analyzer.sim.ptybus import PtyBus


@pytest.fixture
def line() -> Iterator[PtyBus]:
    """A pty bus with a 'gripper' drop and a 'host' drop."""
    with PtyBus(["gripper", "host"]) as bus:
        yield bus


@pytest.fixture
def host_port(line: PtyBus) -> Iterator[serial.Serial]:
    port = serial.Serial(line.path("host"), 115200, timeout=1.0)
    yield port
    port.close()
