"""``eg2scope decode FILE``: decode a capture into text, JSONL or CSV."""

from __future__ import annotations

import argparse
from typing import IO, Any

from ..listener import Listener, make_listener
from ..outfile import OutputError, output_stream
from ..session import Session
from .common import (
    CaptureOptions,
    add_input_arguments,
    finish_capture,
    non_negative_int,
    open_reader,
    run_capture,
)

FORMATS = ("text", "jsonl", "csv")
EXIT_CODES = (
    "exit status: 0 decoded; 1 error (a file that cannot be read or written); 2 usage error; "
    "3 decoded as far as possible, but the input is damaged (see the messages on stderr); "
    "130 interrupted"
)


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
            "  eg2scope decode capture.blf --device 2 --errors-only\n\n" + EXIT_CODES
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
    parser.add_argument(
        "--output",
        "-o",
        metavar="PATH",
        help="write to PATH instead of stdout (written under a temporary name and renamed "
        "when done; never the input file)",
    )
    parser.add_argument(
        "--jobs",
        "-j",
        type=non_negative_int,
        default=0,
        metavar="N",
        help="decode large raw dumps and candump logs in N processes (default 0: one per "
        "core; 1: in one piece). The output is the same either way.",
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


def make_output(args: argparse.Namespace, out: IO[Any]) -> Listener:
    """The output listener of ``--format``, found by name in the listener registry."""
    if args.format != "text":
        return make_listener(args.format, out)
    colour = {"always": True, "never": False}.get(args.colour)
    if args.output and colour is None:
        colour = False
    return make_listener("text", out, colour=colour, absolute_time=args.absolute_time)


def run(args: argparse.Namespace) -> int:
    opts = CaptureOptions.from_args(args)
    reader = open_reader(opts)  # opened first: a missing input must not touch the output
    with output_stream(args.output, binary=args.format == "jsonl", inputs=[opts.path]) as out:
        from ..parallel import decode_in_parallel

        done = decode_in_parallel(opts, args.format, args.jobs, reader, out)
        if done is not None:
            return done
        listener = make_output(args, out)
        session, reader = run_capture(opts, [listener], reader)
        raise_output_failure(session, args.output)
    return finish_capture(opts.path, session, reader)


def raise_output_failure(session: Session, path: str | None) -> None:
    """The output listener was detached: fail (a file that was there before is kept)."""
    if not session.detached:
        return
    exc = session.detached[0][1]
    if isinstance(exc, BrokenPipeError):
        raise exc  # `| head`: the reader went away; the CLI stops quietly
    raise OutputError(f"cannot write {path or 'the output'}: {exc}")
