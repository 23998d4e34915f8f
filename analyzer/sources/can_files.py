"""CAN capture files as CanFrames: candump -L logs and everything python-can's LogReader reads.

Every reader has the same shape: opened on a path (a missing file raises at once), a context
manager, an iterable of :class:`~decoders.model.CanFrame` (iterate once), and ``errors``: the
damage found in the file ("line 12: cannot parse: ...", "file truncated ..."), recorded instead
of raised, after every frame before the damage has been yielded. ``warnings`` holds notes that
are not damage (relative timestamps, an unfinished file), ``frames`` counts the frames yielded
and ``tell()`` gives the byte position for progress bars where the format allows.

candump logs get a parser of their own (:class:`CandumpReader`): python-can's
``CanutilsLogReader`` builds a ``can.Message`` per line at about 200k lines/s, which alone would
eat the pipeline's budget; this one does about 1M lines/s and also reads what candump writes
and python-can does not (remote DLCs ``123#R5``, the DLC 9-15 suffix ``#..._F``, error frame
payloads). The other formats go through python-can (:class:`PythonCanFileReader`).

``open_can_file(path)`` chooses by suffix (``CAN_READERS``); ``.gz`` compressed files of any
of them are read too (``trace.asc.gz``).
"""

from __future__ import annotations

import binascii
import gzip
import io
import os
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import Any, Protocol

import can

from decoders.model import CanFrame

from ..lifecycle import Closing

MAX_ERRORS = 100  # errors listed per file; ``bad_lines`` counts them all
READ_BUFFER = 1 << 20

CAN_ERR_FLAG = 0x20000000  # SocketCAN: error frame; the identifier carries the error class
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


def message_to_frame(msg: can.Message) -> CanFrame:
    """A python-can Message as the decoders' CanFrame.

    More than 8 data bytes make a frame CAN FD even where the format lost the flag (.csv).
    """
    data = bytes(msg.data) if msg.data is not None else b""
    return CanFrame(
        t=msg.timestamp,
        arbitration_id=msg.arbitration_id,
        data=data,
        is_extended=msg.is_extended_id,
        is_remote=msg.is_remote_frame,
        is_error=msg.is_error_frame,
        is_fd=msg.is_fd or len(data) > 8,
        dlc=msg.dlc,
        channel=str(msg.channel) if msg.channel is not None else None,
    )


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


class CandumpReader(_FileReaderBase):
    """candump -L log lines: ``(1600000000.123456) can0 04FF0001#0000F401F401``.

    Standard (3 hex digits) and extended (8) identifiers, remote frames ``123#R`` / ``123#R5``,
    error frames (CAN_ERR_FLAG 0x20000000 in the identifier: ``is_error``, the identifier
    keeps the error class), CAN FD ``123##<flags><data>``, the classic DLC 9-15 suffix
    ``123#1122334455667788_F``, and the direction flag python-can appends (`` R`` / `` T``).
    Blank lines and ``#`` comments are skipped; any other line that does not parse is counted
    in ``bad_lines`` and listed in ``errors`` ("line N: cannot parse: ...") and skipped.
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
            for lineno, line in enumerate(f, 1):
                # the fast path: "(stamp) channel ID#HEXDATA" with a 3- or 8-digit data frame
                try:
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
                    text = line.decode("ascii", "replace").strip()
                    if len(text) > 80:
                        text = text[:77] + "..."
                    self._error(f"line {lineno}: cannot parse: {text!r} ({exc})")
                    continue
                if parsed is None:
                    skipped += 1
                    continue
                yield parsed
        except (OSError, EOFError) as exc:  # a cut or damaged .gz
            self._error(f"line {lineno + 1}: read error: {type(exc).__name__}: {exc}")
        finally:
            self.frames = lineno - skipped


_HEX_DIGITS = frozenset(b"0123456789abcdefABCDEF")
_DIRECTIONS = frozenset({b"R", b"T", b"r", b"t"})  # python-can appends the direction


def _parse_candump(line: bytes, channels: dict[bytes, str]) -> CanFrame | None:
    """Any candump -L line: a CanFrame, None for a blank or comment line; else ValueError
    saying what is wrong."""
    parts = line.split()
    if not parts or parts[0][:1] == b"#":
        return None
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
_PYTHON_CAN_READERS: dict[str, Any] = {
    ".asc": can.ASCReader,
    ".blf": can.BLFReader,
    ".trc": can.TRCReader,
    ".csv": can.CSVReader,
    ".mf4": can.MF4Reader,
}
_BINARY_SUFFIXES = frozenset({".blf", ".mf4"})


class PythonCanFileReader(_FileReaderBase):
    """Any format python-can reads (.asc, .blf, .trc, .csv, .mf4), as CanFrames.

    ASC timestamps are made absolute from the file's "Begin Triggerblock" date (to the
    millisecond the format keeps); when that date cannot be parsed they stay relative and
    ``warnings`` says so. A truncated or corrupt file yields every frame before the damage and
    records the error; a .blf cut short (or never finished by its writer) is detected from the
    file size its header states.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        super().__init__(path)
        self.suffix = _format_suffix(self.path)
        reader_type = _PYTHON_CAN_READERS.get(self.suffix)
        if reader_type is None:
            raise ValueError(_unsupported(self.path))
        if not self.path.exists():
            raise FileNotFoundError(f"CAN capture not found: {self.path}")
        self._reader_type = reader_type
        self._reader: Any = None
        self._relative = False
        self._reader = self._open(relative=False)

    def _open(self, relative: bool) -> Any:
        binary = self.suffix in _BINARY_SUFFIXES
        kwargs: dict[str, Any] = {}
        if self.suffix == ".asc":
            kwargs["relative_timestamp"] = relative
        if self._file is not None:
            self._file.close()
        try:
            # text formats: a stray non-UTF-8 byte (a comment in a local code page) must not
            # end the file early
            text: dict[str, Any] = {} if binary else {"encoding": "utf-8", "errors": "replace"}
            if is_gzip(self.path):
                mode = "rb" if binary else "rt"
                self._file = gzip.open(self.path, mode, **text)  # noqa: SIM115
            else:
                self._file = open(self.path, "rb" if binary else "r", **text)  # noqa: SIM115
            return self._reader_type(self._file, **kwargs)
        except NotImplementedError as exc:  # e.g. .mf4 without asammdf
            raise ValueError(f"cannot read {self.path.name}: {exc}") from exc
        except OSError:
            raise
        except Exception as exc:  # a damaged header: nothing to read
            self._error(f"{self.path.name}: cannot open: {_exc_text(exc)}")
            return None

    def __iter__(self) -> Iterator[CanFrame]:
        if self._reader is None:
            return
        count = 0
        convert = message_to_frame
        try:
            for msg in self._reader:
                count += 1
                self.frames = count
                if count == 1 and self.suffix == ".asc" and not self._relative:
                    self._check_asc_start()
                yield convert(msg)
        except Exception as exc:
            if (
                count == 0
                and self.suffix == ".asc"
                and not self._relative
                and "datetime" in str(exc).lower()
            ):
                # the ASC start date is in a form python-can cannot parse: keep relative times
                self._relative = True
                self.warnings.append(
                    f"{self.path.name}: timestamps are relative to the start of the capture "
                    f"(cannot read its start date: {exc})"
                )
                self._reader = self._open(relative=True)
                yield from self.__iter__()
                return
            self._error(f"{self.path.name}: damaged after {count} frames: {_exc_text(exc)}")
            return
        if self.suffix == ".blf":
            self._check_blf()

    def _check_asc_start(self) -> None:
        if getattr(self._reader, "start_time", None) == 0.0:
            self._relative = True
            self.warnings.append(
                f"{self.path.name}: timestamps are relative to the start of the capture "
                "(no start date in the file)"
            )

    def _check_blf(self) -> None:
        reader = self._reader
        stated = int(getattr(reader, "file_size", 0) or 0)
        if is_gzip(self.path):
            return  # the header states the uncompressed size; nothing to compare against
        actual = self.path.stat().st_size
        header_size = 144  # BLF file header (FILE_HEADER_SIZE)
        if stated == header_size and actual > stated:
            self.warnings.append(
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


def _exc_text(exc: BaseException) -> str:
    kind = type(exc)
    name = kind.__name__ if kind.__module__ == "builtins" else f"{kind.__module__}.{kind.__name__}"
    return f"{name}: {exc}"


def _format_suffix(path: Path) -> str:
    """The format suffix, looking through .gz (``trace.asc.gz`` -> ``.asc``)."""
    suffixes = [s.lower() for s in path.suffixes]
    if suffixes and suffixes[-1] == ".gz":
        return suffixes[-2] if len(suffixes) >= 2 else ""
    return suffixes[-1] if suffixes else ""


CAN_READERS: dict[str, type[CandumpReader] | type[PythonCanFileReader]] = {
    ".log": CandumpReader,
    ".asc": PythonCanFileReader,
    ".blf": PythonCanFileReader,
    ".trc": PythonCanFileReader,
    ".csv": PythonCanFileReader,
    ".mf4": PythonCanFileReader,
}


def _unsupported(path: Path) -> str:
    supported = ", ".join(sorted(CAN_READERS))
    return (
        f"{path.name}: unsupported CAN capture suffix {_format_suffix(path) or '(none)'!r}; "
        f"supported: {supported} (each also .gz compressed)"
    )


def is_can_file(path: str | os.PathLike[str]) -> bool:
    """Whether open_can_file would pick a reader for this path's suffix."""
    return _format_suffix(Path(path)) in CAN_READERS


def open_can_file(path: str | os.PathLike[str]) -> CandumpReader | PythonCanFileReader:
    """The reader for a CAN capture, chosen by its suffix (like python-can's LogReader)."""
    p = Path(path)
    reader_type = CAN_READERS.get(_format_suffix(p))
    if reader_type is None:
        raise ValueError(_unsupported(p))
    return reader_type(p)
