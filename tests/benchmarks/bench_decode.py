"""Decode throughput and peak memory: ``eg2scope decode --format jsonl`` on 1M frames/protocol.

    python tests/benchmarks/bench_decode.py [--frames 1000000] [--runs 3] [--out bench-out]

Generates one million realistic frames per protocol (a raw serial dump, a raw Modbus RTU dump,
a candump -L log), runs the real CLI on each in a subprocess ``--runs`` times and reports the
median frames/s and the peak RSS. Where tshark is installed, the same CAN frames written as a
SocketCAN pcap are dissected with ``tshark -T fields`` in the same run for comparison.
Targets (issue 2): >= tshark on CAN (measured in the same run; 150k frames/s when tshark is not
installed), >= 150k frames/s on serial and Modbus, peak memory < 200 MB.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import struct
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

from traffic import can_frames, modbus_frames, serial_frames  # noqa: E402

from decoders.build import candump_line  # noqa: E402

MUST_FPS = 150_000
MUST_MB = 200


def write_inputs(out: Path, n: int) -> dict[str, Path]:
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "serial": out / f"serial_{n}.bin",
        "modbus": out / f"modbus_{n}.bin",
        "can": out / f"can_{n}.log",
        "pcap": out / f"can_{n}.pcap",
    }
    if all(p.exists() for p in paths.values()):
        return paths
    with paths["serial"].open("wb") as f:
        f.writelines(serial_frames(n))
    with paths["modbus"].open("wb") as f:
        f.writelines(modbus_frames(n))
    with paths["can"].open("w") as log, paths["pcap"].open("wb") as pcap:
        # pcap global header, linktype 227 = LINKTYPE_CAN_SOCKETCAN
        pcap.write(struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65535, 227))
        lines = []
        for frame in can_frames(n):
            lines.append(candump_line(frame))
            t = frame.t or 0.0
            can_id = frame.arbitration_id | 0x80000000  # CAN_EFF_FLAG
            body = struct.pack(">IB3x", can_id, len(frame.data)) + frame.data.ljust(8, b"\0")
            sec = int(t)
            pcap.write(struct.pack("<IIII", sec, int((t - sec) * 1e6), len(body), len(body)))
            pcap.write(body)
            if len(lines) >= 10_000:
                log.write("\n".join(lines) + "\n")
                lines.clear()
        if lines:
            log.write("\n".join(lines) + "\n")
    return paths


def timed(cmd: list[str]) -> tuple[float, float]:
    """Wall seconds and peak RSS (MB) of one child process, its output discarded."""
    start = time.perf_counter()
    with open(os.devnull, "wb") as devnull:
        proc = subprocess.Popen(cmd, stdout=devnull, stderr=subprocess.PIPE)
        _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status) != 0:
        err = proc.stderr.read().decode() if proc.stderr else ""
        raise SystemExit(f"command failed: {' '.join(cmd)}\n{err}")
    return wall, usage.ru_maxrss / 1024.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--frames", type=int, default=1_000_000)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--out", type=Path, default=ROOT / "bench-out")
    args = ap.parse_args()

    t = time.perf_counter()
    paths = write_inputs(args.out, args.frames)
    print(f"inputs ready in {time.perf_counter() - t:.1f} s under {args.out}")
    eg2 = [sys.executable, "-m", "analyzer", "decode", "--format", "jsonl", "--no-progress"]
    cases = {
        "serial": [*eg2, "--protocol", "serial", str(paths["serial"])],
        "modbus": [*eg2, "--protocol", "modbus", str(paths["modbus"])],
        "can": [*eg2, str(paths["can"])],
    }
    tshark = shutil.which("tshark")
    if tshark:
        cases["can (tshark)"] = [
            tshark,
            "-r",
            str(paths["pcap"]),
            "-T",
            "fields",
            "-e",
            "can.id",
            "-e",
            "can.len",
            "-e",
            "data.data",
        ]
    results: dict[str, tuple[float, float]] = {}
    for name, cmd in cases.items():
        walls, rss = [], []
        for _ in range(args.runs):
            w, m = timed(cmd)
            walls.append(w)
            rss.append(m)
        wall = statistics.median(walls)
        results[name] = (args.frames / wall, max(rss))
        runs = ", ".join(f"{w:.2f}" for w in walls)
        print(
            f"{name:14} {args.frames / wall:>10,.0f} frames/s  (median of {args.runs}: "
            f"{runs} s)  peak RSS {max(rss):.0f} MB"
        )
    ok = True
    for name in ("serial", "modbus", "can"):
        fps, mb = results[name]
        target = MUST_FPS
        if name == "can" and "can (tshark)" in results:
            # the must for CAN: at least as fast as tshark on the same frames, same run
            target = int(results["can (tshark)"][0])
        verdict = "ok" if fps >= target and mb < MUST_MB else "BELOW TARGET"
        ok &= verdict == "ok"
        print(
            f"  {name}: {fps:,.0f} frames/s vs must {target:,}; {mb:.0f} MB vs {MUST_MB} MB: "
            f"{verdict}"
        )
    if not tshark:
        print("  tshark not installed: CAN compared with the 150k frames/s figure only")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
