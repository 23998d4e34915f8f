"""``eg2scope decode FILE``: decode a capture into text, JSONL, CSV or Parquet."""

from __future__ import annotations

import argparse
import dataclasses
import os
import stat
import sys
from typing import IO, Any

from ..errors import UsageError
from ..session.capture import DecodeOutput, open_reader, protocol_hint
from ..session.engine import ENGINES
from ..session.listener import Listener, make_listener
from .common import add_input_arguments, capture_options, non_negative_int
from .helptext import FILE_EXIT_STATUS, HelpFormatter, epilog

FORMATS = ("text", "jsonl", "csv", "parquet")
BINARY = ("jsonl", "parquet")


def add_subparser(sub: Any) -> None:
    parser = sub.add_parser(
        "decode",
        help="decode a capture file into text, JSONL, CSV or Parquet",
        description=(
            "Decode a capture into one line per frame: time, bus, direction, device, command "
            "and decoded values with units, with checksum/CRC errors and warnings. Every input "
            "byte appears in a record: bytes that belong to no frame come out as 'garbage', a "
            "frame cut off by the end of the file as 'truncated'."
        ),
        epilog=epilog(
            "examples:\n"
            "  eg2scope decode captures/can_pick_place.log\n"
            "  eg2scope decode dump.bin --protocol modbus --format jsonl > out.jsonl\n"
            "  eg2scope decode capture.blf --device 2 --errors-only",
            FILE_EXIT_STATUS,
        ),
        formatter_class=HelpFormatter,
    )
    add_input_arguments(parser)
    parser.add_argument(
        "--format",
        "-f",
        choices=FORMATS,
        default="text",
        help="text: for people (default); jsonl: one JSON record per line, the stable "
        "contract for other programs; csv: for spreadsheets; parquet: typed columns for "
        "pandas, polars and DuckDB (needs -o FILE, or stdout to a file or pipe)",
    )
    parser.add_argument(
        "--output",
        "-o",
        metavar="PATH",
        help="write to PATH instead of stdout (written under a temporary name and renamed "
        "when done, replacing a PATH that is there, as a compiler replaces its output; never "
        "the input file)",
    )
    parser.add_argument(
        "--jobs",
        "-j",
        type=non_negative_int,
        default=0,
        metavar="N",
        help="Python engine: decode large raw dumps and candump logs in N processes (default "
        "0: every idle core; 1: in one piece). The output is the same either way. The native "
        "core decodes in one process, faster than the parts.",
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
    parser.add_argument(
        "--engine",
        choices=ENGINES,
        default="auto",
        help="auto: the native core where it applies (candump logs and raw dumps to jsonl, "
        "csv, text or parquet, byte-identical output; other CAN captures, and raw dumps "
        "replayed with --speed, are read in Python and decoded natively), else Python "
        "(default); python: the Python decoders (and "
        "--jobs); native: the native core, a usage error where it cannot be used. "
        "'eg2scope --version' says whether the native core is built",
    )
    parser.set_defaults(func=run)


def make_output(args: argparse.Namespace, out: IO[Any], header: bool = True) -> Listener:
    """The output listener of ``--format``, found by name in the listener registry
    (``header``: False when a CSV header was written already)."""
    if args.format == "csv":
        return make_listener("csv", out, header=header)
    if args.format != "text":
        return make_listener(args.format, out)
    colour = text_colour(args)
    return make_listener("text", out, colour=colour, absolute_time=args.absolute_time)


def text_colour(args: argparse.Namespace) -> bool | None:
    """--colour: True, False, or None (decided by the output: a terminal or not)."""
    colour = {"always": True, "never": False}.get(args.colour)
    if args.output and colour is None:
        colour = False
    return colour


def run(args: argparse.Namespace) -> int:
    to_terminal = to_a_terminal(args.output)
    if args.format == "parquet" and to_terminal:
        raise UsageError(
            "--format parquet writes a binary file, not to a terminal: give -o FILE.parquet"
        )
    opts = capture_options(args)
    if to_terminal:  # the records scrolling by show the progress; a bar would cut into them
        opts = dataclasses.replace(opts, progress=False)
    reader = open_reader(opts)  # opened first: a missing input must not touch the output
    hint = protocol_hint(opts, reader)
    if hint:
        print(f"eg2scope: {opts.path}: {hint}", file=sys.stderr)
    output = DecodeOutput(
        args.format, args.output, text_colour(args), args.absolute_time, args.jobs
    )
    from ..session.decode_routes import decode_capture  # parts' multiprocessing: when used

    return decode_capture(
        opts, output, reader, lambda out, header: make_output(args, out, header=header)
    )


def to_a_terminal(output: str | None) -> bool:
    """Whether the output goes to a terminal: stdout (no ``-o``, or ``-o -``) that is one, or
    ``-o`` naming one (``/dev/tty``, ``/dev/stdout`` on a terminal)."""
    if output in (None, "-"):
        return sys.stdout.isatty()
    try:
        if not stat.S_ISCHR(os.stat(output).st_mode):
            return False
        fd = os.open(output, os.O_WRONLY | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError:
        return False  # not there yet (a new file), or not ours to open: not a terminal
    try:
        return os.isatty(fd)
    finally:
        os.close(fd)
