"""Rerun output under load (issues 9 and 17): a capture turned into an .rrd against decoding it
to JSONL, memory for a large capture, and a live session at 20,000 records/s.

    python tests/benchmarks/bench_rerun.py [--frames 200000 1000000] [--memory-frames 1000000]
                                           [--runs 3] [--live-rate 20000] [--live-duration 60]
                                           [--only capture|warnings|memory|live]

Captures (candump logs): realistic EG2 polling traffic (``traffic.can_frames``) and a host that
draws a warning on every command (``traffic.warning_can_frames``: commands 0.25 ms apart,
broadcast writes, an undocumented address; most records go to the error and command logs).
Each is decoded with ``eg2scope decode FILE --format jsonl`` and plotted with ``eg2scope plot
FILE --save out.rrd`` in child processes, side by side, after one warm-up run (so Python's
bytecode caches are written, as they are for a user); CPU (user + system, all threads, from the
child's rusage), wall time and peak RSS, median of ``--runs``. Also shown: a session with no
output (the plot's decoding and state samples), importing rerun, and Rerun's own cost of the
plot's output (its .rrd's chunks sent and written again by a script that does only that), the
floor no eg2scope code can go under. Each size of ``--frames`` is measured (default 200k and 1M
frames). Targets: plot CPU at most 2x decode --format jsonl on the warning-heavy capture; peak
RSS of plot under 300 MB at 1M records of it (``memory``: one run of ``--memory-frames``).

Live: python-can's virtual bus does not cross processes, so a flooder thread sends request and
response frames at ``--live-rate`` records/s while a live session (the real CanTap, the Rerun
listener writing an .rrd as ``plot -i virtual`` does) decodes them in this process. Targets: no
drops, every record decoded, and the viewer updated at least 10 times a second (the listener's
flushes are counted).
"""

from __future__ import annotations

import argparse
import itertools
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

from traffic import can_frames, warning_can_frames  # noqa: E402

# (the live benchmark's modules are imported by it: a child's peak RSS starts at this
# process's, which importing rerun here would raise by 200 MB)

MAX_RATIO = 2.0  # plot --save / decode --format jsonl, CPU
MAX_RSS_MB = 300
MIN_UPDATES_PER_S = 10

# one session, no output; with "states", the tracker also makes the state samples the Rerun
# listener reads (their cost is the session's, shown apart)
DECODE_ONLY = """
import sys
from analyzer.session.capture import CaptureOptions, run_capture
from analyzer.session.listener import Listener
class Null(Listener):
    wants_states = sys.argv[2] == "states"
    def on_records(self, records): pass
run_capture(CaptureOptions(sys.argv[1], progress=False), [Null()])
"""
IMPORT_RERUN = "import rerun, rerun.blueprint"
# Rerun's own cost of the plot's output: the chunks of its .rrd sent again to a new file, no
# eg2scope code involved (prints the CPU, all threads, of sending, encoding and writing them)
ENCODE_ONLY = """
import resource, sys
import rerun as rr
from rerun.chunk import RrdReader
chunks = list(RrdReader(sys.argv[1]).stream())
def cpu():
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime
stream = rr.RecordingStream("eg2scope-bench")
stream.save(sys.argv[2])
start = cpu()
stream.send_chunks(chunks)
stream.flush()
stream.disconnect()
print(cpu() - start)
"""


def write_candump(path: Path, frames: Any) -> None:
    with path.open("w") as f:
        for fr in frames:
            f.write(f"({fr.t:.6f}) can0 {fr.arbitration_id:08X}#{fr.data.hex().upper()}\n")


# the children run as a user's eg2scope does: with Python's bytecode caches
CHILD_ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def run_child(cmd: list[str]) -> tuple[float, float, float]:
    """(CPU s, wall s, peak RSS MB) of a child process."""
    start = time.perf_counter()
    proc = subprocess.Popen(
        cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=ROOT, env=CHILD_ENV
    )
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status) != 0:
        assert proc.stderr is not None
        raise SystemExit(f"failed: {' '.join(cmd)}\n{proc.stderr.read().decode()}")
    return usage.ru_utime + usage.ru_stime, wall, usage.ru_maxrss / 1024


EG2SCOPE = [sys.executable, "-m", "analyzer"]


def encoding_cpu(rrd: Path, tmp: Path) -> float:
    """CPU seconds Rerun takes to send, encode and write the chunks of ``rrd`` again."""
    out = subprocess.run(
        [sys.executable, "-c", ENCODE_ONLY, str(rrd), str(tmp / "again.rrd")],
        capture_output=True, text=True, check=True, cwd=ROOT, env=CHILD_ENV,
    )  # fmt: skip
    return float(out.stdout)


def bench_capture(what: str, frames: int, runs: int, tmp: Path) -> bool:
    """``what``: "capture" (realistic polling) or "warnings" (every command flagged)."""
    log = tmp / f"{what}.log"
    write_candump(log, (can_frames if what == "capture" else warning_can_frames)(frames))
    cases = {
        "decode --format jsonl": [*EG2SCOPE, "decode", str(log), "--format", "jsonl"],
        "session, no output": [sys.executable, "-c", DECODE_ONLY, str(log), "states"],
        "import rerun": [sys.executable, "-c", IMPORT_RERUN],
        "plot --save .rrd": [
            *EG2SCOPE, "plot", str(log), "--save", str(tmp / "out.rrd"), "--no-progress"
        ],
    }  # fmt: skip
    for cmd in cases.values():  # warm-up: bytecode caches, the file in the page cache
        run_child(cmd)
    samples: dict[str, list[tuple[float, float, float]]] = {name: [] for name in cases}
    for _ in range(runs):  # side by side: each run's load is shared by every case
        for name, cmd in cases.items():
            samples[name].append(run_child(cmd))
    label = "realistic polling" if what == "capture" else "a warning on every command"
    print(f"{label}: {frames:,} CAN frames (candump log, {log.stat().st_size / 1e6:.0f} MB), "
          f"median of {runs} runs")  # fmt: skip
    results = {}
    for name, rows in samples.items():
        cpu, wall, rss = (statistics.median(r[i] for r in rows) for i in range(3))
        results[name] = (cpu, wall, rss)
        print(f"  {name:22} CPU {cpu:6.2f} s  wall {wall:6.2f} s  peak RSS {rss:5.0f} MB")
    base, plot = results["decode --format jsonl"], results["plot --save .rrd"]
    ratio_cpu, ratio_wall = plot[0] / base[0], plot[1] / base[1]
    size = (tmp / "out.rrd").stat().st_size / 1e6
    ok = ratio_cpu <= MAX_RATIO
    verdict = "ok" if ok else "MISSED"
    print(f"  plot / decode jsonl: CPU x{ratio_cpu:.2f}, wall x{ratio_wall:.2f} "
          f"(target <= x{MAX_RATIO}); .rrd {size:.0f} MB -> {verdict}")  # fmt: skip
    encode = statistics.median(encoding_cpu(tmp / "out.rrd", tmp) for _ in range(runs))
    floor = results["import rerun"][0] + encode
    print(f"  Rerun alone: its .rrd's chunks sent and written again CPU {encode:.2f} s; with "
          f"import rerun {floor:.2f} s = x{floor / base[0]:.2f} decode jsonl before any "
          "reading or decoding")  # fmt: skip
    return ok or what == "capture"  # the target is the warning-heavy capture's


def bench_memory(frames: int, tmp: Path) -> bool:
    log = tmp / "memory.log"
    write_candump(log, warning_can_frames(frames))
    out = tmp / "memory.rrd"
    cpu, wall, rss = run_child([*EG2SCOPE, "plot", str(log), "--save", str(out), "--no-progress"])
    ok = rss < MAX_RSS_MB
    print(f"memory: plot --save of {frames:,} frames with a warning on every command: peak RSS "
          f"{rss:.0f} MB (target < {MAX_RSS_MB}), CPU {cpu:.1f} s, wall {wall:.1f} s -> "
          f"{'ok' if ok else 'MISSED'}")  # fmt: skip
    return ok


def bench_live(rate: int, duration: float, tmp: Path, rerun: bool = True) -> bool:
    """``rate`` records/s: requests and responses, half each (``rate`` frames/s)."""
    from bench_record import flood_can

    from analyzer.plot.listener import RerunListener
    from analyzer.session.session import live_session
    from analyzer.sources.can_tap import CanTap
    from analyzer.sources.live import wait_open

    channel = f"bench-rerun-{os.getpid()}-{time.monotonic_ns()}"
    from analyzer.session.listener import Listener

    class NullStates(Listener):
        """Decoding and state samples, no output: the live baseline."""

        wants_states = True

        def on_records(self, records: list[Any]) -> None:
            pass

        def flush(self, final: bool = False) -> None:
            pass

    listener: Any = RerunListener(str(tmp / "live.rrd"), live=True) if rerun else NullStates()
    flushes: list[float] = []
    flush = listener.flush

    def counted_flush(final: bool = False) -> None:
        flushes.append(time.monotonic())
        flush(final)

    listener.flush = counted_flush
    session = live_session([CanTap("can0", "virtual", channel)], [listener])
    flood: dict = {}
    sender = threading.Thread(target=flood_can, args=(channel, rate, duration, flood))

    def start_flood() -> None:
        wait_open(session.source.taps)
        sender.start()

    session.source.on_started = start_flood
    cpu0 = time.process_time()
    runner = threading.Thread(target=session.run)
    runner.start()
    time.sleep(0.5)
    sender.join()
    time.sleep(1.0)  # the last batch
    session.stop()
    runner.join()
    cpu = time.process_time() - cpu0 - flood.get("cpu", 0.0)
    counts = session.counts
    during = flushes[:-1]  # the last one is the final flush at close
    gaps = [b - a for a, b in itertools.pairwise(during)]
    per_s = len(during) / max(during[-1] - during[0], 1e-9) if len(during) > 1 else 0.0
    kept = counts.dropped == 0 and counts.records >= flood["sent"]
    what = "Rerun listener" if rerun else "baseline, no output"
    sent = flood["sent"]
    print(f"live ({what}): {sent:,} records sent in {duration:.0f} s "
          f"({sent / duration:,.0f}/s of {rate:,}/s asked) on the virtual CAN bus")  # fmt: skip
    print(f"  decoded {counts.records:,}, dropped {counts.dropped:,}; session CPU "
          f"{cpu / duration * 100:.0f}% of a core; peak RSS "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")  # fmt: skip
    if not rerun:
        return kept
    ok = kept and per_s >= MIN_UPDATES_PER_S
    print(f"  viewer updated {per_s:.1f} times/s (longest gap {max(gaps, default=0) * 1000:.0f} "
          f"ms) -> {'ok' if ok else 'MISSED'}")  # fmt: skip
    return ok


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--frames", type=int, nargs="+", default=[200_000, 1_000_000])
    ap.add_argument("--memory-frames", type=int, default=1_000_000)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--live-rate", type=int, default=20_000)
    ap.add_argument("--live-duration", type=float, default=60.0)
    ap.add_argument("--only", choices=("capture", "warnings", "memory", "live"))
    args = ap.parse_args()
    ok = True
    with tempfile.TemporaryDirectory() as tmp:
        for what in ("capture", "warnings"):
            for frames in args.frames if args.only in (None, what) else ():
                ok &= bench_capture(what, frames, args.runs, Path(tmp))
        if args.only in (None, "memory"):
            ok &= bench_memory(args.memory_frames, Path(tmp))
        if args.only in (None, "live"):
            bench_live(args.live_rate, args.live_duration, Path(tmp), rerun=False)
            ok &= bench_live(args.live_rate, args.live_duration, Path(tmp))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
