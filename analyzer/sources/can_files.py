"""CAN capture files as CanFrames: candump logs in every layout, PCAN traces, and what python-can's
LogReader reads.

Every reader has the same shape: opened on a path (a missing file raises at once), a context
manager, an iterable of :class:`~decoders.model.CanFrame` (iterate once), and ``errors``: the
damage found in the file ("line 12: not a frame: ...", "file truncated ..."), recorded instead
of raised, after every frame before the damage has been yielded; reading goes on after a bad
line. ``warnings`` holds notes that are not damage (relative timestamps, an unfinished file),
``frames`` counts the frames yielded and ``tell()`` gives the byte position for progress bars
where the format allows.

candump logs get a reader of their own (:class:`CandumpReader`, the line grammar in
``candump``): python-can's ``CanutilsLogReader`` builds a ``can.Message`` per line at about
200k lines/s, which alone would eat the pipeline's budget; this one does about 1M lines/s and
reads every layout candump writes (python-can reads -L only, without remote DLCs, DLC
suffixes or error frame payloads). PCAN traces too (:class:`TrcReader`, ``pcan_trc``: python-
can gives up on some versions). The other formats go through python-can
(:class:`PythonCanFileReader`); their text forms (.asc, .csv) line by line through
``can_lines``, so no line is skipped in silence.

Text files may start with a UTF-8 byte order mark and end their lines with LF, CRLF or CR
alone. A last line without its line end is a frame when it is whole (its stated length
matches); one that may be cut short is reported as truncated and never read as a frame. A
file whose first lines hold no frame is no log of its kind: one error says so.

``open_can_file(path)`` chooses by content (``sniff``), else by suffix (``SUFFIX_FORMATS``);
``.gz`` compressed files of the formats that can be read from a stream are read too
(``trace.asc.gz``), the others (``.mf4.gz``) are refused in words.
"""

from __future__ import annotations

import binascii
import gzip
import io
import logging
import os
import zlib
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, Protocol

from decoders.model import CanFrame

from ..errors import UsageError
from ..lifecycle import Closing
from . import candump, pcan_trc, sniff
from .can_lines import FORMATS, LineFeed, next_noted
from .can_message import message_to_frame
from .compressed import compression_damage

if TYPE_CHECKING:  # python-can is imported when one of its formats is read: 0.1 s at start-up
    import can

MAX_ERRORS = 100  # errors listed per file; ``bad_lines`` counts them all
READ_BUFFER = candump.READ_BUFFER
CAN_EFF_MASK = candump.CAN_EFF_MASK


class CanFileReader(Protocol):
    """What every CAN capture reader here offers."""

    path: Path
    errors: list[str]
    warnings: list[str]
    frames: int

    def __iter__(self) -> Iterator[CanFrame]: ...
    def __enter__(self) -> CanFileReader: ...
    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None: ...
    def close(self) -> None: ...
    def tell(self) -> int: ...


def is_gzip(path: Path) -> bool:
    return path.suffix.lower() == ".gz"


class _FileReaderBase(Closing):
    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.errors: list[str] = []
        self.warnings: list[str] = []
        self.frames = 0
        self._file: Any = None  # the open file (text, binary or gzip)

    def __iter__(self) -> Iterator[CanFrame]:
        raise NotImplementedError

    def close(self) -> None:
        if self._file is not None:
            self._file.close()

    def tell(self) -> int:
        """Bytes read so far (of the compressed file for .gz); 0 when unknown."""
        f: Any = self._file
        try:
            if f is None or f.closed:
                return 0
            f = getattr(f, "buffer", f)  # text: the binary file under it (tell works while
            f = getattr(f, "fileobj", f)  # iterating); gzip: the compressed file
            return int(f.tell())
        except (OSError, ValueError, AttributeError):
            return 0

    def _error(self, text: str) -> None:
        if len(self.errors) < MAX_ERRORS:
            self.errors.append(text)
        elif len(self.errors) == MAX_ERRORS:
            self.errors.append("further errors not listed")

    def _warning(self, text: str) -> None:
        if text not in self.warnings and len(self.warnings) < MAX_ERRORS:
            self.warnings.append(text)


class _TextLogReader(_FileReaderBase):
    """A text log read line by line here (candump, PCAN trace): plain, gzip compressed (by
    the suffix) or a byte range of a plain file; ``bad_lines`` counts the lines that are no
    frames. A file whose first GIVE_UP bad lines come before any frame is no log of the kind:
    one error says so ("does not look like a candump log") and reading stops."""

    what = "log"

    def __init__(
        self, path: str | os.PathLike[str], byte_range: tuple[int, int] | None = None
    ) -> None:
        """``byte_range``: read only the lines in [start, end) of an uncompressed file (the
        bounds must fall on line starts): the parallel decoder's parts."""
        super().__init__(path)
        self.bad_lines = 0
        if is_gzip(self.path):
            if byte_range is not None:
                raise ValueError(f"a byte range of a compressed {self.what} cannot be read")
            self._file = gzip.open(self.path, "rb")  # noqa: SIM115
        elif byte_range is not None:
            lo, hi = byte_range
            with open(self.path, "rb") as f:
                f.seek(lo)
                self._file = io.BytesIO(f.read(hi - lo))
        else:
            self._file = open(self.path, "rb", buffering=READ_BUFFER)  # noqa: SIM115
        self._lines = candump.ByteLines(self._file)
        self._held: list[str] | None = []  # errors before the first frame
        self._first_bad = b""

    def _bad(self, lineno: int, line: bytes, exc: BaseException) -> bool:
        """Report a line that is no frame; True when the file is no log and reading stops."""
        self.bad_lines += 1
        why = candump.reason(exc) if line[-1:] == b"\n" else TRUNCATED
        text = f"line {lineno}: cannot parse: {candump.quote(line)} ({why})"
        held = self._held
        if held is None:
            self._error(text)
            return False
        if not held:
            self._first_bad = line
        held.append(text)
        if len(held) < GIVE_UP:
            return False
        self.errors.append(
            f"does not look like a {self.what}: no CAN frame in its first {GIVE_UP} lines "
            f"(the first is {candump.quote(self._first_bad, 40)}); nothing read"
        )
        return True

    def _framed(self) -> None:
        """A frame was read: the errors held before it are damage in a log."""
        held, self._held = self._held, None
        for text in held or ():
            self._error(text)

    def _read_error(self, lineno: int, exc: BaseException) -> None:
        self._framed()
        words = compression_damage(exc, at_start=lineno == 1)
        self._error(f"line {lineno}: {words or f'read error: {type(exc).__name__}: {exc}'}")


GIVE_UP = 5  # bad lines before the first frame that make a file no log of its kind
TRUNCATED = "truncated: the file ends in the middle of this line"
_DIRECTIONS = frozenset({b"R", b"T", b"r", b"t"})  # python-can appends the direction


class CandumpReader(_TextLogReader):
    """A candump log in any layout candump writes (``candump`` module): -l/-L log files, the
    default columns with or without ``-t`` stamps, ERROR lines.

    Blank lines and ``#`` comments are skipped, and so are candump -e's explanation lines after
    an error frame; any other line that does not parse (an identifier wider than 29 bits, a
    last line cut short, ...) is counted in ``bad_lines``, listed in ``errors`` ("line N:
    cannot parse: ...") and skipped. ``splittable``: the parallel decoder may split it (-L
    lines, whose stamps are Unix time).
    """

    what = "candump log"

    def __init__(
        self, path: str | os.PathLike[str], byte_range: tuple[int, int] | None = None
    ) -> None:
        super().__init__(path, byte_range)
        head = self._lines.head
        self._clock = candump.Clock(candump.holds_deltas(head, self._lines.cr))
        self.splittable = not self._clock.deltas and _starts_with_log_line(head)

    def __iter__(self) -> Iterator[CanFrame]:
        if self._file is None:
            return
        unhex = binascii.unhexlify
        channels: dict[bytes, str] = {}
        frame_type = CanFrame
        clock = self._clock
        lineno = 0
        after_error = False  # candump -e explains an error frame on TAB-indented lines
        try:
            for lineno, line in enumerate(self._lines, 1):
                # the fast path: "(stamp) channel ID#HEXDATA" with a 3- or 8-digit data frame
                try:
                    if line[-1] != 10:  # no line end: the file was cut in this line
                        raise ValueError
                    parts = line.split()
                    if len(parts) != 3:
                        if len(parts) != 4 or parts[3] not in _DIRECTIONS:
                            raise ValueError
                        del parts[3]
                    stamp, chan, body = parts
                    ident, hexdata = body.split(b"#")
                    if stamp[0] != 0x28 or stamp[-1] != 0x29:  # "(" ... ")"
                        raise ValueError
                    t = float(stamp[1:-1])
                    aid = int(ident, 16)
                    data = unhex(hexdata)
                    channel = channels.get(chan)
                    if channel is None:
                        channel = channels[chan] = chan.decode("ascii")
                    k = len(ident)
                    n = len(data)
                    if k == 8 and 0 <= aid <= CAN_EFF_MASK and n <= 8:
                        frame = frame_type(t, aid, data, True, False, False, False, n, channel)
                    elif k == 3 and 0 <= aid <= 0x7FF and n <= 8:
                        frame = frame_type(t, aid, data, False, False, False, False, n, channel)
                    else:
                        raise ValueError
                except (ValueError, IndexError):
                    pass
                else:
                    if self._held is not None:
                        self._framed()
                    after_error = False
                    self.frames += 1
                    yield frame
                    continue
                # everything else: the default layout, remote, error and FD frames, DLC
                # suffixes, blank lines, comments and damage
                if after_error and line[:1] == b"\t":
                    continue
                try:
                    parsed = candump.parse_line(line, channels, clock)
                    cut = parsed is not None and line[-1:] != b"\n"
                    if cut and not candump.is_complete(line, parsed[1]):  # type: ignore[index]
                        raise ValueError(TRUNCATED)
                except (ValueError, IndexError) as exc:
                    if self._bad(lineno, line, exc):
                        return
                    continue
                if parsed is None:
                    continue
                if self._held is not None:
                    self._framed()
                frame = parsed[0]
                after_error = frame.is_error
                self.frames += 1
                yield frame
            self._framed()
        except (OSError, EOFError, zlib.error) as exc:  # a cut or damaged .gz
            self._read_error(lineno + 1, exc)


def _starts_with_log_line(head: bytes) -> bool:
    """Whether a log's first line is a -L line: "(stamp) channel ID#..."."""
    first = head.lstrip().split(b"\n", 1)[0].split()
    return len(first) >= 3 and first[0][:1] == b"(" and b"#" in first[2]


class TrcReader(_TextLogReader):
    """A PEAK PCAN trace (.trc) of any version, 1.0 to 2.1 (``pcan_trc``): comments and the
    ``;$`` header lines, then one message per line."""

    what = "PCAN trace"

    def __iter__(self) -> Iterator[CanFrame]:
        header = pcan_trc.TraceHeader()
        layout: tuple[str, ...] | None = None
        lineno = 0
        try:
            for lineno, line in enumerate(self._lines, 1):
                text = line.decode("ascii", "replace").strip()
                if not text:
                    continue
                if text[0] == ";":
                    try:
                        if text[:2] == ";$" and layout is None:
                            header.read(text)
                    except ValueError as exc:
                        self._error(f"line {lineno}: {exc}")
                    continue
                if layout is None:
                    try:
                        layout = header.layout()
                    except ValueError as exc:  # a version of the format we do not know
                        self._error(f"cannot read this trace: {exc}")
                        return
                try:
                    frame = pcan_trc.parse_message(text, header, layout)
                except ValueError as exc:
                    if self._bad(lineno, line, exc):
                        return
                    continue
                if frame is not None:
                    self._framed()
                    self.frames += 1
                    yield frame
            self._framed()
        except (OSError, EOFError, zlib.error) as exc:  # a cut or damaged .gz
            self._read_error(lineno + 1, exc)


# python-can reader per suffix (the readers keep python-can's own names)
_PYTHON_CAN_READERS: dict[str, str] = {
    ".asc": "ASCReader",
    ".blf": "BLFReader",
    ".csv": "CSVReader",
    ".mf4": "MF4Reader",
}
_BINARY_SUFFIXES = frozenset({".blf", ".mf4"})
_TEXT_KINDS = {".asc": "Vector ASC log", ".csv": "python-can CSV log"}
BLF_HEADER_SIZE = 144  # FILE_HEADER_SIZE: what python-can's BLFWriter writes first


class PythonCanFileReader(_FileReaderBase):
    """The formats python-can reads for us (.asc, .blf, .csv, .mf4), as CanFrames.

    ASC timestamps are made absolute from the file's "Begin Triggerblock" date (to the
    millisecond the format keeps); when that date cannot be parsed they stay relative and
    ``warnings`` says so. Text formats are read line by line (``can_lines.LineFeed``): a line
    that is not a frame is reported where it is and reading goes on. A frame whose data do not
    match its DLC is reported and not read. A truncated or corrupt binary file yields every
    frame before the damage and records the error; a .blf cut short (or never finished by its
    writer) is detected from the file size its header states.
    """

    def __init__(self, path: str | os.PathLike[str], fmt: str | None = None) -> None:
        """``fmt``: "asc", "blf", "csv" or "mf4" (what the file holds); default: its suffix."""
        super().__init__(path)
        self.suffix = f".{fmt}" if fmt else _format_suffix(self.path)
        reader_name = _PYTHON_CAN_READERS.get(self.suffix)
        if reader_name is None:
            raise ValueError(_unsupported(self.path))
        reader_type = _python_can_reader(reader_name)
        if not self.path.exists():
            raise FileNotFoundError(f"CAN capture not found: {self.path}")
        self._reader_type = reader_type
        self._kwargs: dict[str, Any] = {}
        self._feed: LineFeed | None = None
        self._relative = False
        self._held: list[str] | None = []  # line errors before the first frame
        self._first_bad = ""
        self._reader: Any = self._open(relative=False)

    def _open(self, relative: bool) -> Any:
        binary = self.suffix in _BINARY_SUFFIXES
        if self.suffix == ".asc":
            self._kwargs["relative_timestamp"] = relative
        if self._file is not None:
            self._file.close()
        # text formats: a stray non-UTF-8 byte (a comment in a local code page) must not end
        # the file early; a byte order mark is not part of the first line
        text: dict[str, Any] = {} if binary else {"encoding": "utf-8-sig", "errors": "replace"}
        if is_gzip(self.path):
            self._file = gzip.open(self.path, "rb" if binary else "rt", **text)  # noqa: SIM115
        else:
            self._file = open(self.path, "rb" if binary else "r", **text)  # noqa: SIM115
        source = self._file
        if not binary:
            source = self._feed = LineFeed(self._file, FORMATS[self.suffix], self._line_error)
        try:
            return self._reader_type(source, **self._kwargs)
        except NotImplementedError as exc:  # e.g. .mf4 without asammdf
            raise ValueError(f"cannot read {self.path.name}: {exc}") from exc
        except OSError:
            raise
        except Exception as exc:  # a damaged header: nothing to read
            self._error(f"cannot open: {self._cannot_open(exc)}")  # the caller names the file
            return None

    def _cannot_open(self, exc: BaseException) -> str:
        """Why the file could not be opened, in words."""
        if self.suffix == ".blf":
            size = self.path.stat().st_size if not is_gzip(self.path) else None
            if size == 0:
                return "the file is empty: not a BLF capture"
            if "unpack requires a buffer" in str(exc):
                return "too short for a BLF file header: not a BLF capture, or cut short"
            from can.io.blf import BLFParseError

            if isinstance(exc, BLFParseError):
                return "not a BLF capture (it does not start with the BLF signature 'LOGG')"
        return _exc_text(exc)

    def __iter__(self) -> Iterator[CanFrame]:
        if self._reader is None:
            return
        if self._feed is not None:
            yield from self._read_text()
        else:
            yield from self._read_binary()

    # -- text formats: line by line ----------------------------------------------------------

    def _read_text(self) -> Iterator[CanFrame]:
        first_error = len(self.errors)
        while True:
            feed = self._feed
            assert feed is not None
            it = iter(self._reader)
            try:
                while True:
                    msg = next_noted(it, feed.note)
                    where = f"line {feed.number}"
                    if self._accept(msg, feed.produced(), where):
                        yield message_to_frame(msg)
            except StopIteration:
                break
            except Exception as exc:
                if self._can_go_relative(exc):
                    del self.errors[first_error:]  # read again from the start
                    self._reader = self._open(relative=True)
                    if self._reader is None:
                        return
                    continue
                if not feed.failed(exc):
                    self._error(f"cannot read past line {feed.number}: {_exc_text(exc)}")
                    break
                self._reader = self._reader_type(feed, **self._kwargs)
        feed.finish()
        if self._no_log():
            return
        for text in self._held or ():
            self._error(text)
        if feed.read_error is not None:
            self._error(_read_error_text(feed.read_error, feed.number))

    def _line_error(self, text: str) -> None:
        """A line that is no frame: damage, or (before any frame) a sign the file is no log."""
        held = self._held
        if self.frames or held is None:
            self._error(text)
            return
        if not held:
            self._first_bad = text if len(text) <= 80 else text[:77] + "..."
        held.append(text)
        if len(held) >= GIVE_UP and self._feed is not None:
            self._feed.stop = True

    def _no_log(self) -> bool:
        """Whether reading stopped because the first lines held no frame (and say so)."""
        held = self._held
        if held is None or len(held) < GIVE_UP:
            return False
        what = _TEXT_KINDS.get(self.suffix, "capture")
        self.errors.append(
            f"does not look like a {what}: no CAN frame in its first {GIVE_UP} lines "
            f"(the first: {self._first_bad}); nothing read"
        )
        return True

    def _can_go_relative(self, exc: BaseException) -> bool:
        """The ASC start date is in a form python-can cannot parse: keep relative times."""
        if self.frames or self.suffix != ".asc" or self._relative:
            return False
        if "datetime" not in str(exc).lower():
            return False
        self._relative = True
        self._warning(
            f"timestamps are relative to the start of the capture "
            f"(cannot read its start date: {exc})"
        )
        return True

    # -- binary formats ------------------------------------------------------------------------

    def _read_binary(self) -> Iterator[CanFrame]:
        notes: list[tuple[int, str]] = []

        def note(record: logging.LogRecord) -> None:
            notes.append((record.levelno, record.getMessage()))

        it = iter(self._reader)
        try:
            while True:
                msg = next_noted(it, note)
                where = f"frame {self.frames + 1}"
                if self._accept(msg, notes, where):
                    yield message_to_frame(msg)
                notes.clear()
        except StopIteration:
            pass
        except Exception as exc:
            self._error(f"damaged after {self.frames} frames: {_exc_text(exc)}")
            return
        for level, text in notes:  # logged after the last frame
            self._note(level, f"{text}")
        if self.suffix == ".blf":
            self._check_blf()

    # -- shared ----------------------------------------------------------------------------------

    def _accept(self, msg: can.Message, notes: list[tuple[int, str]], where: str) -> bool:
        """Report what python-can said about this frame; False if it must not be read."""
        for level, text in notes:
            self._note(level, f"{where}: {text}")
        if not _data_match_dlc(msg):
            if self._feed is not None and self._feed.cut:
                self._error(f"{where}: {TRUNCATED} (no line end), which is not read")
            else:
                self._error(
                    f"{where}: DLC {msg.dlc} but {len(msg.data)} data bytes: the frame is "
                    "damaged and not read"
                )
            return False
        self.frames += 1
        if self.frames == 1:
            for text in self._held or ():
                self._error(text)
            self._held = None
            if self.suffix == ".asc" and not self._relative:
                self._check_asc_start()
        return True

    def _note(self, level: int, text: str) -> None:
        if level >= logging.WARNING:
            self._error(text)
        else:
            self._warning(text)

    def _check_asc_start(self) -> None:
        if getattr(self._reader, "start_time", None) == 0.0:
            self._relative = True
            self._warning(
                "timestamps are relative to the start of the capture (no start date in the file)"
            )

    def _check_blf(self) -> None:
        reader = self._reader
        stated = int(getattr(reader, "file_size", 0) or 0)
        if is_gzip(self.path):
            return  # the header states the uncompressed size; nothing to compare against
        actual = self.path.stat().st_size
        if stated == BLF_HEADER_SIZE and actual > stated:
            self._warning(
                "the writer did not finish the file (its header was never "
                "updated); read what is there"
            )
        elif actual < stated:
            self._error(
                f"file truncated: its header states {stated} bytes, the file "
                f"has {actual}; frames after the cut are lost"
            )
        elif not _blf_padding(getattr(reader, "_tail", b"")):
            self._error("the last object is incomplete")


def _blf_padding(tail: bytes) -> bool:
    """Whether what is left after a BLF's last object is only the zero padding that aligns
    objects to 4 bytes (a writer may pad the last container's last object too)."""
    return len(tail) < 4 and not tail.strip(b"\0")


def _data_match_dlc(msg: can.Message) -> bool:
    """A data frame carries the bytes its DLC says (a line cut or damaged inside its data
    does not)."""
    if msg.is_remote_frame or msg.is_error_frame:
        return True
    n = len(msg.data)
    if msg.is_fd or n > 8:  # CAN FD, the flag lost or not (.csv)
        from can.util import dlc2len

        return n in (msg.dlc, dlc2len(min(msg.dlc, 15)))
    return n == min(msg.dlc, 8)


def _read_error_text(exc: BaseException, lines: int) -> str:
    """A python-can log's read error after ``lines`` lines: a .gz cut or damaged in words."""
    words = compression_damage(exc, at_start=lines == 0)
    if words is None:
        return f"read error after line {lines}: {_exc_text(exc)}"
    return f"after line {lines}: {words}" if lines else words


def _exc_text(exc: BaseException) -> str:
    kind = type(exc)
    name = kind.__name__ if kind.__module__ == "builtins" else f"{kind.__module__}.{kind.__name__}"
    return f"{name}: {exc}"


def _python_can_reader(name: str) -> Any:
    import can

    if name == "MF4Reader":
        from .mf4 import mf4_reader

        return mf4_reader()
    return getattr(can, name)


# -- choosing a reader --------------------------------------------------------------------------

#: the reader of each CAN capture format
FORMAT_READERS: dict[str, type[_FileReaderBase]] = {
    "candump": CandumpReader,
    "trc": TrcReader,
    "asc": PythonCanFileReader,
    "blf": PythonCanFileReader,
    "csv": PythonCanFileReader,
    "mf4": PythonCanFileReader,
}
#: the format a suffix names, where the content does not tell (python-can's LogReader goes by it)
SUFFIX_FORMATS: dict[str, str] = {
    ".log": "candump",
    ".trc": "trc",
    ".asc": "asc",
    ".blf": "blf",
    ".csv": "csv",
    ".mf4": "mf4",
}
CAN_READERS: dict[str, type[_FileReaderBase]] = {
    suffix: FORMAT_READERS[fmt] for suffix, fmt in SUFFIX_FORMATS.items()
}
# read from a stream, so also gzip compressed (.mf4 needs random access)
GZIP_READABLE = frozenset({".log", ".asc", ".blf", ".trc", ".csv"})
GZIP_FORMATS = frozenset(SUFFIX_FORMATS[s] for s in GZIP_READABLE)
#: every suffix a CAN capture may have, compressed ones included (".log", ".log.gz", ...)
CAN_SUFFIXES = frozenset([*CAN_READERS, *(f"{s}.gz" for s in GZIP_READABLE)])


def _format_suffix(path: Path) -> str:
    """The format suffix, looking through .gz (``trace.asc.gz`` -> ``.asc``)."""
    suffixes = [s.lower() for s in path.suffixes]
    if suffixes and suffixes[-1] == ".gz":
        return suffixes[-2] if len(suffixes) >= 2 else ""
    return suffixes[-1] if suffixes else ""


def _unsupported(path: Path) -> str:
    supported = ", ".join(sorted(CAN_READERS))
    return (
        f"{path.name}: unsupported CAN capture suffix {_format_suffix(path) or '(none)'!r}; "
        f"supported: {supported} (all but .mf4 also .gz compressed)"
    )


def can_format(path: str | os.PathLike[str]) -> str | None:
    """The CAN capture format of a file: from its content (``sniff``), else from its suffix;
    None when it is no CAN capture."""
    p = Path(path)
    fmt = sniff.sniff(p)
    if fmt in FORMAT_READERS:
        return fmt
    if fmt is not None:  # another kind of capture (an MCAP recording)
        return None
    return SUFFIX_FORMATS.get(_format_suffix(p))


def is_can_file(path: str | os.PathLike[str]) -> bool:
    """Whether open_can_file would pick a reader for this path's suffix."""
    return _format_suffix(Path(path)) in CAN_READERS


def open_can_file(path: str | os.PathLike[str]) -> Any:
    """The reader for a CAN capture, chosen by what it holds, else by its suffix (as
    python-can's LogReader chooses)."""
    p = Path(path)
    fmt = can_format(p)
    if fmt is None:
        raise ValueError(_unsupported(p))
    if is_gzip(p) and fmt not in GZIP_FORMATS:
        raise UsageError(compressed_unreadable(p, f".{fmt}"))
    reader_type = FORMAT_READERS[fmt]
    if reader_type is PythonCanFileReader:
        return PythonCanFileReader(p, fmt)
    return reader_type(p)


def compressed_unreadable(path: Path, suffix: str) -> str:
    return (
        f"{path.name}: a compressed {suffix} capture cannot be read (its reader needs random "
        f"access): decompress it first (gunzip {path.name})"
    )
