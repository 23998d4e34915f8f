"""Helpers of the scenario tests: record a scenario on the three simulated buses with a real
``eg2scope record --demo --scenario`` process, decode the recording with a real ``eg2scope
decode`` process, and read the gripper's state, opening and faults out of the decoded records.

Every scenario is recorded once per test module, three at a time, the first time one is needed
(each is a few seconds of a mostly idle process).
"""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
EG2SCOPE = [sys.executable, "-m", "analyzer"]
TIME_SCALE = 4.0  # the jaw 4x faster: a grip and its release in well under a second
DURATION_S = {"tour": 6.0, "bus-off": 3.0}  # each recording's --duration
DEFAULT_DURATION_S = 2.5
AT_ONCE = 3  # recordings made at the same time
BUS_OF = {"serial": "rs232", "modbus": "rs485", "can": "can0"}  # the demo's bus names

# the motion commands as the decoders name them (Modbus and CAN: a write of the target opening)
SERIAL_MOTIONS = {
    "CMD_MC_MOVE_CATCH_XG",
    "CMD_MC_MOVE_CATCH2_XG",
    "CMD_MC_MOVE_RELEASE",
    "CMD_MC_SEEKPOS",
}
TARGET = "CMD_OPENLEN_SET"
STOPS = {"CMD_MC_MOVE_STOPHERE", "CMD_STOP"}


@dataclass(frozen=True)
class Capture:
    """One scenario's recording, decoded, and the truth the simulator wrote of it."""

    records: list[dict[str, Any]]
    truth: list[dict[str, Any]]
    stderr: str

    def on(self, bus: str) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
        """The decoded frames and the truth of one bus (serial, modbus or can)."""
        name = BUS_OF[bus]
        frames = [r for r in self.records if r.get("bus") == name and "summary" in r]
        return frames, [t for t in self.truth if t["protocol"] == bus]


@dataclass(frozen=True)
class Reading:
    """What one poll's answer said (on CAN, with the other read's latest values)."""

    t: float
    state: int | None
    opening: int
    fault: int


def record_argv(name: str, folder: Path, buses: str | None = None) -> list[str]:
    duration = DURATION_S.get(name, DEFAULT_DURATION_S)
    mcap, truth = folder / f"{name}.mcap", folder / f"{name}.truth.jsonl"
    only = [] if buses is None else ["--buses", buses]
    scale = ["--time-scale", str(TIME_SCALE), "--duration", str(duration)]
    return [*EG2SCOPE, "record", "--demo", *only, "--scenario", name, *scale,
            "-o", str(mcap), "--truth", str(truth)]  # fmt: skip


def record_scenarios(names: list[str], folder: Path, buses: str | None = None) -> dict[str, str]:
    """Record the scenarios into ``folder`` (``NAME.mcap``, ``NAME.truth.jsonl``) a few at a
    time (a loaded machine delays the simulated answers); each one's stderr by name. ``buses``:
    the demo's ``--buses`` (default all three)."""
    errors: dict[str, str] = {}
    for first in range(0, len(names), AT_ONCE):
        batch = {n: _start(record_argv(n, folder, buses)) for n in names[first : first + AT_ONCE]}
        errors |= {n: _finish(p, f"record {n}") for n, p in batch.items()}
    return errors


def read_truth(folder: Path, name: str) -> list[dict[str, Any]]:
    truth = (folder / f"{name}.truth.jsonl").read_text().splitlines()
    return [json.loads(line) for line in truth]


def record_all(names: list[str], folder: Path) -> dict[str, Capture]:
    """Record the scenarios, then decode every recording at once."""
    errors = record_scenarios(names, folder)
    decoders = {
        n: _start([*EG2SCOPE, "decode", str(folder / f"{n}.mcap"), "--format", "jsonl"])
        for n in names
    }
    out: dict[str, Capture] = {}
    for name, proc in decoders.items():
        stdout, stderr = proc.communicate(timeout=60)
        assert proc.returncode in (0, 3), f"decode {name}: {proc.returncode} {stderr}"
        records = [json.loads(line) for line in stdout.splitlines()]
        out[name] = Capture(records, read_truth(folder, name), errors[name])
    return out


def _start(argv: list[str]) -> subprocess.Popen[str]:
    return subprocess.Popen(
        argv, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def _finish(proc: subprocess.Popen[str], what: str) -> str:
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 0, f"{what}: exit {proc.returncode}\n{stderr}"
    return stderr


def within(frames: list[dict[str, Any]], step: dict[str, Any]) -> list[dict[str, Any]]:
    """The frames between a step's command and its end."""
    return [r for r in frames if step["start_t"] <= r["t"] <= step["end_t"]]


def readings(frames: list[dict[str, Any]]) -> list[Reading]:
    """The gripper's state, opening and fault, poll by poll: one reading per answer that
    carries the opening (on CAN the read of force and opening, which follows the read of fault
    and state in each poll)."""
    out: list[Reading] = []
    known: dict[str, Any] = {}
    for r in frames:
        if r.get("direction") != "response":
            continue
        fields: dict[str, Any] = r.get("fields") or {}
        values = fields.get("values")
        values = values if isinstance(values, dict) else fields
        found = {
            "state": values.get("CMD_STATUS", fields.get("state")),
            "opening": values.get("CMD_OPENLEN_ACT", fields.get("position")),
            "fault": values.get("CMD_ERRORCODE", fields.get("fault")),
        }
        known.update({k: v for k, v in found.items() if isinstance(v, int)})
        if isinstance(found["opening"], int):
            out.append(Reading(r["t"], known.get("state"), found["opening"], known.get("fault", 0)))
    return out


def is_motion(r: dict[str, Any]) -> bool:
    """A motion command: catch, continuous catch, release, seek, or a write of the target."""
    if r.get("direction") != "request":
        return False
    fields = r.get("fields") or {}
    if fields.get("op") == "read":
        return False
    registers = fields.get("registers") or [fields.get("name")]
    name = r.get("name") or ""
    if name in SERIAL_MOTIONS:
        return True
    start, count = fields.get("start"), fields.get("count")
    if isinstance(start, int) and isinstance(count, int) and start <= 1010 < start + count:
        return fields.get("function") == 16  # a Modbus write of several registers
    return TARGET in registers
