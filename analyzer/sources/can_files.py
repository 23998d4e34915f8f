"""CAN capture files as CanFrames: candump -L logs and everything python-can's LogReader reads.

Every reader has the same shape: opened on a path (a missing file raises at once), a context
manager, an iterable of :class:`~decoders.model.CanFrame` (iterate once), and ``errors``: the
damage found in the file ("line 12: not a frame: ...", "file truncated ..."), recorded instead
of raised, after every frame before the damage has been yielded; reading goes on after a bad
line. ``warnings`` holds notes that are not damage (relative timestamps, an unfinished file),
``frames`` counts the frames yielded and ``tell()`` gives the byte position for progress bars
where the format allows.

candump logs get a parser of their own (:class:`CandumpReader`): python-can's
``CanutilsLogReader`` builds a ``can.Message`` per line at about 200k lines/s, which alone would
eat the pipeline's budget; this one does about 1M lines/s and also reads what candump writes
and python-can does not (remote DLCs ``123#R5``, the DLC 9-15 suffix ``#..._F``, error frame
payloads). The other formats go through python-can (:class:`PythonCanFileReader`); their text
forms (.asc, .trc, .csv) line by line through ``can_lines``, so no line is skipped in silence.

Text files may start with a UTF-8 byte order mark and end their lines with LF, CRLF or CR
alone. A last line cut short (no line end) is reported as truncated and never read as a frame.

``open_can_file(path)`` chooses by suffix (``CAN_READERS``); ``.gz`` compressed files of the
formats python-can can read from a stream are read too (``trace.asc.gz``), the others
(``.mf4.gz``) are refused in words.
"""

from __future__ import annotations

import binascii
import gzip
import io
import itertools
import logging
import os
import zlib
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import IO, TYPE_CHECKING, Any, Protocol

from decoders.model import CanFrame

from ..errors import UsageError
from ..lifecycle import Closing
from .can_lines import FORMATS, LineFeed, next_noted
from .can_message import message_to_frame

if TYPE_CHECKING:  # python-can is imported when one of its formats is read: 0.1 s at start-up
    import can

MAX_ERRORS = 100  # errors listed per file; ``bad_lines`` counts them all
READ_BUFFER = 1 << 20
HEAD_SIZE = 1 << 16  # bytes looked at for a byte order mark and the line ends
BOM = b"\xef\xbb\xbf"

CAN_ERR_FLAG = 0x20000000  # SocketCAN: error frame; the identifier carries the error class
CAN_RTR_FLAG = 0x40000000  # SocketCAN: remote frame; never printed by candump (it writes "#R")
CAN_EFF_FLAG = 0x80000000  # SocketCAN: extended frame (some tools print it)
CAN_EFF_MASK = 0x1FFFFFFF


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


def byte_lines(f: IO[bytes]) -> Iterator[bytes]:
    """The lines of a binary text file, each ending in b"\\n" but a cut last one: without its
    UTF-8 byte order mark, and split at lone CRs when the file ends its lines that way. A read
    error (a cut .gz) is raised after the lines read before it."""
    head = b""
    error: BaseException | None = None
    read1 = getattr(f, "read1", f.read)  # read1: a cut .gz keeps what it gave before the cut
    try:
        while len(head) < HEAD_SIZE and (block := read1(HEAD_SIZE - len(head))):
            head += block
    except (OSError, EOFError, zlib.error) as exc:
        error = exc
    if head.startswith(BOM):
        head = head[len(BOM) :]
    if b"\n" not in head and b"\r" in head:
        lines: Iterator[bytes] = _cr_lines(head, f if error is None else io.BytesIO())
    elif error is not None or not head:
        lines = io.BytesIO(head)
    else:
        if not head.endswith(b"\n"):
            head += f.readline()
        lines = itertools.chain(io.BytesIO(head), f)
    yield from lines
    if error is not None:
        raise error


def _cr_lines(head: bytes, f: IO[bytes]) -> Iterator[bytes]:
    rest = head
    while True:
        block = f.read(READ_BUFFER)
        lines = (rest + block).split(b"\r")
        rest = lines.pop()
        for line in lines:
            yield line + b"\n"
        if not block:
            break
    if rest:
        yield rest


class CandumpReader(_FileReaderBase):
    """candump -L log lines: ``(1600000000.123456) can0 04FF0001#0000F401F401``.

    Standard (3 hex digits) and extended (8) identifiers, remote frames ``123#R`` / ``123#R5``,
    error frames (CAN_ERR_FLAG 0x20000000 in the identifier: ``is_error``, the identifier
    keeps the error class), CAN FD ``123##<flags><data>``, the classic DLC 9-15 suffix
    ``123#1122334455667788_F``, and the direction flag python-can appends (`` R`` / `` T``).
    Blank lines and ``#`` comments are skipped; any other line that does not parse (an
    identifier wider than 29 bits, a last line cut short, ...) is counted in ``bad_lines``,
    listed in ``errors`` ("line N: cannot parse: ...") and skipped.
    """

    def __init__(
        self, path: str | os.PathLike[str], byte_range: tuple[int, int] | None = None
    ) -> None:
        """``byte_range``: read only the lines in [start, end) of an uncompressed file (the
        bounds must fall on line starts): the parallel decoder's parts."""
        super().__init__(path)
        self.bad_lines = 0
        if is_gzip(self.path):
            if byte_range is not None:
                raise ValueError("a byte range of a compressed candump log cannot be read")
            self._file = gzip.open(self.path, "rb")  # noqa: SIM115
        elif byte_range is not None:
            lo, hi = byte_range
            with open(self.path, "rb") as f:
                f.seek(lo)
                self._file = io.BytesIO(f.read(hi - lo))
        else:
            self._file = open(self.path, "rb", buffering=READ_BUFFER)  # noqa: SIM115

    def __iter__(self) -> Iterator[CanFrame]:
        f = self._file
        if f is None:
            return
        unhex = binascii.unhexlify
        channels: dict[bytes, str] = {}
        frame_type = CanFrame
        lineno = 0
        skipped = 0  # blank, comment and bad lines
        try:
            for lineno, line in enumerate(byte_lines(f), 1):
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
                        yield frame_type(t, aid, data, True, False, False, False, n, channel)
                        continue
                    if k == 3 and 0 <= aid <= 0x7FF and n <= 8:
                        yield frame_type(t, aid, data, False, False, False, False, n, channel)
                        continue
                    raise ValueError
                except (ValueError, IndexError):
                    pass
                # everything else: remote, error, FD frames, DLC suffixes, blank lines,
                # comments and damage
                try:
                    parsed = _parse_candump(line, channels)
                except (ValueError, IndexError) as exc:
                    skipped += 1
                    self.bad_lines += 1
                    self._error(f"line {lineno}: cannot parse: {_quote(line)} ({exc})")
                    continue
                if parsed is None:
                    skipped += 1
                    continue
                yield parsed
        except (OSError, EOFError, zlib.error) as exc:  # a cut or damaged .gz
            self._error(f"line {lineno + 1}: read error: {type(exc).__name__}: {exc}")
        finally:
            self.frames = lineno - skipped


def _quote(line: bytes) -> str:
    text = line.decode("ascii", "replace").strip()
    if len(text) > 80:
        text = text[:77] + "..."
    return repr(text)


_HEX_DIGITS = frozenset(b"0123456789abcdefABCDEF")
_DIRECTIONS = frozenset({b"R", b"T", b"r", b"t"})  # python-can appends the direction


def _parse_candump(line: bytes, channels: dict[bytes, str]) -> CanFrame | None:
    """Any candump -L line: a CanFrame, None for a blank or comment line; else ValueError
    saying what is wrong."""
    parts = line.split()
    if not parts or parts[0][:1] == b"#":
        return None
    if not line.endswith(b"\n"):
        raise ValueError("truncated: the file ends in the middle of this line")
    if len(parts) == 4 and parts[3] in _DIRECTIONS:
        parts = parts[:3]
    if len(parts) != 3:
        raise ValueError(f"expected 3 fields, found {len(parts)}")
    stamp, chan, body = parts
    if stamp[:1] != b"(" or stamp[-1:] != b")":
        raise ValueError("no (timestamp)")
    t = float(stamp[1:-1])
    ident, sep, payload = body.partition(b"#")
    if not sep:
        raise ValueError("no '#' between identifier and data")
    if not ident or not _HEX_DIGITS.issuperset(ident) or len(ident) > 8:
        raise ValueError(f"bad identifier {ident.decode('ascii', 'replace')!r}")
    aid = int(ident, 16)
    extended = len(ident) > 3
    error = False
    if extended:
        if aid & CAN_RTR_FLAG:
            raise ValueError(f"identifier {ident.decode()} does not fit in 29 bits")
        error = bool(aid & CAN_ERR_FLAG)
        aid &= CAN_EFF_MASK
    elif aid > 0x7FF:
        raise ValueError("standard identifier above 0x7FF")
    remote = fd = False
    if payload[:1] == b"#":  # CAN FD: "##", one flags digit (BRS, ESI: not kept), the data
        if len(payload) < 2 or payload[1] not in _HEX_DIGITS:
            raise ValueError("CAN FD frame without its flags digit")
        fd = True
        data = binascii.unhexlify(payload[2:])
        dlc = len(data)
    elif payload[:1] in (b"R", b"r"):  # remote frame, optional DLC digit
        data = b""
        dlc = int(payload[1:], 16) if len(payload) > 1 else 0
        if not 0 <= dlc <= 15:
            raise ValueError("bad remote DLC")
        remote = True
    elif b"_" in payload:  # classic frame with a DLC of 9-15: 8 data bytes and "_<dlc>"
        hexdata, _, dlc_text = payload.partition(b"_")
        data = binascii.unhexlify(hexdata)
        dlc = int(dlc_text, 16)
        if len(data) != 8 or not 9 <= dlc <= 15:
            raise ValueError("bad DLC suffix")
    else:
        try:
            data = binascii.unhexlify(payload)
        except binascii.Error as exc:
            raise ValueError(f"bad data: {exc}") from None
        dlc = len(data)
    if not fd and len(data) > 8:
        raise ValueError(f"{len(data)} data bytes in a classic CAN frame")
    channel = channels.get(chan)
    if channel is None:
        channel = channels[chan] = chan.decode("ascii")
    return CanFrame(t, aid, data, extended, remote, error, fd, dlc, channel)


# python-can reader per suffix (the readers keep python-can's own names)
_PYTHON_CAN_READERS: dict[str, str] = {
    ".asc": "ASCReader",
    ".blf": "BLFReader",
    ".trc": "TRCReader",
    ".csv": "CSVReader",
    ".mf4": "MF4Reader",
}
_BINARY_SUFFIXES = frozenset({".blf", ".mf4"})
BLF_HEADER_SIZE = 144  # FILE_HEADER_SIZE: what python-can's BLFWriter writes first


class PythonCanFileReader(_FileReaderBase):
    """Any format python-can reads (.asc, .blf, .trc, .csv, .mf4), as CanFrames.

    ASC timestamps are made absolute from the file's "Begin Triggerblock" date (to the
    millisecond the format keeps); when that date cannot be parsed they stay relative and
    ``warnings`` says so. Text formats are read line by line (``can_lines.LineFeed``): a line
    that is not a frame is reported where it is and reading goes on. A frame whose data do not
    match its DLC is reported and not read. A truncated or corrupt binary file yields every
    frame before the damage and records the error; a .blf cut short (or never finished by its
    writer) is detected from the file size its header states.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        super().__init__(path)
        self.suffix = _format_suffix(self.path)
        reader_name = _PYTHON_CAN_READERS.get(self.suffix)
        if reader_name is None:
            raise ValueError(_unsupported(self.path))
        import can

        reader_type = getattr(can, reader_name)
        if not self.path.exists():
            raise FileNotFoundError(f"CAN capture not found: {self.path}")
        self._reader_type = reader_type
        self._kwargs: dict[str, Any] = {}
        self._feed: LineFeed | None = None
        self._relative = False
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
            source = self._feed = LineFeed(self._file, FORMATS[self.suffix], self._error)
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
                    self._error(
                        f"{self.path.name}: cannot read past line {feed.number}: {_exc_text(exc)}"
                    )
                    break
                self._reader = self._reader_type(feed, **self._kwargs)
        feed.finish()
        if feed.read_error is not None:
            self._error(
                f"{self.path.name}: read error after line {feed.number}: "
                f"{_exc_text(feed.read_error)}"
            )

    def _can_go_relative(self, exc: BaseException) -> bool:
        """The ASC start date is in a form python-can cannot parse: keep relative times."""
        if self.frames or self.suffix != ".asc" or self._relative:
            return False
        if "datetime" not in str(exc).lower():
            return False
        self._relative = True
        self._warning(
            f"{self.path.name}: timestamps are relative to the start of the capture "
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
            self._error(f"{self.path.name}: damaged after {self.frames} frames: {_exc_text(exc)}")
            return
        for level, text in notes:  # logged after the last frame
            self._note(level, f"{self.path.name}: {text}")
        if self.suffix == ".blf":
            self._check_blf()

    # -- shared ----------------------------------------------------------------------------------

    def _accept(self, msg: can.Message, notes: list[tuple[int, str]], where: str) -> bool:
        """Report what python-can said about this frame; False if it must not be read."""
        for level, text in notes:
            self._note(level, f"{where}: {text}")
        if not _data_match_dlc(msg):
            self._error(
                f"{where}: DLC {msg.dlc} but {len(msg.data)} data bytes: the frame is damaged "
                "and not read"
            )
            return False
        self.frames += 1
        if self.frames == 1 and self.suffix == ".asc" and not self._relative:
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
                f"{self.path.name}: timestamps are relative to the start of the capture "
                "(no start date in the file)"
            )

    def _check_blf(self) -> None:
        reader = self._reader
        stated = int(getattr(reader, "file_size", 0) or 0)
        if is_gzip(self.path):
            return  # the header states the uncompressed size; nothing to compare against
        actual = self.path.stat().st_size
        if stated == BLF_HEADER_SIZE and actual > stated:
            self._warning(
                f"{self.path.name}: the writer did not finish the file (its header was never "
                "updated); read what is there"
            )
        elif actual < stated:
            self._error(
                f"{self.path.name}: file truncated: its header states {stated} bytes, the file "
                f"has {actual}; frames after the cut are lost"
            )
        elif getattr(reader, "_tail", b""):
            self._error(f"{self.path.name}: the last object is incomplete")


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


def _exc_text(exc: BaseException) -> str:
    kind = type(exc)
    name = kind.__name__ if kind.__module__ == "builtins" else f"{kind.__module__}.{kind.__name__}"
    return f"{name}: {exc}"


# -- choosing a reader --------------------------------------------------------------------------

CAN_READERS: dict[str, type[CandumpReader] | type[PythonCanFileReader]] = {
    ".log": CandumpReader,
    ".asc": PythonCanFileReader,
    ".blf": PythonCanFileReader,
    ".trc": PythonCanFileReader,
    ".csv": PythonCanFileReader,
    ".mf4": PythonCanFileReader,
}
# read from a stream, so also gzip compressed (.mf4 needs random access)
GZIP_READABLE = frozenset({".log", ".asc", ".blf", ".trc", ".csv"})
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


def is_can_file(path: str | os.PathLike[str]) -> bool:
    """Whether open_can_file would pick a reader for this path's suffix."""
    return _format_suffix(Path(path)) in CAN_READERS


def open_can_file(path: str | os.PathLike[str]) -> CandumpReader | PythonCanFileReader:
    """The reader for a CAN capture, chosen by its suffix (like python-can's LogReader)."""
    p = Path(path)
    suffix = _format_suffix(p)
    reader_type = CAN_READERS.get(suffix)
    if reader_type is None:
        raise ValueError(_unsupported(p))
    if is_gzip(p) and suffix not in GZIP_READABLE:
        raise UsageError(compressed_unreadable(p, suffix))
    return reader_type(p)


def compressed_unreadable(path: Path, suffix: str) -> str:
    return (
        f"{path.name}: a compressed {suffix} capture cannot be read (its reader needs random "
        f"access): decompress it first (gunzip {path.name})"
    )
