"""``eg2scope decode FILE``: decode a capture into text, JSONL or CSV."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from ..sinks.csv import CsvSink
from ..sinks.jsonl import JsonlSink
from ..sinks.text import TextSink
from .common import add_input_arguments, decoded_batches

FORMATS = ("text", "jsonl", "csv")


def add_subparser(sub: Any) -> None:
    parser = sub.add_parser(
        "decode",
        help="decode a capture file into text, JSONL or CSV",
        description=(
            "Decode a capture into one line per frame: time, bus, direction, device, command "
            "and decoded values with units, with checksum/CRC errors and warnings. Every input "
            "byte appears in a record: bytes that belong to no frame come out as 'garbage', a "
            "frame cut off by the end of the file as 'truncated'."
        ),
        epilog=(
            "examples:\n"
            "  eg2scope decode captures/can_pick_place.log\n"
            "  eg2scope decode dump.bin --protocol modbus --format jsonl > out.jsonl\n"
            "  eg2scope decode capture.blf --device 2 --errors-only"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_input_arguments(parser)
    parser.add_argument(
        "--format",
        "-f",
        choices=FORMATS,
        default="text",
        help="text: for people (default); jsonl: one JSON record per line, the stable "
        "contract for other programs; csv: for spreadsheets",
    )
    parser.add_argument("--output", "-o", metavar="PATH", help="write to PATH instead of stdout")
    parser.add_argument(
        "--absolute-time", action="store_true", help="text: show capture timestamps, not "
        "seconds since the first record"
    )  # fmt: skip
    parser.add_argument(
        "--colour", "--color", choices=("auto", "always", "never"), default="auto",
        help="text: colour errors and warnings (default: when writing to a terminal)",
    )  # fmt: skip
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    binary = args.format == "jsonl"
    if args.output:
        out: Any = open(args.output, "wb" if binary else "w", newline="" if not binary else None)
    else:
        out = sys.stdout.buffer if binary else sys.stdout
    sink: Any
    if args.format == "jsonl":
        sink = JsonlSink(out)
    elif args.format == "csv":
        sink = CsvSink(out)
    else:
        colour = {"always": True, "never": False}.get(args.colour)
        if args.output and colour is None:
            colour = False
        sink = TextSink(out, colour=colour, absolute_time=args.absolute_time)
    try:
        for batch in decoded_batches(args):
            sink.write(batch)
    finally:
        sink.close()
        if args.output:
            out.close()
    return 0
