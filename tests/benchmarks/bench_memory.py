"""Peak memory of decoding hostile input: random bytes (all garbage), through every output.

    python tests/benchmarks/bench_memory.py [--mb 50] [--runs 3]

Decodes a dump of random bytes with ``decode -f jsonl|csv|text -j 1`` and ``stats`` and prints
the median peak RSS of each; the target is under 150 MB whatever the input size (memory must stay
flat: garbage is cut into records of at most 4 KiB and records are written batch by batch).
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LIMIT_MB = 150


def peak_rss_mb(cmd: list[str]) -> float:
    """Peak RSS of a child process, from wait4's rusage (kilobytes on Linux)."""
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) not in (0, 3):
        raise SystemExit(f"failed: {' '.join(cmd)}")
    return usage.ru_maxrss / 1024


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mb", type=int, default=50, help="size of the random dump (MB)")
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    with tempfile.TemporaryDirectory() as tmp:
        dump = Path(tmp) / "random.bin"
        with dump.open("wb") as f:
            for _ in range(args.mb):
                f.write(os.urandom(1 << 20))
        eg2 = [sys.executable, "-m", "analyzer"]
        cases = {
            f"decode -f {fmt}": [*eg2, "decode", str(dump), "-f", fmt, "-j", "1", "-o",
                                 str(Path(tmp) / f"out.{fmt}")]
            for fmt in ("jsonl", "csv", "text")
        }  # fmt: skip
        cases["stats"] = [*eg2, "stats", str(dump)]
        failed = False
        print(f"random dump of {args.mb} MB, median of {args.runs} runs")
        for name, cmd in cases.items():
            peak = statistics.median(peak_rss_mb(cmd) for _ in range(args.runs))
            ok = peak < LIMIT_MB
            failed |= not ok
            print(f"  {name:16} peak RSS {peak:6.0f} MB  {'ok' if ok else 'OVER'} (< {LIMIT_MB})")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
