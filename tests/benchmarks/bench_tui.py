"""Benchmark of the TUI (issue 8, "Speed and memory"): not a timed test. Prints figures.

    .venv/bin/python tests/benchmarks/bench_tui.py capture [--records 1000000]
    .venv/bin/python tests/benchmarks/bench_tui.py live [--seconds 60 --rate 20000]

capture: a candump log of N CAN records replayed in the real app (Pilot, headless): time to the
first screen, to the whole capture, a filter, going to the last frame, and the process's peak
memory. live: CAN frames sent on python-can's virtual bus at RATE frames/s through the real CAN
tap, decoding and the app for SECONDS: drops, records shown, CPU use of the process, and how
long a key press takes to be answered.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import resource
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
            while app.frames.row_count == 0:
                await asyncio.sleep(0.01)
            first = time.perf_counter() - t0
            while not app.done:
                await asyncio.sleep(0.05)
            whole = time.perf_counter() - t0
            t1 = time.perf_counter()
            app.frames.set_filter(parse("dev == 1 and latency > 0.5"))
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


async def bench_live(seconds: float, rate: int) -> None:
    import can
    from conftest import live_args

    from analyzer.commands.tui import live_plan
    from analyzer.sources.can_tap import CanTap
    from analyzer.tui.app import Eg2ScopeApp

    channel = f"bench-tui-{os.getpid()}"
    tap = CanTap("can0", "virtual", channel)
    stop = threading.Event()
    sent = [0]

    def send() -> None:
        bus = can.Bus(interface="virtual", channel=channel)
        frames = list(can_frames(200_000))
        k, start = 0, time.perf_counter()
        while not stop.is_set():
            # every frame due by now: a thread that waited for the GIL catches up at once
            due = int((time.perf_counter() - start) * rate)
            while k < due:
                fr = frames[k % len(frames)]
                k += 1
                bus.send(can.Message(arbitration_id=fr.arbitration_id, data=fr.data))
            sent[0] = k
            time.sleep(0.001)
        bus.shutdown()

    app = Eg2ScopeApp(live_plan(live_args(), [tap], {}, None))
    async with app.run_test(size=(200, 50)) as pilot:
        frames = app.frames
        painted: list[float] = []  # when the cursor's row was last painted
        render_line = frames.render_line

        def spy(y: int) -> Any:
            if frames.scroll_offset.y + y == frames.cursor:
                painted.append(time.perf_counter())
            return render_line(y)

        frames.render_line = spy  # type: ignore[method-assign]
        sender = threading.Thread(target=send, daemon=True)
        c0, w0 = time.process_time(), time.perf_counter()
        sender.start()
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
        stop.set()
        count, dropped, captured = app.store.count, app.dropped, app.captured
        await pilot.press("q")
    lags.sort()
    print(
        f"live {rate:,}/s for {seconds:.0f} s: {count:,} records ({count / wall:,.0f}/s), "
        f"{sent[0]:,} sent, {captured:,} taken by the session, {dropped:,} dropped, "
        f"CPU {cpu:.0%} of one core (sender included), key answered in median "
        f"{lags[len(lags) // 2] * 1000:.0f} ms, max {lags[-1] * 1000:.0f} ms"
    )


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("what", choices=("capture", "live"))
    parser.add_argument("--records", type=int, default=1_000_000)
    parser.add_argument("--seconds", type=float, default=60)
    parser.add_argument("--rate", type=int, default=20_000)
    args = parser.parse_args()
    if args.what == "capture":
        asyncio.run(bench_capture(args.records))
    else:
        asyncio.run(bench_live(args.seconds, args.rate))


if __name__ == "__main__":
    main()
