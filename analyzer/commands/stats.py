"""``eg2scope stats FILE``: per-device and per-command counts, errors, latency, warnings, and
each bus's health."""

from __future__ import annotations

import argparse
import sys
from typing import Any

import orjson
from rich.console import Console
from rich.table import Table

from decoders.flags import DESCRIPTIONS

from ..cycles.listener import CyclesListener
from ..cycles.summary import CycleSummary
from ..health.listener import HealthListener
from ..health.rates import rates_of_capture
from ..health.table import print_health
from ..session.capture import finish_capture, open_reader, run_capture
from ..sinks.stats import StatsListener
from ..stats import COUNT_NAMES
from .common import add_input_arguments, add_rate_arguments, capture_options, rate_options
from .helptext import FILE_EXIT_STATUS, HelpFormatter


def add_subparser(sub: Any) -> None:
    parser = sub.add_parser(
        "stats",
        help="summarise a capture: counts, errors, latency, warnings, bus health",
        description=(
            "Summarise a capture: frames per device and per command, unanswered requests, "
            "errors (checksum, CRC, garbage, truncation), response latency p50/p95/max, the "
            "warnings raised by the manual's rules, and notable patterns such as ID scans. "
            "Then each bus's health: CAN load from the exact bits of every frame (stuff bits "
            "included) per second (mean, p95, max), frames/s, error frames by class with "
            "error-passive and bus-off periods; a serial line's use at its baud (10 bits a "
            "byte), the gaps between frames, Modbus frames closer than 3.5 characters, each "
            "gripper's turnaround, and a hint when a USB adapter's latency timer shows in the "
            "read times. A capture without times (a raw dump) gets counts only. Last, per "
            "gripper its grip cycles: their outcomes and the percentiles of their times (see "
            "'eg2scope cycles')."
        ),
        epilog=FILE_EXIT_STATUS,
        formatter_class=HelpFormatter,
    )
    add_input_arguments(parser)
    add_rate_arguments(parser)
    parser.add_argument(
        "--format",
        "-f",
        choices=("text", "json"),
        default="text",
        help="text tables (default) or one JSON object",
    )
    parser.set_defaults(func=run)


def _ms(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}"


def run(args: argparse.Namespace) -> int:
    opts, rates = capture_options(args), rate_options(args)
    reader = open_reader(opts)
    listener = StatsListener()
    health = HealthListener(rates_of_capture(reader.metadata, rates.bitrate, rates.baud))
    cycles = CycleSummary()  # of every record: --device picks the grippers, below
    whole = [health, CyclesListener(cycles, opts.device)]
    session, reader = run_capture(opts, [listener], reader, whole=whole)
    code = finish_capture(opts.path, session, reader, opts)
    data = listener.stats.as_dict()
    data["buses"] = health.buses()
    data["cycles"] = cycles.as_list()
    if args.format == "json":
        sys.stdout.buffer.write(orjson.dumps(data, option=orjson.OPT_INDENT_2) + b"\n")
    else:
        print_tables(args.file, data)
    sys.stdout.flush()
    return code


def print_tables(path: str, data: dict[str, Any]) -> None:
    # a pipe or file gets the whole table, not one squeezed to 80 columns
    console = Console(highlight=False, width=None if sys.stdout.isatty() else 200)
    console.print(
        f"[bold]{path}[/]: {data['records']:,} records, {data['frames']:,} frames "
        f"({data['valid_frames']:,} valid), {data['garbage_bytes']:,} garbage bytes, "
        f"{data['truncated']} truncated"
        + (f", {data['duration_s']:.3f} s" if data["duration_s"] is not None else "")
    )
    for title, rows, key in (
        ("Devices", data["devices"], None),
        ("Commands", data["commands"], "name"),
    ):
        if not rows:
            continue  # an empty capture is said so once, on stderr
        table = Table(title=title, title_justify="left")
        for col in ("bus", "protocol", "device", *([key] if key else [])):
            table.add_column(col, no_wrap=True)
        for col in COUNT_NAMES:
            table.add_column(col, justify="right")
        for col in ("p50 ms", "p95 ms", "max ms"):
            table.add_column(col, justify="right")
        for row in rows:
            table.add_row(
                row["bus"],
                row["protocol"],
                str(row["device"]),
                *([row[key]] if key else []),
                *(str(row[c]) for c in COUNT_NAMES),
                _ms(row["p50_ms"]),
                _ms(row["p95_ms"]),
                _ms(row["max_ms"]),
            )
        console.print(table)
    if data["flags"]:
        console.print("[bold]Problems[/] (flag: records)")
        for code, n in data["flags"].items():
            console.print(f"  {n:>8,}  {code}: {DESCRIPTIONS.get(code, code)}", markup=False)
    if data["events"]:
        console.print("[bold]Source events[/]")
        for kind, n in data["events"].items():
            console.print(f"  {n:>8,}  {kind}", markup=False)
    print_health(console, data["buses"])
    for note in data["notes"]:
        console.print(f"[bold]Note:[/] {note}")
    if data["cycles"]:
        console.print(cycles_table(data["cycles"]))


def cycles_table(rows: list[dict[str, Any]]) -> Table:
    """Each gripper's grip cycles: outcomes, cycle time (command to the next), settle time."""
    table = Table(title="Grip cycles", title_justify="left")
    for col in ("bus", "device", "outcomes"):
        table.add_column(col, no_wrap=col != "outcomes")
    for col in ("cycles", "cycle p50 ms", "p95 ms", "max ms", "settle p50 ms", "p95 ms", "max ms"):
        table.add_column(col, justify="right")
    for row in rows:
        times = (row["duration"][k] for k in ("p50_ms", "p95_ms", "max_ms"))
        settle = (row["settle"][k] for k in ("p50_ms", "p95_ms", "max_ms"))
        outcomes = ", ".join(f"{name} {n}" for name, n in row["outcomes"].items())
        table.add_row(
            row["bus"], str(row["device"]), outcomes, str(row["cycles"]), *map(_ms, times),
            *map(_ms, settle),
        )  # fmt: skip
    return table
