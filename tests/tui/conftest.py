"""Fixtures of the TUI tests: the real app on the simulated buses (real ptys and python-can's
virtual bus) or on a capture file, driven by Textual's Pilot."""

from __future__ import annotations

import argparse
import os
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import pytest

os.environ["TEXTUAL_ANIMATIONS"] = "none"

from analyzer.commands.common import CaptureOptions, byte_protocol, open_reader
from analyzer.commands.tui import live_plan
from analyzer.session import Session, SessionOptions
from analyzer.tui.app import Eg2ScopeApp, SessionPlan
from analyzer.tui.replay import ReplaySource

CAPTURES = Path(__file__).resolve().parents[2] / "captures"
SIZE = (200, 50)


def live_args(output: str | None = None, freeze_on: str | None = None) -> argparse.Namespace:
    return argparse.Namespace(
        protocol="auto", output=output, duration=None, queue_size=200_000, freeze_on=freeze_on
    )


def demo_app(rig, output: str | None = None, freeze_on: str | None = None) -> Eg2ScopeApp:
    return Eg2ScopeApp(
        live_plan(live_args(output, freeze_on), rig.taps, rig.protocols, rig.run_hosts)
    )


def capture_app(path: Path, speed: float | None = None) -> Eg2ScopeApp:
    opts = CaptureOptions(str(path), speed=speed, progress=False)
    reader = open_reader(opts)
    source = ReplaySource(reader, speed)

    def build(feed) -> Session:
        return Session(source, [feed], SessionOptions(protocol=byte_protocol(opts)))

    return Eg2ScopeApp(SessionPlan(build, live=False, replay=source, title=path.name))


@asynccontextmanager
async def driving(app: Eg2ScopeApp) -> AsyncIterator[Any]:
    """``app.run_test`` that always stops the session, even when the test fails inside."""
    try:
        async with app.run_test(size=SIZE) as pilot:
            yield pilot
    finally:
        if app.session is not None:
            app.session.stop()


async def until(pilot, condition: Callable[[], bool], timeout: float = 15.0) -> None:
    """Let the app run until ``condition()`` holds (fails after ``timeout`` seconds)."""
    waited = 0.0
    while not condition():
        if waited >= timeout:
            pytest.fail(f"timed out after {timeout} s waiting for {condition}")
        await pilot.pause(0.1)
        waited += 0.1
