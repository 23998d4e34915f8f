"""What bus health and grip cycles cost: issue 20's speed target, on the decode benchmark's
1M-frame inputs (a raw serial dump, a raw Modbus RTU dump, a candump -L log; see
bench_decode.py).

    python tests/benchmarks/bench_cell.py [--frames 1000000] [--runs 3] [--clock cpu|wall]
                                          [--out bench-out] [--protocols serial,modbus,can]

Per input, the real CLI in a subprocess, the runs interleaved (run 1 of every case, then run 2,
...) so a noisy neighbour hits every case alike:

  (a) decode   ``decode --format jsonl --engine native --jobs 1 -o FILE``: the decode
               benchmark's own command, the baseline;
  (b) stats    ``stats --format json`` as users run it: health and cycles included;
  (c) bare     the same ``stats`` with the health and cycles listeners replaced by inert ones
               that want nothing (no raw items, no states: what the session does only for
               them, such as the Tracker's samples, counts as theirs); this file run as
               ``bench_cell.py --bare-stats ARGS...``: the real CLI's ``main`` in its own
               process, nothing added to the product for it;
  (d) cycles   ``cycles --format jsonl -o FILE``;
  (e) cycles/10 the same on a tenth of the frames (the same traffic, ``--frames`` / 10).

``stats`` and ``cycles`` run with the engine ``auto``: the native core's session on all three
(``CanStage`` for CAN, ``ByteStage`` for a raw dump's one byte stream, then the native
``Tracker`` and ``CycleSegmenter``). ``decode --engine native`` runs the native core's own
whole-file run on all three.

"Health and cycles add at most 20% to the 1M-frame decode benchmarks on the native engine"
is measured as two ratios over (a), the decode benchmark's time on the same input (``--clock``:
CPU seconds, user + system of all threads, or wall seconds), each the median of its value in
each run (the cases of a run ran back to back, so a neighbour's load that slows a run slows both
sides of its ratio alike; the difference of two medians of stats' seconds, most of them spent
alike in (b) and (c), is at the mercy of that noise):

  health+cycles in stats  ((b) - (c)) / (a)   the time stats spends on them, per decode;
  cycles                  (d) / (a) - 1       what finding the cycles costs beyond decoding
                                              the same frames (it must decode them too).

Each must be <= 20%. "Memory stays flat": what health and cycles hold does not grow: the peak
RSS of (b) at most ``FLAT_MB`` over (c)'s (the same command without them), and of (d) at most
``FLAT_MB`` over (e)'s (ten times the frames, no more memory). (d)'s peak over (a)'s is shown
too, not judged: it is the cycles command's fixed footprint (python-can, whose options it takes
for live sources, and the simulator for ``--demo``), the same at any input size. The bench
prints PASS or FAIL per input and exits 1 on any FAIL. On a shared machine use ``--clock cpu``:
it does not depend on the neighbours (and the minimum of several runs less than the median).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

from bench_decode import timed, write_inputs  # noqa: E402

MUST_ADD = 0.20  # of the decode benchmark's time
FLAT_MB = 8.0  # "memory stays flat": this much above the run without health and cycles
CASES = ("decode", "stats", "bare", "cycles", "cycles/10")
PROTOCOL_ARGS = {"serial": ["--protocol", "serial"], "modbus": ["--protocol", "modbus"], "can": []}


def commands(path: Path, tenth: Path, proto: str, sink: Path) -> dict[str, list[str]]:
    """The five commands on one input (``tenth``: its first tenth)."""
    eg2 = [sys.executable, "-m", "analyzer"]
    common = [*PROTOCOL_ARGS[proto], "--no-progress", str(path)]
    stats = ["stats", "--format", "json", *common]
    return {
        "decode": [*eg2, "decode", "--format", "jsonl", "--engine", "native", "--jobs", "1",
                   "-o", str(sink), *common],
        "stats": [*eg2, *stats],
        "bare": [sys.executable, str(Path(__file__).resolve()), "--bare-stats", *stats],
        "cycles": [*eg2, "cycles", "--format", "jsonl", "-o", str(sink), *common],
        "cycles/10": [*eg2, "cycles", "--format", "jsonl", "-o", str(sink),
                      *PROTOCOL_ARGS[proto], "--no-progress", str(tenth)],
    }  # fmt: skip


def bare_stats(argv: list[str]) -> int:
    """``eg2scope ARGV`` (a stats command) with the health and cycles listeners inert."""
    from analyzer import cli
    from analyzer.commands import stats
    from analyzer.session.listener import Listener

    class Inert(Listener):
        """Takes what the session gives, does nothing with it."""

        def __init__(self, *args: object, **kwargs: object) -> None:
            self.label = "inert"

        def on_records(self, records: object) -> None:
            pass

        def buses(self) -> list[object]:
            return []

    # wanting nothing, as if they were not there: what the session does for them is theirs
    stats.HealthListener = Inert  # type: ignore[misc,assignment]
    stats.CyclesListener = Inert  # type: ignore[misc,assignment]
    return cli.main(argv)


def run_all(
    paths: dict[str, Path], tenths: dict[str, Path], protos: list[str], runs: int, sink: Path
) -> dict:
    """{(proto, case): [(wall, cpu, mb), ...]}, the runs interleaved over every case."""
    cmds = {
        (proto, case): cmd
        for proto in protos
        for case, cmd in commands(paths[proto], tenths[proto], proto, sink).items()
    }
    found: dict[tuple[str, str], list[tuple[float, float, float]]] = {key: [] for key in cmds}
    for i in range(runs):
        for key, cmd in cmds.items():
            found[key].append(timed(cmd, sink))
        print(f"run {i + 1} of {runs} done", flush=True)
    sink.unlink(missing_ok=True)
    return found


def report(found: dict, protos: list[str], clock: str) -> bool:
    pick = 0 if clock == "wall" else 1
    ok = True
    for proto in protos:
        med = {c: statistics.median(r[pick] for r in found[(proto, c)]) for c in CASES}
        rss = {c: max(r[2] for r in found[(proto, c)]) for c in CASES}
        print(f"{proto}:")
        for case in CASES:
            each = ", ".join(f"{r[pick]:.2f}" for r in found[(proto, case)])
            print(f"  {case:9} {med[case]:6.2f} {clock}-s  (runs: {each})  peak RSS "
                  f"{rss[case]:.0f} MB")  # fmt: skip
        # per run (its cases ran back to back), then the median: a neighbour's load that
        # slows one run slows both sides of its ratio
        runs = list(zip(*(found[(proto, c)] for c in CASES[:4]), strict=True))
        in_stats = statistics.median((s[pick] - b[pick]) / d[pick] for d, s, b, _ in runs)
        in_cycles = statistics.median(c[pick] / d[pick] - 1 for d, _, _, c in runs)
        flat = rss["stats"] - rss["bare"] <= FLAT_MB and rss["cycles"] - rss["cycles/10"] <= FLAT_MB
        good = in_stats <= MUST_ADD and in_cycles <= MUST_ADD and flat
        ok &= good
        print(
            f"  stats/bare {med['stats'] / med['bare']:.2f}x, cycles/decode "
            f"{med['cycles'] / med['decode']:.2f}x; health+cycles in stats add "
            f"{in_stats:+.0%} of decode, cycles adds {in_cycles:+.0%}; RSS stats-bare "
            f"{rss['stats'] - rss['bare']:+.0f} MB, cycles at 10x the frames "
            f"{rss['cycles'] - rss['cycles/10']:+.0f} MB (cycles-decode "
            f"{rss['cycles'] - rss['decode']:+.0f} MB, not judged)  "
            f"[must <= {MUST_ADD:.0%}, <= {FLAT_MB:g} MB: {'PASS' if good else 'FAIL'}]"
        )
    return ok


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == "--bare-stats":
        return bare_stats(sys.argv[2:])
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--frames", type=int, default=1_000_000)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--out", type=Path, default=ROOT / "bench-out")
    ap.add_argument("--protocols", default="serial,modbus,can", help="comma-separated inputs")
    ap.add_argument("--clock", choices=("wall", "cpu"), default="wall", help="what a second is")
    args = ap.parse_args()
    t = time.perf_counter()
    paths = write_inputs(args.out, args.frames)
    tenths = write_inputs(args.out, args.frames // 10)
    print(f"inputs ready in {time.perf_counter() - t:.1f} s under {args.out}", flush=True)
    protos = [p for p in args.protocols.split(",") if p]
    found = run_all(paths, tenths, protos, args.runs, args.out / "cell-out.jsonl")
    return 0 if report(found, protos, args.clock) else 1


if __name__ == "__main__":
    sys.exit(main())
