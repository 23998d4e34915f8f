"""Decode throughput and peak memory: ``eg2scope decode --format jsonl -o FILE`` on 1M frames
per protocol, with both engines and tshark side by side in one run.

    python tests/benchmarks/bench_decode.py [--frames 1000000] [--runs 5] [--out bench-out]
                                            [--engines native,python]

Generates one million realistic frames per protocol (a raw serial dump, a raw Modbus RTU dump,
a candump -L log with varying values) and a warning-heavy CAN log (``can-warnings``: every
command closer than 5 ms to the last, broadcast writes, reads of an undocumented register, so
every request draws a warning), runs the real CLI on each in a subprocess ``--runs`` times
per engine, writing JSONL to a file, and reports the median frames/s and the peak RSS. Where
tshark is installed, the same CAN frames written as a SocketCAN pcap are dissected with
``tshark -T fields`` in the same run, and the CAN figures are quoted as ratios to it.
Targets, native engine, one process (issues 10 and 19): CAN >= 5x tshark on both CAN logs;
serial and Modbus >= 1,000,000 frames/s; peak memory < 100 MB. The Python engine is measured
alongside for the ratio. ``--clock cpu`` rates each command by its CPU seconds (user + system,
all threads) instead of wall seconds: on a shared, loaded machine that is the figure that does
not depend on what the neighbours do.
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
from collections.abc import Iterator
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

from traffic import can_frames, modbus_frames, serial_frames, warning_can_frames  # noqa: E402

from decoders.build import candump_line  # noqa: E402
from decoders.model import CanFrame  # noqa: E402

MUST_FPS = 1_000_000  # native, serial and Modbus
MUST_TSHARK_RATIO = 5.0  # native CAN vs tshark
MUST_MB = 100


CAN_CASES = ("can", "can-warnings")  # each a candump log and the same frames as a pcap


def write_inputs(out: Path, n: int) -> dict[str, Path]:
    out.mkdir(parents=True, exist_ok=True)
    paths = {"serial": out / f"serial_{n}.bin", "modbus": out / f"modbus_{n}.bin"}
    for case in CAN_CASES:
        paths[case] = out / f"{case}_{n}.log"
        paths[f"{case}.pcap"] = out / f"{case}_{n}.pcap"
    if all(p.exists() for p in paths.values()):
        return paths
    with paths["serial"].open("wb") as f:
        f.writelines(serial_frames(n))
    with paths["modbus"].open("wb") as f:
        f.writelines(modbus_frames(n))
    write_can(can_frames(n), paths["can"], paths["can.pcap"])
    write_can(warning_can_frames(n), paths["can-warnings"], paths["can-warnings.pcap"])
    return paths


def write_can(frames: Iterator[CanFrame], log_path: Path, pcap_path: Path) -> None:
    """The frames as a candump -L log and as a SocketCAN pcap for tshark."""
    with log_path.open("w") as log, pcap_path.open("wb") as pcap:
        # pcap global header, linktype 227 = LINKTYPE_CAN_SOCKETCAN
        pcap.write(struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65535, 227))
        lines = []
        for frame in frames:
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


def timed(cmd: list[str], sink: Path | None = None) -> tuple[float, float, float]:
    """Wall seconds, CPU seconds and peak RSS (MB) of one child process, its output discarded.
    The last run's ``sink`` is removed first, outside the clock: freeing hundreds of MB of an old
    output (when the new one is renamed over it) is not decoding."""
    if sink is not None:
        sink.unlink(missing_ok=True)
    start = time.perf_counter()
    with open(os.devnull, "wb") as devnull:
        proc = subprocess.Popen(cmd, stdout=devnull, stderr=subprocess.PIPE)
        _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status) != 0:
        err = proc.stderr.read().decode() if proc.stderr else ""
        raise SystemExit(f"command failed: {' '.join(cmd)}\n{err}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0


def _tshark(pcap: Path) -> list[str] | None:
    tshark = shutil.which("tshark")
    if not tshark:
        return None
    fields = ["-e", "can.id", "-e", "can.len", "-e", "data.data"]
    return [tshark, "-r", str(pcap), "-T", "fields", *fields]


def measure(
    name: str, cmd: list[str], frames: int, runs: int, clock: str, sink: Path | None = None
) -> tuple[float, float]:
    """Median frames/s (per ``clock`` second) and the highest peak RSS of ``runs`` runs."""
    seconds: dict[str, list[float]] = {"wall": [], "cpu": []}
    rss = []
    for _ in range(runs):
        wall, cpu, mb = timed(cmd, sink)
        seconds["wall"].append(wall)
        seconds["cpu"].append(cpu)
        rss.append(mb)
    chosen = statistics.median(seconds[clock])
    times = {k: ", ".join(f"{x:.2f}" for x in v) for k, v in seconds.items()}
    print(
        f"{name:22} {frames / chosen:>10,.0f} frames/{clock}-s  (median of {runs}; wall "
        f"{times['wall']} s; cpu {times['cpu']} s)  peak RSS {max(rss):.0f} MB",
        flush=True,
    )
    return frames / chosen, max(rss)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--frames", type=int, default=1_000_000)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--out", type=Path, default=ROOT / "bench-out")
    ap.add_argument("--engines", default="native,python", help="comma-separated engines to run")
    ap.add_argument("--clock", choices=("wall", "cpu"), default="wall", help="what a second is")
    args = ap.parse_args()

    t = time.perf_counter()
    paths = write_inputs(args.out, args.frames)
    print(f"inputs ready in {time.perf_counter() - t:.1f} s under {args.out}")
    engines = [e for e in args.engines.split(",") if e]
    sink = args.out / "decoded.jsonl"
    cases: dict[str, list[str]] = {}
    for engine in engines:
        eg2 = [sys.executable, "-m", "analyzer", "decode", "--format", "jsonl", "--no-progress"]
        eg2 += ["--engine", engine, "--jobs", "1", "-o", str(sink)]
        cases[f"serial ({engine})"] = [*eg2, "--protocol", "serial", str(paths["serial"])]
        cases[f"modbus ({engine})"] = [*eg2, "--protocol", "modbus", str(paths["modbus"])]
        for case in CAN_CASES:
            cases[f"{case} ({engine})"] = [*eg2, str(paths[case])]
    for case in CAN_CASES:
        tshark = _tshark(paths[f"{case}.pcap"])
        if tshark:
            cases[f"{case} (tshark)"] = tshark
    # interleaved protocol by protocol, so a noisy neighbour hits every engine alike
    order = sorted(cases, key=lambda k: (not k.startswith("can"), k.split()[0]))
    results = {
        name: measure(name, cases[name], args.frames, args.runs, args.clock, sink) for name in order
    }
    sink.unlink(missing_ok=True)
    return report(results, "native" in engines)


def report(results: dict[str, tuple[float, float]], native: bool) -> int:
    ok = True
    for engine in ("native", "python"):
        if f"can ({engine})" not in results:
            continue
        print(f"{engine} engine:")
        for proto in ("serial", "modbus", *CAN_CASES):
            fps, mb = results[f"{proto} ({engine})"]
            line = f"  {proto}: {fps:,.0f} frames/s, {mb:.0f} MB"
            base = results.get(f"{proto} (tshark)")
            if base:
                line += f", {fps / base[0]:.2f}x tshark"
            if engine == "native":
                if proto in CAN_CASES:
                    good = base is None or fps >= MUST_TSHARK_RATIO * base[0]
                    must = f"{MUST_TSHARK_RATIO:g}x tshark" if base else "(no tshark)"
                else:
                    good, must = fps >= MUST_FPS, f"{MUST_FPS:,} frames/s"
                good &= mb < MUST_MB
                ok &= good
                line += f"  [must {must}, < {MUST_MB} MB: {'ok' if good else 'BELOW TARGET'}]"
            print(line)
    if native and "can (python)" in results:
        for proto in ("serial", "modbus", *CAN_CASES):
            ratio = results[f"{proto} (native)"][0] / results[f"{proto} (python)"][0]
            print(f"  native / python on {proto}: {ratio:.1f}x")
    if "can (tshark)" not in results:
        print("  tshark not installed (apt install tshark): CAN ratio not measured")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
