"""The native core's offline run of ``eg2scope decode``: opened where it applies (``open_for``,
the core's own capture reader and writers: JSONL, CSV, text or Parquet's Arrow columns), and
written out with the Python engine's progress bar, damage reports and exit codes (``decode``).
Which route decodes a capture is chosen in analyzer/session/decode_routes.py."""

from __future__ import annotations

import codecs
import io
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

from ..errors import EXIT_DAMAGED, EXIT_INTERRUPTED, EXIT_OK, UsageError
from ..outfile import OutputError
from ..sources.capture import CaptureReader
from .batches import native_input, native_session_available
from .capture import CaptureOptions, DecodeOutput, ProgressListener, byte_protocol
from .engine import _native, ineligible
from .session import signals_as_interrupt


def open_for(opts: CaptureOptions, output: DecodeOutput, reader: CaptureReader) -> Any:
    """The native run of ``eg2scope decode`` with these options (``opts.engine``: auto where
    eligible; native or a UsageError saying why not), or None: the Python engine decodes. The
    Python ``reader`` (opened first, for the same checks and messages) is closed when the native
    core takes over."""
    if opts.engine == "python":
        return None
    try:
        why = ineligible(reader, output.fmt, opts.speed, opts.device)
        if not why and output.fmt != "jsonl" and output.path in (None, "-"):
            why = _text_stdout_differs()
        if why:
            if opts.engine == "native" and not _session_decodes(reader):
                raise UsageError(f"--engine native: {why}; use --engine python or auto")
            return None  # the Python engine, or the session's native CAN decoding
        colour = output.colour
        if colour is None:  # stdout: coloured as the text listener would decide
            from ..sinks.text import use_colour

            colour = use_colour(sys.stdout)
        assert _native is not None  # ineligible() said so
        try:
            run = open_run(opts, output.fmt, colour and output.fmt == "text", output.absolute_time)
        except _native.Unsupported as exc:  # the core's own word: only Python reads this
            if opts.engine == "native" and not _session_decodes(reader):
                raise UsageError(f"--engine native: {exc}; use --engine python or auto") from None
            run = None
        if run is None and opts.engine == "native" and not _session_decodes(reader):
            raise UsageError(f"--engine native: the native core does not support {opts.path}")
    except BaseException:
        reader.close()
        raise
    if run is not None:
        reader.close()
    return run


def _session_decodes(reader: CaptureReader) -> bool:
    """Whether the session decodes this capture natively when the core's own decode cannot:
    CAN frames read in Python, a raw dump replayed with --speed (analyzer/session/batches.py
    `session_engine`)."""
    return native_input(reader.kind, reader.single_stream) and native_session_available()


def _text_stdout_differs() -> str:
    """Why text written to stdout would not come out as the native core's UTF-8 bytes ("" when
    it would): the Python engine writes through sys.stdout's own encoding."""
    encoding = getattr(sys.stdout, "encoding", None) or "utf-8"
    try:
        utf8 = codecs.lookup(encoding).name == "utf-8"
    except LookupError:
        utf8 = False
    if not utf8:
        return f"stdout is {encoding}, not UTF-8"
    return ""


def open_run(opts: CaptureOptions, fmt: str, colour: bool, absolute_time: bool) -> Any:
    """A native decode (iterate it for output bytes). ``_native.Unsupported`` when the core
    does not handle this input (the Python engine decodes it); OSError: it cannot be opened."""
    assert _native is not None
    if fmt == "parquet":  # records as Arrow columns (parquet/native.py)
        from ..parquet.native import open_run as open_arrow_run

        return open_arrow_run(
            _native,
            opts.path,
            protocol=byte_protocol(opts),
            bus=opts.bus or None,
            device=opts.device,
            errors_only=opts.errors_only,
        )
    return _native.DecodeRun(
        opts.path,
        fmt,
        protocol=byte_protocol(opts),
        bus=opts.bus or None,  # the readers treat --bus "" as no --bus (`bus or "serial"`)
        device=opts.device,
        errors_only=opts.errors_only,
        colour=colour,
        absolute_time=absolute_time,
    )


class _RunReader:
    """What the progress bar reads of a capture reader, from a native run."""

    def __init__(self, path: str, run: Any) -> None:
        self.path = Path(path)
        self.run = run
        self.size = run.size

    @property
    def position(self) -> int:
        return int(self.run.position)


@contextmanager
def _progress(path: str, run: Any, show: bool) -> Iterator[Any]:
    """The Python engine's progress bar (capture.ProgressListener), on terminals."""
    if not (show and sys.stderr.isatty()):
        yield None
        return
    bar = ProgressListener(_RunReader(path, run))  # type: ignore[arg-type]
    try:
        yield bar
    finally:
        bar.close()


def decode(run: Any, path: str, out: IO[Any], output_name: str | None, progress: bool) -> int:
    """Write a native run's output into ``out`` (a binary stream, or a text stream whose buffer
    takes the bytes); report damage on stderr; the exit code, as capture.finish_capture
    gives it for the Python engine."""
    assert _native is not None  # a native run: the core is built
    binary: IO[bytes] = out
    if isinstance(out, io.TextIOBase):
        out.flush()  # anything written as text before goes first
        binary = out.buffer
    fd = _fileno(binary)
    interrupted = False
    try:
        with signals_as_interrupt(), _progress(path, run, progress) as bar:
            try:
                if isinstance(run, _native.ArrowRun):  # --format parquet
                    from ..parquet.native import write

                    write(run, binary, None if bar is None else lambda: _tick(bar, run))
                elif fd is not None:  # the core writes each batch itself: no copy through Python
                    binary.flush()
                    try:
                        while run.write_batch(fd):
                            if bar is not None:
                                _tick(bar, run)
                    finally:
                        run.finish_writing()  # its writer thread is done with the descriptor
                else:
                    for batch in run:
                        binary.write(batch)
                        if bar is not None:
                            _tick(bar, run)
            except KeyboardInterrupt:
                interrupted = True  # what was decoded stays written, as with the Python engine
        binary.flush()
    except BrokenPipeError:
        raise  # `| head`: the CLI stops quietly
    except OSError as exc:
        raise OutputError(f"cannot write {output_name or 'the output'}: {exc}") from None
    errors = run.errors
    for err in errors:
        print(f"eg2scope: {path}: {err}", file=sys.stderr)
    if interrupted:
        return EXIT_INTERRUPTED
    return EXIT_DAMAGED if errors else EXIT_OK


def _tick(bar: Any, run: Any) -> None:
    bar.records = run.records_written
    bar.tick(0.0)


def _fileno(stream: IO[bytes]) -> int | None:
    """The file descriptor under ``stream`` when the core may write to it directly (POSIX, a
    real file, pipe or terminal), else None (a test's in-memory stream, ...)."""
    if os.name != "posix":
        return None
    try:
        return stream.fileno()
    except (AttributeError, OSError, ValueError):  # io.UnsupportedOperation is both
        return None
