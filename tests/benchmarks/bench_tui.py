"""Benchmark of the TUI (issue 8, "Speed and memory"): not a timed test. Prints figures.

    .venv/bin/python tests/benchmarks/bench_tui.py capture [--records 1000000]
    .venv/bin/python tests/benchmarks/bench_tui.py live [--seconds 60 --rate 20000]

capture: a candump log of N CAN records replayed in the real app (Pilot, headless): time to the
first screen, to the whole capture, a filter, going to the last frame, and the process's peak
memory.

live: CAN frames at RATE frames/s through the real CAN tap, decoding and the app for SECONDS:
records shown, drops, CPU of the process (and of each of its threads), and how long a key press
takes to be answered (the cursor's row repainted). The frames come from another process, as a
user's do (from the kernel or the adapter), over python-can's ``udp_multicast`` interface:
python-can's ``virtual`` bus does not cross processes, and a sender thread in the measured
process would count its cost and its share of the GIL against the TUI. udp_multicast is a real
socket interface like socketcan (no vcan in this sandbox: no kernel module): one ``select`` and
one ``recvmsg`` per frame, timestamps from the kernel, and a kernel receive buffer, plus a
msgpack decoding that socketcan does not pay, so the tap costs a little more than on socketcan.
The CPU reported is this process's only (``time.process_time``; threads by psutil); the sender
process's is printed apart. Frames the kernel dropped before the tap read them (its socket
buffer overflowed) are counted as sent - taken - dropped: they are losses too.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import resource
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

os.environ["TEXTUAL_ANIMATIONS"] = "none"
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tui"))

from traffic import can_frames


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def write_candump(path: Path, n: int) -> None:
    with path.open("w") as f:
        for fr in can_frames(n):
            f.write(f"({fr.t:.6f}) can0 {fr.arbitration_id:08X}#{fr.data.hex().upper()}\n")


async def bench_capture(n: int) -> None:
    from conftest import capture_app  # the tests' way of opening a capture in the app

    from analyzer.tui.filter import parse

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.log"
        write_candump(path, n)
        t0 = time.perf_counter()
        app = capture_app(path)
        async with app.run_test(size=(200, 50)) as pilot:
            await pilot.pause()  # the screen is composed: the frame list exists
            while app.frames.row_count == 0:
                await asyncio.sleep(0.01)
            first = time.perf_counter() - t0
            while not app.done:
                await asyncio.sleep(0.05)
            whole = time.perf_counter() - t0
            t1 = time.perf_counter()
            app.frames.set_filter(parse("dev == 1 and latency > 0.1"))
            await pilot.pause()
            filtered = time.perf_counter() - t1
            shown = app.frames.row_count
            app.frames.set_filter(None)
            t1 = time.perf_counter()
            app.frames.move_to(app.frames.row_count - 1)
            await pilot.pause()
            end = time.perf_counter() - t1
            t1 = time.perf_counter()
            app.go_to_index(app.store.count // 2)
            await pilot.pause()
            goto = time.perf_counter() - t1
            count = app.store.count
        print(
            f"capture {count:,} records: first screen {first:.2f} s, all decoded {whole:.1f} s, "
            f"filter {filtered:.2f} s ({shown:,} shown), to the end {end:.2f} s, "
            f"go to {goto:.2f} s, peak RSS {peak_mb():.0f} MB"
        )


def send(group: str, port: int, rate: int, seconds: float) -> None:
    """The sender process: CAN frames on the UDP multicast bus at ``rate`` frames/s, paced on
    the clock (frames that fall due while it sleeps go out at once). The frames are packed
    once, by python-can's own ``pack_message``, and sent by its own multicast socket class: the
    wire is the udp_multicast interface's, at a fraction of the sender's CPU (it shares the
    machine with the process measured). Prints how many it sent and the CPU time that took."""
    import can
    from can.interfaces.udp_multicast.bus import GeneralPurposeUdpMulticastBus
    from can.interfaces.udp_multicast.utils import pack_message

    sock = GeneralPurposeUdpMulticastBus(group, port, hop_limit=1)
    packed = [
        pack_message(can.Message(arbitration_id=fr.arbitration_id, data=fr.data,
                                 is_extended_id=fr.is_extended))
        for fr in can_frames(200_000)
    ]  # fmt: skip
    k, start, cpu = 0, time.perf_counter(), time.process_time()
    while (elapsed := time.perf_counter() - start) < seconds:
        due = int(elapsed * rate)
        while k < due:
            sock.send(packed[k % len(packed)])
            k += 1
        time.sleep(0.001)
    sock.shutdown()
    print(f"{k} {time.process_time() - cpu:.3f}", flush=True)


def thread_cpu() -> dict[str, float]:
    """CPU seconds of each thread of this process, by thread name (psutil)."""
    import psutil

    names = {t.native_id: t.name for t in threading.enumerate()}
    found: dict[str, float] = {}
    for t in psutil.Process().threads():
        name = names.get(t.id, "other")
        name = "tap" if name.startswith(("Notifier", "eg2scope can")) else name
        found[name] = found.get(name, 0.0) + t.user_time + t.system_time
    return found


async def bench_live(seconds: float, rate: int) -> None:
    from conftest import live_opts

    from analyzer.sources.can_tap import CanTap
    from analyzer.sources.live import wait_open
    from analyzer.tui.app import Eg2ScopeApp
    from analyzer.tui.launch import live_plan

    # a group and port of this run's own: other processes on the machine stay out of it
    group, port = "ff15:7079:7468:6f6e:6465:6d6f:6d63:6173", 43200 + os.getpid() % 1000
    tap = CanTap("can0", "udp_multicast", group, port=port)
    app = Eg2ScopeApp(live_plan(live_opts(), [tap], {}, None))
    async with app.run_test(size=(200, 50)) as pilot:
        while app.session is None or not wait_open([tap], 0.0):
            await asyncio.sleep(0.01)
        frames = app.frames
        painted: list[float] = []  # when the cursor's row was last painted
        render_line = frames.render_line

        def spy(y: int) -> Any:
            if frames.scroll_offset.y + y == frames.cursor:
                painted.append(time.perf_counter())
            return render_line(y)

        frames.render_line = spy  # type: ignore[method-assign]
        sender = subprocess.Popen(
            [sys.executable, __file__, "send", "--group", group, "--port", str(port),
             "--rate", str(rate), "--seconds", str(seconds + 1.0)],
            stdout=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        while app.captured == 0:  # the sender's interpreter is up: the clock starts
            await asyncio.sleep(0.01)
        n0, threads0 = app.store.count, thread_cpu()
        c0, w0 = time.process_time(), time.perf_counter()
        lags = []
        while time.perf_counter() - w0 < seconds:
            await asyncio.sleep(1.0)
            painted.clear()
            t1 = time.perf_counter()
            frames.action_cursor(-1)  # what the up key does; answered when it is repainted
            while not painted and time.perf_counter() - t1 < 5:
                await asyncio.sleep(0.002)
            lags.append((painted[0] if painted else time.perf_counter()) - t1)
        wall = time.perf_counter() - w0
        cpu = (time.process_time() - c0) / wall
        threads = {k: (v - threads0.get(k, 0.0)) / wall for k, v in thread_cpu().items()}
        count = app.store.count - n0
        out, _ = sender.communicate()
        sent, sender_cpu = int(out.split()[0]), float(out.split()[1])
        before = -1
        while app.captured + app.dropped != before:  # what is still in flight lands
            before = app.captured + app.dropped
            await asyncio.sleep(0.5)
        dropped, captured = app.dropped, app.captured
        await pilot.press("q")
    lags.sort()
    lost = sent - captured - dropped  # never reached the tap (the socket's buffer overflowed)
    share = ", ".join(f"{k} {v:.0%}" for k, v in sorted(threads.items(), key=lambda x: -x[1]))
    print(
        f"live {rate:,}/s for {seconds:.0f} s: {count:,} records in the window "
        f"({count / wall:,.0f}/s); {sent:,} sent, {captured:,} taken by the session, "
        f"{dropped:,} dropped by the queue, {lost:,} lost before the tap; "
        f"CPU of the eg2scope process {cpu:.0%} of one core ({share}); "
        f"sender process {sender_cpu / (seconds + 1):.0%}; key answered in median "
        f"{lags[len(lags) // 2] * 1000:.0f} ms, max {lags[-1] * 1000:.0f} ms"
    )


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("what", choices=("capture", "live", "send"))
    parser.add_argument("--group", default="")
    parser.add_argument("--port", type=int, default=0)
    parser.add_argument("--records", type=int, default=1_000_000)
    parser.add_argument("--seconds", type=float, default=60)
    parser.add_argument("--rate", type=int, default=20_000)
    args = parser.parse_args()
    if args.what == "capture":
        asyncio.run(bench_capture(args.records))
    elif args.what == "send":
        send(args.group, args.port, args.rate, args.seconds)
    else:
        asyncio.run(bench_live(args.seconds, args.rate))


if __name__ == "__main__":
    main()
