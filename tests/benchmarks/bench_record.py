"""Live recording under load: the highest rate ``eg2scope record`` sustains with zero drops.

    python tests/benchmarks/bench_record.py [--duration 30] [--can-rates 8000,12000,16000]
                                            [--serial-baud 115200] [--only can|serial]

CAN: python-can's virtual bus does not cross processes, so the flooder (a thread sending
realistic EG2 polling traffic at a fixed rate) and the recorder (a live Session with the real
CanTap and MCAP output, as ``eg2scope record -i virtual`` runs it) share this process; the
recorder's CPU is the process's minus the flooder thread's own.
Serial: ``eg2scope record --serial PTY`` runs as a child process while this process writes
realistic frames into the pty at the byte rate of a saturated line (115200 baud 8N1 = 11520
bytes/s); the child's CPU and peak memory come from its rusage.
Targets: 8,000 CAN frames/s (a saturated 1 Mbit/s bus) and a saturated 115200-baud line, under
one core (issue 3); at 12,000 CAN frames/s, zero drops and at most 0.35 core (issue 10).
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import subprocess
import sys
import tempfile
import threading
import time
import tty
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

import can  # noqa: E402
from traffic import can_frames, modbus_frames  # noqa: E402

from analyzer.recording.recorder import McapRecorder  # noqa: E402
from analyzer.session.session import live_session  # noqa: E402
from analyzer.sources.can_tap import CanTap  # noqa: E402
from analyzer.sources.live import wait_open  # noqa: E402


def flood_can(channel: str, rate: int, duration: float, result: dict) -> None:
    """Send `rate` frames/s for `duration` s in 1 ms slices; record own CPU and count."""
    bus = can.Bus(interface="virtual", channel=channel)
    frames = can_frames(10**9)
    sent = 0
    start = time.perf_counter()
    cpu0 = time.thread_time()
    while (now := time.perf_counter() - start) < duration:
        due = int(now * rate)
        while sent < due:
            f = next(frames)
            bus.send(can.Message(arbitration_id=f.arbitration_id, data=f.data, is_extended_id=True))
            sent += 1
        time.sleep(0.001)
    result["sent"] = sent
    result["cpu"] = time.thread_time() - cpu0
    bus.shutdown()


def bench_can(rate: int, duration: float, out: Path) -> dict:
    channel = f"bench-{os.getpid()}-{time.monotonic_ns()}"
    recorder = McapRecorder(out / f"can_{rate}.mcap", metadata={"bench": "can"})
    session = live_session([CanTap("can0", "virtual", channel)], [recorder])
    flood: dict = {}
    thread = threading.Thread(target=flood_can, args=(channel, rate, duration, flood))

    def start_flood() -> None:
        wait_open(session.source.taps)
        thread.start()

    session.source.on_started = start_flood
    cpu0, wall0 = time.process_time(), time.perf_counter()
    runner = threading.Thread(target=session.run)
    runner.start()
    time.sleep(0.2)
    thread.join()
    # let the recorder drain what is queued, then stop
    deadline = time.perf_counter() + 5
    while session.counts.items < flood["sent"] and time.perf_counter() < deadline:
        time.sleep(0.05)
    lag = time.perf_counter()
    session.stop()
    runner.join()
    wall = time.perf_counter() - wall0
    cpu = time.process_time() - cpu0 - flood["cpu"]
    captured = session.counts.items
    return {
        "rate": rate,
        "sent": flood["sent"],
        "captured": captured,
        "dropped": session.counts.dropped,
        "cpu_cores": cpu / wall,
        # the recorder's CPU per frame at the rate asked: what cpu_cores would be if the
        # recorder had the CPU to itself (on a busy machine it falls behind and catches up
        # after the flood, which stretches the wall time cpu_cores is measured over)
        "cpu_per_frame_cores": cpu / max(1, captured) * rate,
        "drain_s": lag - (wall0 + 0.2 + duration),
        "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def bench_serial(baud: int, duration: float, out: Path) -> dict:
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    port = os.ttyname(slave)
    mcap = out / "serial.mcap"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [
        sys.executable,
        "-m",
        "analyzer",
        "record",
        "--serial",
        port,
        "--protocol",
        "modbus",
        "-o",
        str(mcap),
        "--duration",
        str(duration + 2),
    ]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    time.sleep(1.5)  # the child starts and opens the port
    bytes_per_s = baud / 10  # 8N1: ten bit times per byte
    frames = modbus_frames(10**9)
    sent = frames_sent = 0
    pending = b""
    start = time.perf_counter()
    while (now := time.perf_counter() - start) < duration:
        due = int(now * bytes_per_s)
        while len(pending) < due - sent:
            pending += next(frames)
            frames_sent += 1
        n = due - sent
        if n > 0:
            os.write(master, pending[:n])
            pending = pending[n:]
            sent += n
        time.sleep(0.002)
    _, _status, usage = os.wait4(proc.pid, 0)
    err = proc.stderr.read().decode() if proc.stderr else ""
    os.close(master)
    os.close(slave)
    m = re.search(
        r"([\d,]+) chunks/frames captured, ([\d,]+) records decoded, ([\d,]+) with "
        r"errors, ([\d,]+) dropped",
        err,
    )
    if not m:
        raise SystemExit(f"recorder output not understood:\n{err}")
    records, errors, dropped = (int(m.group(i).replace(",", "")) for i in (2, 3, 4))
    cpu = usage.ru_utime + usage.ru_stime
    return {
        "baud": baud,
        "bytes": sent,
        "frames_sent": frames_sent,
        "records": records,
        "errors": errors,
        "dropped": dropped,
        "cpu_cores": cpu / (duration + 3.5),
        "rss_mb": usage.ru_maxrss / 1024,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--can-rates", default="8000,12000,16000,20000")
    ap.add_argument("--serial-baud", type=int, default=115200)
    ap.add_argument("--only", choices=("can", "serial"))
    args = ap.parse_args()
    ok = True
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        if args.only != "serial":
            best = 0
            for rate in (int(r) for r in args.can_rates.split(",")):
                r = bench_can(rate, args.duration, out)
                achieved = r["sent"] / args.duration
                held = r["dropped"] == 0 and r["captured"] == r["sent"] and r["cpu_cores"] < 1
                print(
                    f"CAN {rate:>6,} frames/s for {args.duration:.0f} s: sent {r['sent']:,}, "
                    f"captured {r['captured']:,}, dropped {r['dropped']}, recorder CPU "
                    f"{r['cpu_cores']:.2f} cores ({r['cpu_per_frame_cores']:.2f} from its CPU "
                    f"per frame), drained {max(0.0, r['drain_s']):.1f} s after the flood, "
                    f"peak RSS {r['rss_mb']:.0f} MB: "
                    f"{'sustained' if held else 'NOT sustained'}",
                    flush=True,
                )
                if achieved < 0.97 * rate:
                    print(
                        f"CAN {rate:,} frames/s asked: the flooder thread reached only "
                        f"{achieved:,.0f} frames/s (it shares the GIL with the recorder); "
                        "stopping here"
                    )
                    if held:
                        best = max(best, int(achieved))
                    break
                if rate == 12_000:
                    light = held and r["cpu_cores"] <= 0.35
                    print(f"CAN 12,000 frames/s at most 0.35 core: {'yes' if light else 'NO'}")
                    ok &= light
                if not held:
                    break
                best = rate
            print(f"CAN: highest rate sustained with zero drops: {best:,} frames/s (must: 8,000)")
            ok &= best >= 8000
        if args.only != "can":
            r = bench_serial(args.serial_baud, args.duration, out)
            held = r["dropped"] == 0 and r["cpu_cores"] < 1
            print(
                f"serial {r['baud']} baud saturated for {args.duration:.0f} s: "
                f"{r['bytes']:,} bytes ({r['frames_sent']:,} Modbus frames), "
                f"{r['records']:,} records, {r['errors']} errors, dropped {r['dropped']}, "
                f"recorder CPU {r['cpu_cores']:.2f} cores, peak RSS {r['rss_mb']:.0f} MB: "
                f"{'sustained' if held else 'NOT sustained'}"
            )
            ok &= held
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
