"""The routes of ``eg2scope decode``, chosen in one function (``decode_capture``). Each route
writes byte-identical output (tests/native/ and tests/analyzer/ check it); they differ in speed:

1. the native core's own run, where it applies (native_run.open_for: a candump log or a raw
   dump on a regular file, no timed replay): ``_native.DecodeRun`` writes JSONL, CSV or text,
   ``_native.ArrowRun`` Parquet's columns;
2. parts on every idle core in Python, for large raw dumps and candump logs to JSONL or CSV
   (parallel.decode_in_parallel; ``--jobs``);
3. one session: on the native core's ``CanStage`` for CAN input and ``ByteStage`` for a raw
   dump (replayed with ``--speed``) where the core is built, else on the Python decoding stage
   (batches.session_engine, by ``CaptureOptions.engine``)."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import IO, Any

from ..errors import EXIT_INTERRUPTED, EXIT_OK
from ..outfile import output_stream
from ..sources.capture import CaptureReader
from . import native_run
from .capture import (
    CaptureOptions,
    DecodeOutput,
    finish_capture,
    raise_output_failure,
    report_empty,
    run_capture,
)
from .listener import Listener
from .parallel import JoinError, decode_in_parallel, resumed

# the output listener of the format, on an open stream (header: False when a CSV header was
# written already)
MakeOutput = Callable[[IO[Any], bool], Listener]


def decode_capture(
    opts: CaptureOptions, output: DecodeOutput, reader: CaptureReader, make_output: MakeOutput
) -> int:
    """Decode ``reader``'s capture into ``output`` by the first route that takes it (the
    module's docstring lists them); the exit code (docs/contracts.md)."""
    nrun = native_run.open_for(opts, output, reader)
    if nrun is not None:
        return _native_route(nrun, opts, output)
    with output_stream(output.path, binary=output.binary, inputs=[opts.path]) as out:
        resume = 0
        try:
            done = decode_in_parallel(opts, output.fmt, output.jobs, reader, out)
        except JoinError as exc:  # parts were written: go on in one piece where they end
            done, resume = None, exc.resume
        if done is not None:
            return done
        listener = make_output(out, not resume)
        if resume:
            listener = resumed(listener, resume)
        session, reader = run_capture(opts, [listener], reader)
        raise_output_failure(session, output.path)
    return finish_capture(opts.path, session, reader, opts)


def _native_route(nrun: Any, opts: CaptureOptions, output: DecodeOutput) -> int:
    with output_stream(output.path, binary=output.binary, inputs=[opts.path]) as out:
        code = native_run.decode(nrun, opts.path, out, output.path, opts.progress)
    if code == EXIT_INTERRUPTED:
        print("eg2scope: interrupted", file=sys.stderr)
    elif code == EXIT_OK:  # not damaged (the damage says why itself)
        report_empty(opts.path, nrun.size, nrun.records_written, opts.filter_words())
    return code
