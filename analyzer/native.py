"""The native decoding core (``analyzer._native``, Rust, built from ``native/``) as the engine of
``eg2scope decode``.

The core runs the whole offline path (capture reading, framing, decoding, lint, pairing and the
JSONL/CSV/text writers) in one streaming pass and hands Python batches of output bytes, not one
object per frame. Its output is byte-identical to the Python engine's (tests/native/ checks
that), so it is used automatically where it applies:

- the extension is installed (``pip install`` builds it when a Rust toolchain is there; without
  one the package installs in pure Python, and ``eg2scope --version`` says so);
- the capture is a candump log (any layout candump writes, plain or ``.gz``) or a raw byte
  dump (``.gz`` too), a regular file (a FIFO cannot be opened twice);
- ``--format`` is jsonl, csv, text or parquet (the core builds the Arrow columns:
  analyzer/native_parquet.py), and there is no ``--speed`` (a timed replay).

Other CAN captures (PCAN traces, python-can's formats, CAN recordings) are read in Python and
decoded by the session, natively where the core is built (analyzer/batches.py); a session on a
candump log (``plot``, ``tui``) gets its frames from the core's reader (``candump_frames``)
when it decodes natively and no listener wants the raw items. Byte streams of
recordings, live taps and the TUI stay with the Python decoders, the readable reference.
``--engine python`` forces the Python engine, ``--engine native`` the native one: the core's
own decode where it applies, the session's native decoding for the other CAN captures, a usage
error saying why for the rest.
"""

from __future__ import annotations

import codecs
import importlib
import io
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType
from typing import IO, TYPE_CHECKING, Any

from .errors import EXIT_DAMAGED, EXIT_INTERRUPTED, EXIT_OK, UsageError
from .outfile import OutputError
from .sources.can_files import CandumpReader
from .sources.capture import CanLogReader, CaptureReader, GzipBytesReader, RawBytesReader

if TYPE_CHECKING:
    from .commands.common import CaptureOptions

ENGINES = ("auto", "python", "native")
FORMATS = ("jsonl", "csv", "text")
_I64_MAX = (1 << 63) - 1

_native: ModuleType | None
try:
    _native = importlib.import_module(f"{__package__}._native")
except ModuleNotFoundError as exc:
    _native = None
    if exc.name == f"{__package__}._native":
        WHY_NOT = "not built: no Rust toolchain at install time, or its build failed"
    else:
        WHY_NOT = f"not loadable: {exc}"
except ImportError as exc:  # built, but for another platform, or damaged
    _native = None
    WHY_NOT = f"not loadable: {exc}"
else:
    WHY_NOT = ""


def available() -> bool:
    return _native is not None


def status() -> str:
    """The engine, as ``eg2scope --version`` says it."""
    if _native is not None:
        return "native core: available"
    return f"native core: {WHY_NOT}; pure Python"


def ineligible(reader: CaptureReader, fmt: str, speed: float | None, device: int | None) -> str:
    """Why the native core cannot decode this capture this way ("" when it can)."""
    if _native is None:
        return f"the native core is {WHY_NOT}"
    if fmt not in FORMATS and fmt != "parquet":
        return f"the native core does not write --format {fmt}"
    if speed is not None:
        return "a timed replay (--speed) runs on the Python engine only"
    if device is not None and device > _I64_MAX:
        return f"--device {device} is beyond the native core's integers"
    path = reader.path
    if isinstance(reader, CanLogReader):
        if not isinstance(getattr(reader, "_reader", None), CandumpReader):
            return f"{path.name}: the native core reads candump logs, not this CAN format"
    elif not isinstance(reader, RawBytesReader | GzipBytesReader):
        return f"{path.name}: the native core does not read this kind of capture"
    if not path.is_file():
        return f"{path.name} is not a regular file"
    try:  # messages naming the file must come out as Python prints the name
        os.fsencode(path).decode("utf-8")
    except UnicodeDecodeError:
        return f"{path.name!r} is not a UTF-8 file name"
    return ""


def candump_frames(reader: CaptureReader) -> Any:
    """The frames of ``reader``'s capture as the native core reads them for a session
    (``_native.CandumpFrames``: the reader ``decode`` uses, batches of frames that the native
    ``LiveCan`` decodes with no Python object per frame), or None: the Python reader reads it
    (not a candump log on a regular file, or the core does not read it)."""
    if ineligible(reader, "jsonl", None, None):
        return None
    assert _native is not None  # ineligible() said so
    try:
        return _native.CandumpFrames(str(reader.path), reader.bus or None)
    except (_native.Unsupported, OSError):
        return None  # the Python reader reads it (and says why it cannot, if it cannot)


def open_for(args: Any, opts: CaptureOptions, reader: CaptureReader, colour: bool | None) -> Any:
    """The native run of ``eg2scope decode`` with these options (``--engine``: auto where
    eligible; native or a UsageError saying why not), or None: the Python engine decodes. The
    Python ``reader`` (opened first, for the same checks and messages) is closed when the native
    core takes over."""
    if args.engine == "python":
        return None
    try:
        why = ineligible(reader, args.format, opts.speed, opts.device)
        if not why and args.format != "jsonl" and args.output in (None, "-"):
            why = _text_stdout_differs()
        if why:
            if args.engine == "native" and not _session_decodes(reader):
                raise UsageError(f"--engine native: {why}; use --engine python or auto")
            return None  # the Python engine, or the session's native CAN decoding
        if colour is None:  # stdout: coloured as the text listener would decide
            from .sinks.text import use_colour

            colour = use_colour(sys.stdout)
        assert _native is not None  # ineligible() said so
        try:
            run = open_run(opts, args.format, colour and args.format == "text", args.absolute_time)
        except _native.Unsupported as exc:  # the core's own word: only Python reads this
            if args.engine == "native" and not _session_decodes(reader):
                raise UsageError(f"--engine native: {exc}; use --engine python or auto") from None
            run = None
        if run is None and args.engine == "native" and not _session_decodes(reader):
            raise UsageError(f"--engine native: the native core does not support {opts.path}")
    except BaseException:
        reader.close()
        raise
    if run is not None:
        reader.close()
    return run


def _session_decodes(reader: CaptureReader) -> bool:
    """Whether the session decodes this capture natively when the core's own decode cannot:
    CAN frames read in Python (analyzer/batches.py `session_engine`)."""
    from .batches import native_session_available

    return reader.kind == "can" and native_session_available()


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
    from .commands.common import byte_protocol

    assert _native is not None
    if fmt == "parquet":  # records as Arrow columns (native_parquet.py)
        from .native_parquet import open_run as open_arrow_run

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
    """The Python engine's progress bar (commands.common.ProgressListener), on terminals."""
    if not (show and sys.stderr.isatty()):
        yield None
        return
    from .commands.common import ProgressListener

    bar = ProgressListener(_RunReader(path, run))  # type: ignore[arg-type]
    try:
        yield bar
    finally:
        bar.close()


def decode(run: Any, path: str, out: IO[Any], output_name: str | None, progress: bool) -> int:
    """Write a native run's output into ``out`` (a binary stream, or a text stream whose buffer
    takes the bytes); report damage on stderr; the exit code, as commands.common.finish_capture
    gives it for the Python engine."""
    from .session import signals_as_interrupt

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
                    from .native_parquet import write

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
