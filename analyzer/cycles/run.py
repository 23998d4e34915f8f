"""``eg2scope cycles``'s run: the grip cycles of a capture, of live sources or of the demo, to
text, JSONL, CSV or Parquet (``CyclesOptions``, typed: the core never sees argparse)."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import IO, Any

from ..errors import UsageError
from ..live_runner import LiveOptions, check_live_engine, run_demo, run_session
from ..outfile import output_stream
from ..session.batches import session_engine
from ..session.capture import (
    CaptureOptions,
    finish_capture,
    open_reader,
    raise_output_failure,
    run_capture,
)
from ..sim.demo_options import DemoOptions
from ..sources.source import live_kind
from ..sources.tap_options import TapOptions, make_taps
from .listener import CyclesListener
from .outputs import BINARY, FORMATS, CsvCycles, CycleOutput, JsonlCycles, TextCycles


@dataclass(frozen=True)
class CyclesOptions:
    """What ``eg2scope cycles`` reads and writes. ``fmt``: text, jsonl, csv or parquet;
    ``output``: the file (None or "-": stdout); ``device``: only that gripper's cycles;
    ``capture``: the capture to read (None: live); ``live``, ``taps``, ``demo``: the live
    session's options, its sources, or the demo instead of them."""

    fmt: str
    output: str | None
    device: int | None
    live: LiveOptions
    taps: TapOptions
    capture: CaptureOptions | None = None
    demo: DemoOptions | None = None


def cycles(opts: CyclesOptions) -> int:
    """The cycles of what the options name: a capture, or one live source (the demo, or taps);
    the exit status (docs/contracts.md)."""
    live = opts.demo is not None or opts.taps.given
    if opts.capture is not None and live:
        raise UsageError("give a capture file or a live source (or --demo), not both")
    if opts.capture is None and not live:
        raise UsageError(
            "no cycles to find: give a capture file, a live source (-i/-c, --serial PORT) or "
            "--demo (see --help)"
        )
    if opts.capture is not None:
        return capture_cycles(opts, opts.capture)
    return live_cycles(opts)


def capture_cycles(opts: CyclesOptions, capture: CaptureOptions) -> int:
    reader = open_reader(capture)  # opened first: a missing input must not touch the output
    try:
        session_engine(capture.engine, reader.kind, reader.single_stream)
    except ValueError as exc:
        reader.close()
        raise UsageError(f"--engine {capture.engine}: {exc}") from None
    with output_stream(opts.output, opts.fmt in BINARY, inputs=[capture.path]) as out:
        listener = CyclesListener(make_output(opts.fmt, out), opts.device)
        session, reader = run_capture(capture, [listener], reader)
        raise_output_failure(session, opts.output)
    code = finish_capture(capture.path, session, reader)
    if session.counts.records and not listener.count and not session.counts.interrupted:
        which = f"of device {opts.device} " if opts.device is not None else ""
        print(
            f"eg2scope: {capture.path}: no grip cycles {which}in this capture (no motion "
            "command: catch, release, seek or a target opening written)",
            file=sys.stderr,
        )
    return code


def live_cycles(opts: CyclesOptions) -> int:
    """The cycles of a live session, each written as it ends."""
    taps = None  # usage errors first, before anything is opened or written
    if opts.demo is not None:
        check_live_engine(opts.live.engine, opts.demo.kind)
    else:
        taps = make_taps(opts.taps)
        check_live_engine(opts.live.engine, live_kind(taps))
    with output_stream(opts.output, opts.fmt in BINARY) as out:
        listener = CyclesListener(make_output(opts.fmt, out), opts.device)
        if opts.demo is not None:
            return run_demo("cycles", opts.demo, opts.live, show=None, extra=[listener])
        assert taps is not None
        return run_session(opts.live, taps, show=None, extra=[listener])


def make_output(fmt: str, out: IO[Any]) -> CycleOutput:
    """The output of ``fmt`` on an open stream (binary for jsonl and parquet)."""
    if fmt == "jsonl":
        return JsonlCycles(out)
    if fmt == "csv":
        return CsvCycles(out)
    if fmt == "parquet":
        from .parquet import ParquetCycles  # pyarrow: only when asked for

        return ParquetCycles(out)
    if fmt == "text":
        return TextCycles(out)
    raise ValueError(f"unknown cycles format {fmt!r}; choose one of {', '.join(FORMATS)}")
