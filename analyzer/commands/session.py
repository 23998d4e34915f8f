"""Running a live session from the command line: outputs, status line, clean ending."""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from decoders.model import Record
from decoders.registry import resolve_protocol

from .. import __version__
from ..live import LiveSession, OutputBase, SessionCounts
from ..outputs import JsonlOutput, McapOutput, TextOutput
from ..sources.live import Tap


def add_session_arguments(parser: argparse.ArgumentParser, record_required: bool) -> None:
    parser.add_argument(
        "--output",
        "-o",
        metavar="RUN.mcap",
        required=record_required,
        help="record raw input, decoded records, device state and events to this MCAP file",
    )
    parser.add_argument(
        "--duration",
        type=float,
        metavar="S",
        help="stop after S seconds (default: run until Ctrl-C)",
    )
    parser.add_argument(
        "--queue-size",
        type=int,
        default=200_000,
        metavar="N",
        help="items buffered between capture and decoding before drops are "
        "counted (default 200000)",
    )


class StatusLine(OutputBase):
    """A one-line status on stderr, refreshed twice a second (terminals only)."""

    def __init__(self, session: LiveSession, label: str) -> None:
        self.session = session
        self.label = label
        self._next = 0.0

    def records(self, records: list[Record]) -> None:
        pass

    def tick(self) -> None:
        now = time.monotonic()
        if now < self._next:
            return
        self._next = now + 0.5
        sys.stderr.write(f"\r\x1b[2K{self.label}: {self.session.counts.line()}")
        sys.stderr.flush()

    def close(self) -> None:
        sys.stderr.write("\r\x1b[2K")
        sys.stderr.flush()


def metadata(args: argparse.Namespace, taps: list[Tap]) -> dict[str, Any]:
    return {
        "tool": "eg2scope",
        "version": __version__,
        "command": " ".join(sys.argv),
        "sources": [
            {"bus": t.bus, "type": type(t).__name__, "passive": t.passive, **t.settings}
            for t in taps
        ],
        "passive": (
            "yes"
            if all(t.passive == "yes" for t in taps)
            else "no"
            if any(t.passive == "no" for t in taps)
            else "unknown"
        ),
    }


def run_session(
    args: argparse.Namespace,
    taps: list[Tap],
    show: str | None = "text",
    status: bool = False,
    extra_outputs: list[Any] | None = None,
    per_bus: dict[str, str] | None = None,
    on_start: Callable[[], None] | None = None,
) -> int:
    protocol = None if args.protocol in (None, "auto") else resolve_protocol(args.protocol)
    outputs: list[Any] = list(extra_outputs or [])
    if show == "text":
        outputs.append(TextOutput())
    elif show == "jsonl":
        outputs.append(JsonlOutput())
    recorder = None
    if args.output:
        from ..sinks.mcap import McapRecorder

        path = Path(args.output)
        if path.suffix.lower() != ".mcap":
            raise ValueError(f"recordings are MCAP files: name the output *.mcap, not {path}")
        recorder = McapRecorder(path, metadata=metadata(args, taps))
        outputs.append(McapOutput(recorder))
    session = LiveSession(
        taps, outputs, protocol=protocol, queue_size=args.queue_size, per_bus=per_bus
    )
    if status and show is None:
        outputs.append(StatusLine(session, f"recording {args.output}"))
    counts: SessionCounts = session.run(duration=args.duration, on_start=on_start)
    where = f" into {args.output}" if args.output else ""
    print(f"eg2scope: {counts.line()}{where}", file=sys.stderr)
    return 0
