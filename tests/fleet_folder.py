"""A fleet's folder of captures of every kind, generated: what the batch tests and the batch
benchmark decode.

``make_fleet(root, frames)`` writes, under ``root``:
- ``site-a/cell1/``: a candump -L log and a gzipped one (moving grippers, values that vary);
- ``site-a/cell2/``: an ASC and a BLF log written by python-can, and an eg2scope MCAP
  recording;
- with ``demo``: ``site-c/demo.mcap``, what ``eg2scope record --demo`` records (three buses,
  the wall clock's times);
- ``site-b/``: a raw serial dump (regular protocol) and a raw Modbus RTU dump;
- ``broken/``: a gzipped log cut off mid-stream (damaged) and an .mcap that is not MCAP
  (unreadable);
- a note (``site-a/README.txt``) that a folder scan must leave alone.
"""

from __future__ import annotations

import gzip
import os
import random
import subprocess
import sys
from pathlib import Path

import can

from analyzer.recording.recorder import McapRecorder
from analyzer.session.session import Session
from analyzer.sources.capture import open_capture
from analyzer.sources.source import CaptureSource
from decoders.build import candump_line

sys.path.insert(0, str(Path(__file__).resolve().parent / "benchmarks"))
import traffic

sys.path.pop(0)

DAY = 86_400.0
ROOT = Path(__file__).resolve().parents[1]


def _candump(path: Path, frames: int, seed: int, t0: float, channel: str = "can0") -> None:
    lines = [candump_line(f, channel) for f in traffic.can_frames(frames, seed=seed, t0=t0)]
    text = ("\n".join(lines) + "\n").encode()
    if path.suffix == ".gz":
        path.write_bytes(gzip.compress(text))
    else:
        path.write_bytes(text)


def _python_can(path: Path, frames: int, seed: int, t0: float) -> None:
    """An .asc or .blf log, as python-can writes them."""
    writer_class = can.ASCWriter if path.suffix == ".asc" else can.BLFWriter
    with writer_class(str(path)) as writer:
        for f in traffic.can_frames(frames, seed=seed, t0=t0):
            writer.on_message_received(
                can.Message(
                    timestamp=f.t or t0,
                    arbitration_id=f.arbitration_id,
                    is_extended_id=f.is_extended,
                    data=f.data,
                    channel=0,
                )
            )


def _mcap(path: Path, source: Path) -> None:
    """An eg2scope recording of a CAN capture (as `eg2scope record` writes them)."""
    reader = open_capture(source, bus="can1")
    with reader, McapRecorder(path, {"passive": "yes"}) as recorder:
        Session(CaptureSource(reader, None), [recorder]).run()


def _demo(path: Path) -> None:
    """``eg2scope record --demo``: the simulated grippers on all three buses."""
    subprocess.run(
        [sys.executable, "-m", "analyzer", "record", "--demo", "-o", str(path), "--duration", "5"],
        check=True,
        capture_output=True,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        timeout=120,
    )


def make_fleet(
    root: Path, frames: int = 2000, broken: bool = True, demo: bool = False
) -> dict[str, Path]:
    """The folder; name -> path of each capture."""
    t0 = 1_763_700_000.0  # 2025-11-21 UTC
    paths = {
        "candump": root / "site-a/cell1/can_day1.log",
        "candump_gz": root / "site-a/cell1/can_day2.log.gz",
        "asc": root / "site-a/cell2/trace.asc",
        "blf": root / "site-a/cell2/trace.blf",
        "mcap": root / "site-a/cell2/run.mcap",
        "serial": root / "site-b/serial.bin",
        "modbus": root / "site-b/modbus.bin",
    }
    for path in paths.values():
        path.parent.mkdir(parents=True, exist_ok=True)
    _candump(paths["candump"], frames, 1, t0)
    _candump(paths["candump_gz"], frames, 2, t0 + DAY)
    _python_can(paths["asc"], frames, 3, t0 + 2 * DAY)
    _python_can(paths["blf"], frames, 7, t0 + 2.5 * DAY)
    staging = root / "mcap-source.log"
    _candump(staging, frames, 4, t0 + 3 * DAY, channel="can1")
    _mcap(paths["mcap"], staging)
    staging.unlink()
    paths["serial"].write_bytes(b"".join(traffic.serial_frames(frames, seed=5)))
    paths["modbus"].write_bytes(b"".join(traffic.modbus_frames(frames, seed=6)))
    (root / "site-a/README.txt").write_text("cell 1: gripper on can0, 1 Mbit/s\n")
    if demo:
        paths["demo"] = root / "site-c/demo.mcap"
        paths["demo"].parent.mkdir(exist_ok=True)
        _demo(paths["demo"])
    if broken:
        (root / "broken").mkdir(exist_ok=True)
        paths["damaged"] = root / "broken/cut.log.gz"
        whole = gzip.compress(paths["candump"].read_bytes().replace(b"can0", b"can7"))
        paths["damaged"].write_bytes(whole[: len(whole) * 2 // 3])
        paths["unreadable"] = root / "broken/not-mcap.mcap"
        paths["unreadable"].write_bytes(random.Random(7).randbytes(3000))
    return paths
