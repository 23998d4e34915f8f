"""The inputs the Rerun tests plot: the sample captures, the candump capture written again as
python-can .asc and .blf and as an eg2scope .mcap recording, a mixed three-bus recording of the
demo (``eg2scope record --demo``), and two small captures with faults; the engines each can be
decoded with; and a listener that collects what a session decoded."""

from __future__ import annotations

import subprocess
import sys
from functools import cache
from pathlib import Path
from typing import Any

import can

from analyzer.health.listener import HealthListener
from analyzer.model import StateSample
from analyzer.recording.recorder import McapRecorder
from analyzer.session.capture import CaptureOptions, run_capture
from analyzer.session.listener import Listener
from decoders import build as b
from decoders.eg2_serial import Cmd
from decoders.model import Record

ROOT = Path(__file__).resolve().parents[2]
CAPTURES = ROOT / "captures"


class Collector(Listener):
    """What the session decoded, beside the Rerun listener; ``health``: a bus health listener
    to run beside them (what ``stats`` reports of the same capture)."""

    wants_states = True

    def __init__(self) -> None:
        self.records: list[Record] = []
        self.samples: list[StateSample] = []
        self.health = HealthListener()

    def on_records(self, records: list[Record]) -> None:
        self.records += records

    def on_states(self, samples: list[StateSample]) -> None:
        self.samples += samples


# -- inputs ------------------------------------------------------------------------------------


def write_candump(path: Path, frames: list[Any]) -> Path:
    with path.open("w") as f:
        for fr in frames:
            f.write(f"({fr.t:.6f}) can0 {fr.arbitration_id:08X}#{fr.data.hex().upper()}\n")
    return path


def faults_can(tmp: Path) -> Path:
    """Gripper 1 reads fault bits 3 (stall, over-temperature) between clean readings."""
    t0 = 1_763_700_100.0
    frames = [
        b.can_read_request(1, 1128, 4, t=t0),
        b.can_read_response(1, 1128, b.u16le(0, 4), t=t0 + 0.001),
        b.can_read_request(1, 1128, 4, t=t0 + 0.010),
        b.can_read_response(1, 1128, b.u16le(3, 3), t=t0 + 0.011),
        b.can_read_request(1, 1120, 8, t=t0 + 0.020),
        b.can_read_response(1, 1120, b.u16le(480, 300, 150, 41), t=t0 + 0.021),
        b.can_read_request(1, 1128, 4, t=t0 + 3.500),
        b.can_read_response(1, 1128, b.u16le(0, 6), t=t0 + 3.501),
    ]
    return write_candump(tmp / "faults.log", frames)


def faults_serial(tmp: Path) -> Path:
    """Run state with fault bits (the serial decoder flags it), and a catch with a bad sum."""
    s = b.serial_frame
    bad = bytearray(s(1, Cmd.MOVE_CATCH_XG, b.u16le(500, 100)))
    bad[-1] ^= 0xFF
    data = b"".join(
        [
            s(1, Cmd.READ_EG_RUNSTATE),
            s(1, Cmd.READ_EG_RUNSTATE, bytes((3, 0x05, 40)) + b.u16le(300, 100), response=True),
            bytes(bad),
            s(1, Cmd.MOVE_CATCH_XG, b.u16le(500, 100)),
            s(1, Cmd.MOVE_CATCH_XG, b"\x01", response=True),
        ]
    )
    path = tmp / "faults.bin"
    path.write_bytes(data)
    return path


def python_can_copy(tmp: Path, suffix: str) -> Path:
    """The candump capture written again by python-can's own writer for ``suffix``."""
    path = tmp / f"can_pick_place{suffix}"
    with can.Logger(str(path)) as logger:
        for msg in can.LogReader(str(CAPTURES / "can_pick_place.log")):
            logger.on_message_received(msg)
    return path


@cache
def demo_recording() -> Path:
    """A mixed recording of the demo on all three buses (``record --demo``), made once per
    test process: the simulated grippers on two ptys and the virtual CAN bus."""
    import tempfile

    path = Path(tempfile.mkdtemp(prefix="eg2-rerun-")) / "demo.mcap"
    cmd = [sys.executable, "-m", "analyzer", "record", "--demo", "-o", str(path)]
    subprocess.run([*cmd, "--duration", "3"], cwd=ROOT, check=True, capture_output=True)
    return path


def mcap_from_candump(tmp: Path) -> Path:
    """An eg2scope recording of the candump capture (plot re-decodes its raw frames)."""
    path = tmp / "recorded.mcap"
    recorder = McapRecorder(path, metadata={"test": "rerun"})
    run_capture(CaptureOptions(str(CAPTURES / "can_pick_place.log"), progress=False), [recorder])
    return path


INPUTS = {
    "candump": lambda tmp: CAPTURES / "can_pick_place.log",
    "asc": lambda tmp: python_can_copy(tmp, ".asc"),
    "blf": lambda tmp: python_can_copy(tmp, ".blf"),
    "serial": lambda tmp: CAPTURES / "serial_session.bin",
    "modbus": lambda tmp: CAPTURES / "modbus_session.bin",
    "mcap": mcap_from_candump,
    "mixed": lambda tmp: demo_recording(),
    "faults_can": faults_can,
    "faults_serial": faults_serial,
}
TIMED = {"candump", "asc", "blf", "mcap", "mixed", "faults_can"}
# sessions the native engine decodes: CAN input, and a raw dump's one byte stream
NATIVE = {"candump", "asc", "blf", "mcap", "faults_can", "serial", "modbus", "faults_serial"}


def engines(name: str) -> list[str]:
    """The session engines an input can be decoded with: CAN input and raw dumps on both, a
    recording of byte streams on the Python decoders only."""
    return ["python", "native"] if name in NATIVE else ["python"]


# (input, engine) for every input on every engine it can be decoded with
CASES = [(name, engine) for name in INPUTS for engine in engines(name)]
