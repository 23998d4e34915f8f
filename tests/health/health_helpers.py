"""What the bus-health tests share: ``stats --format json``'s buses from a real process, and
the same from a session in this process on a chosen engine; a candump log written from frames;
the bits of a frame counted the second way (``can_wire``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import orjson
from can_wire import reference_bits
from cli_process import eg2scope

from analyzer.health.listener import HealthListener
from analyzer.health.rates import BusRates
from analyzer.session.capture import CaptureOptions, run_capture
from analyzer.session.session import Session
from decoders.build import candump_line
from decoders.model import CanFrame

ENGINES = ("python", "native")


def cli_buses(path: Path, *options: str) -> list[dict[str, Any]]:
    """``eg2scope stats PATH --format json OPTIONS``'s ``buses``, as a real process."""
    proc = eg2scope("stats", str(path), "--format", "json", *options)
    assert proc.returncode == 0, proc.stderr
    buses: list[dict[str, Any]] = orjson.loads(proc.stdout)["buses"]
    return buses


def session_buses(
    path: Path, engine: str, rates: BusRates | None = None
) -> tuple[list[dict[str, Any]], Session]:
    """The buses of a session over ``path`` on ``engine``, and the session (its source says
    whether the capture was read natively)."""
    health = HealthListener(rates)
    session, _ = run_capture(CaptureOptions(str(path), progress=False, engine=engine), [health])
    return health.buses(), session


def write_candump(path: Path, frames: list[CanFrame]) -> Path:
    path.write_text("".join(candump_line(f) + "\n" for f in frames))
    return path


def wire_bits(frame: CanFrame) -> int:
    """A data or remote frame's bits on the wire, by the second count."""
    data = b"" if frame.is_remote else frame.data
    return reference_bits(frame.arbitration_id, frame.is_extended, frame.is_remote,
                          frame.length, data)  # fmt: skip
