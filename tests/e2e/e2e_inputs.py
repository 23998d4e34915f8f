"""The matrix's rows: every kind of input eg2scope reads, as a table (id, file name, how it is
made, whether it holds CAN frames only), and the folder that makes each once per test session.

The sample captures are copied; the candump log is written again by python-can's own ``.asc``
and ``.blf`` writers; the three recordings are made by real ``eg2scope record --demo`` processes
(all three simulated buses, the CAN bus alone, and the scenario tour: every grip outcome, a
dropped answer, a stall fault, a bus-off). Beside them a fourth process records the
demo live with ``--rerun`` too: the live plot, whose MCAP ``/state`` says what it must hold.
The four run at once, the first time any of them is needed.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import can

ROOT = Path(__file__).resolve().parents[2]
CAPTURES = ROOT / "captures"
EG2SCOPE = [sys.executable, "-m", "analyzer"]
# plot's default target depends on a display; every command here runs as on a headless server
HEADLESS = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
# each one's --duration
RECORD_S = {"mixed.mcap": 4.0, "can.mcap": 3.0, "live.mcap": 3.0, "tour.mcap": 6.0}
SCENARIO_TIME_SCALE = "4"  # the scenario's jaw 4x faster: its every cycle within the recording


def copy_capture(name: str) -> Callable[[Path], None]:
    def make(path: Path) -> None:
        shutil.copyfile(CAPTURES / name, path)

    return make


def rewrite_candump(path: Path) -> None:
    """The candump sample written again by python-can's writer for ``path``'s suffix."""
    with can.Logger(str(path)) as logger:
        for msg in can.LogReader(str(CAPTURES / "can_pick_place.log")):
            logger.on_message_received(msg)


def record_demo(*buses: str) -> Callable[[Path], list[str]]:
    """The ``eg2scope record --demo`` command line that records ``buses`` to a path."""

    def argv(path: Path) -> list[str]:
        duration = str(RECORD_S[path.name])
        return [*EG2SCOPE, "record", "--demo", "--buses", ",".join(buses), "-o", str(path),
                "--duration", duration]  # fmt: skip

    return argv


def record_scenario(name: str) -> Callable[[Path], list[str]]:
    """``record --demo --scenario NAME`` on the three buses: every grip outcome, a dropped
    answer, a stall fault and a bus-off on CAN, with the simulator's truth beside it."""

    def argv(path: Path) -> list[str]:
        truth = str(path.with_suffix(".truth.jsonl"))
        return [*record_demo(*ALL_BUSES)(path), "--scenario", name,
                "--time-scale", SCENARIO_TIME_SCALE, "--truth", truth]  # fmt: skip

    return argv


def record_live_plot(*buses: str) -> Callable[[Path], list[str]]:
    """``record --demo`` that also plots the session live into ``<path>.rrd`` (``--rerun``)."""

    def argv(path: Path) -> list[str]:
        return [*record_demo(*buses)(path), "--rerun", str(path.with_suffix(".rrd"))]

    return argv


@dataclass(frozen=True)
class InputKind:
    """One row of the matrix. ``make`` writes the file; ``record`` instead gives the command
    line of the eg2scope process that records it. ``native``: sessions decode it natively
    where the core is built: CAN frames only, or a raw dump's one byte stream
    (docs/architecture.md)."""

    id: str
    file: str
    native: bool
    make: Callable[[Path], None] | None = None
    record: Callable[[Path], list[str]] | None = None


ALL_BUSES = ("serial", "modbus", "can")
KINDS = (
    InputKind("serial-dump", "serial_session.bin", True, make=copy_capture("serial_session.bin")),
    InputKind("modbus-dump", "modbus_session.bin", True, make=copy_capture("modbus_session.bin")),
    InputKind("candump", "can_pick_place.log", True, make=copy_capture("can_pick_place.log")),
    InputKind("asc", "can_pick_place.asc", True, make=rewrite_candump),
    InputKind("blf", "can_pick_place.blf", True, make=rewrite_candump),
    InputKind("mixed-recording", "mixed.mcap", False, record=record_demo(*ALL_BUSES)),
    InputKind("can-recording", "can.mcap", True, record=record_demo("can")),
    InputKind("scenario-recording", "tour.mcap", False, record=record_scenario("tour")),
)  # fmt: skip
LIVE_DEMO = "live-demo"  # the simulated grippers, live: not a file
LIVE_PLOT = InputKind(LIVE_DEMO, "live.mcap", False, record=record_live_plot(*ALL_BUSES))
BY_ID = {k.id: k for k in (*KINDS, LIVE_PLOT)}
IDS = [k.id for k in KINDS]
NATIVE_IDS = [k.id for k in KINDS if k.native]


class InputFolder:
    """Every input kind in one folder, each made the first time a cell asks for it."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.made: dict[str, Path] = {}

    def __getitem__(self, kind_id: str) -> Path:
        if kind_id not in self.made:
            kind = BY_ID[kind_id]
            if kind.record is not None:
                self._record_all()
            else:
                assert kind.make is not None
                path = self.folder / kind.file
                kind.make(path)
                self.made[kind_id] = path
        return self.made[kind_id]

    def _record_all(self) -> None:
        """Every recording at once (each runs for its --duration of wall time)."""
        wanted = [k for k in BY_ID.values() if k.record is not None and k.id not in self.made]
        procs = []
        for kind in wanted:
            assert kind.record is not None
            path = self.folder / kind.file
            procs.append((kind, path, subprocess.Popen(
                kind.record(path), cwd=self.folder, env=HEADLESS, stdout=subprocess.PIPE,
                stderr=subprocess.PIPE, text=True,
            )))  # fmt: skip
        for kind, path, proc in procs:
            _, err = proc.communicate(timeout=120)
            assert proc.returncode == 0, f"recording {kind.id} failed ({proc.returncode}): {err}"
            self.made[kind.id] = path
