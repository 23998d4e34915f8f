"""Fleet batch decoding: records per second with one and two Dask workers, and what Dask costs
over decoding the same files in one loop.

    python tests/benchmarks/bench_batch.py [--captures 100] [--frames 100000] [--runs 1]
                                           [--out bench-out]

Generates ``--captures`` captures of ``--frames`` frames each (candump logs, raw serial and raw
Modbus dumps in turn, realistic moving grippers), then runs the real CLI on the folder, each
time into a fresh dataset:
- ``loop``: ``eg2scope batch DIR -o D --workers 1`` (one process, no Dask);
- ``dask-1``: the same on a one-worker Dask LocalCluster started beforehand (``--scheduler``),
  with the settings of the cluster ``batch`` starts (``analyzer.fleet.runner.WORKER_CONFIG``);
- ``dask-2``: ``eg2scope batch DIR -o D --workers 2`` (the CLI's own two-worker LocalCluster,
  its start included).
Targets (issue 11): two workers at least 1.7 times one; Dask at most 10% slower than the loop.
The machine has two cores: a busy neighbour shows in every figure, so the ratios come from runs
made side by side, and the medians of ``--runs`` rounds.
"""

from __future__ import annotations

import argparse
import shutil
import statistics
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

MUST_SCALING = 1.7
MUST_OVERHEAD = 0.10
BATCH = [sys.executable, "-m", "analyzer", "batch", "--no-progress"]


def write_captures(folder: Path, count: int, frames: int) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i in range(count):
        kind = ("can", "serial", "modbus")[i % 3]
        path = folder / (f"cell{i:03d}.log" if kind == "can" else f"cell{i:03d}-{kind}.bin")
        paths.append(path)
        if path.exists():
            continue
        if kind == "can":
            t0 = 1_763_700_000.0 + i * 3600.0
            lines = (candump_line(f) for f in can_frames(frames, seed=i, t0=t0))
            path.write_text("\n".join(lines) + "\n")
        else:
            gen = serial_frames if kind == "serial" else modbus_frames
            path.write_bytes(b"".join(gen(frames, seed=i)))
    return paths


def records_in(summary: str) -> int:
    for line in summary.splitlines():
        if " records (" in line:
            return int(line.split(" records (")[0].replace(",", ""))
    raise AssertionError(f"no summary in {summary!r}")


def run_batch(folder: Path, dataset: Path, *options: str) -> tuple[float, int]:
    shutil.rmtree(dataset, ignore_errors=True)
    start = time.perf_counter()
    done = subprocess.run(
        [*BATCH, str(folder), "-o", str(dataset), *options],
        capture_output=True,
        text=True,
        cwd=ROOT,
        check=False,
    )
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"batch failed ({done.returncode}): {done.stderr}")
    return seconds, records_in(done.stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--captures", type=int, default=100)
    parser.add_argument("--frames", type=int, default=100_000)
    parser.add_argument("--runs", type=int, default=1)
    parser.add_argument("--out", type=Path, default=ROOT / "bench-out")
    args = parser.parse_args()

    import dask
    from dask.distributed import LocalCluster

    from analyzer.fleet.runner import WORKER_CONFIG

    folder = args.out / f"fleet_{args.captures}x{args.frames}"
    print(f"generating {args.captures} captures of {args.frames:,} frames in {folder} ...")
    write_captures(folder, args.captures, args.frames)
    dataset = args.out / "fleet-dataset"
    times: dict[str, list[float]] = {"loop": [], "dask-1": [], "dask-2": []}
    records = 0
    with (
        dask.config.set(WORKER_CONFIG),  # as the LocalCluster `eg2scope batch` starts
        LocalCluster(
            n_workers=1, threads_per_worker=1, host="127.0.0.1", dashboard_address=None
        ) as one,
    ):
        address = one.scheduler_address
        for run in range(args.runs):
            for name, options in (
                ("loop", ("--workers", "1")),
                ("dask-1", ("--scheduler", address)),
                ("dask-2", ("--workers", "2", "--dashboard-address", "none")),
            ):
                seconds, records = run_batch(folder, dataset, *options)
                times[name].append(seconds)
                print(
                    f"  run {run + 1} {name:7} {seconds:8.1f} s  {records / seconds:10,.0f} rec/s"
                )
    shutil.rmtree(dataset, ignore_errors=True)
    median = {name: statistics.median(t) for name, t in times.items()}
    print(f"\n{records:,} records per run; median of {args.runs}:")
    for name, seconds in median.items():
        print(f"  {name:7} {seconds:8.1f} s  {records / seconds:10,.0f} records/s")
    scaling = median["dask-1"] / median["dask-2"]
    overhead = median["dask-1"] / median["loop"] - 1
    ok_scaling = "ok" if scaling >= MUST_SCALING else f"MISSED (target >= {MUST_SCALING})"
    ok_overhead = "ok" if overhead <= MUST_OVERHEAD else f"MISSED (target <= {MUST_OVERHEAD:.0%})"
    print(f"two workers / one: {scaling:.2f}x  {ok_scaling}")
    print(f"Dask over the loop: {overhead:+.1%}  {ok_overhead}")


if __name__ == "__main__":
    main()
