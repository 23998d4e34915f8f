"""``eg2scope decode FILE``: decode a capture into text, JSONL or CSV."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from decoders.model import EG2_SERIAL

from ..sinks.csv import CsvSink
from ..sinks.jsonl import JsonlSink
from ..sinks.text import TextSink
from ..sources.pacing import parse_speed
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
        "--jobs",
        "-j",
        type=int,
        default=0,
        metavar="N",
        help="decode large raw dumps and candump logs in N processes (default: one per core; "
        "1: in one piece). The output is the same either way.",
    )
    parser.add_argument(
        "--absolute-time",
        action="store_true",
        help="text: show capture timestamps, not seconds since the first record",
    )
    parser.add_argument(
        "--colour",
        "--color",
        choices=("auto", "always", "never"),
        default="auto",
        help="text: colour errors and warnings (default: when writing to a terminal)",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    binary = args.format == "jsonl"
    if args.output:
        # closed in the finally below, after the sink is flushed
        out: Any = open(args.output, "wb" if binary else "w", newline="" if not binary else None)  # noqa: SIM115
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
        if not _decoded_in_parallel(args, sink, out):
            for batch in decoded_batches(args):
                sink.write(batch)
    finally:
        sink.close()
        if args.output:
            out.close()
    return 0


def _decoded_in_parallel(args: argparse.Namespace, sink: Any, out: Any) -> bool:
    """Large raw dumps and candump logs, to JSONL or CSV: decode on every core. False when
    the file is not split (the caller decodes in one piece)."""
    from pathlib import Path

    from decoders.registry import detect_protocol

    from ..parallel import JoinError, reader_kind, run_parallel, splittable
    from ..sources.capture import open_capture
    from .common import progress_bar, protocol_of

    if parse_speed(args.speed) is not None or args.jobs == 1:
        return False
    path = Path(args.file)
    with open_capture(path, bus=args.bus) as reader:
        kind = reader_kind(reader)
        if not kind or not splittable(path, args.format, kind):
            return False
        protocol = protocol_of(args)
        if kind == "bytes" and protocol is None:
            with path.open("rb") as f:
                protocol = detect_protocol(f.read(4096)) or EG2_SERIAL
        binary = out if args.format == "jsonl" else out.buffer
        sink.out.flush()
        with progress_bar(reader, not args.no_progress) as tick:

            def progress(done: int, size: int) -> None:
                reader.position = done
                tick(0)

            try:
                run_parallel(path, kind, args, protocol, binary, progress, jobs=args.jobs)
            except JoinError as exc:
                print(f"eg2scope: decoding {path.name} in one piece ({exc})", file=sys.stderr)
                return False
        binary.flush()
    return True
