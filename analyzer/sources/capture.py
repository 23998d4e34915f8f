"""Capture files as a stream of pipeline Items, chosen by what they hold (``sniff``: binary
formats by their magic, text logs by their first line), else by their full suffix (as
python-can's LogReader chooses its readers).

- CAN logs: candump logs in every layout, PCAN traces and everything python-can reads
  (``can_files``), also gzip compressed where they can be read from a stream (``can.log.gz``,
  ``trace.asc.gz``);
- eg2scope recordings: ``.mcap`` (``analyzer.recording.reader``: the raw topics are decoded again,
  the recorded source events come back in place);
- anything else: raw bytes of a serial line (regular serial protocol or Modbus RTU); ``.gz``:
  such bytes, compressed.

``CAPTURE_READERS`` maps a suffix to ``"module:Class"``; a reader's module is imported only
when a file of its kind is opened. Every reader is a context manager and an iterable of Items
(and, from a recording, of SourceEvents), with ``size``/``position`` (bytes) for progress bars
and ``errors``: damage found in the file, reported instead of raised, after yielding
everything before it (non-empty ``errors``: the input was damaged). A file that cannot be read
at all raises ``OSError`` naming it, the same for every format.
"""

from __future__ import annotations

import gzip
import importlib
import os
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from decoders.model import Chunk

from ..errors import UsageError
from ..lifecycle import Closing
from ..model import Item, SourceEvent
from . import can_files, sniff
from .compressed import compression_damage

READ_SIZE = 1 << 14  # a raw dump's chunk: one batch of a session (source.CAPTURE_BATCH_BYTES)

_CAN_LOG = "analyzer.sources.capture:CanLogReader"
#: suffix (lower case, compound ones whole: ".log.gz") -> "module:Class" of its reader
CAPTURE_READERS: dict[str, str] = {
    **{suffix: _CAN_LOG for suffix in sorted(can_files.CAN_SUFFIXES)},
    ".mcap": "analyzer.recording.reader:McapCaptureReader",
    ".gz": "analyzer.sources.capture:GzipBytesReader",
}
RAW_BYTES = "analyzer.sources.capture:RawBytesReader"  # any other suffix


class CaptureReader(Closing):
    """Base: a capture file opened for reading. Subclasses implement ``__iter__``."""

    kind = "bytes"  # or "can"
    # one byte stream, or CAN frames numbered across the file: records can be numbered by
    # their place in the input (offset / index), which parallel decoding relies on
    single_stream = False

    def __init__(self, path: str | os.PathLike[str], bus: str | None = None) -> None:
        self.path = Path(path)
        check_readable(self.path)
        self.bus = bus
        self.size = self.path.stat().st_size
        self.position = 0
        self.errors: list[str] = []
        self.metadata: dict[str, Any] = {}
        # the protocol of each byte bus, where the capture says it (a recording): bus -> name
        self.protocols: dict[str, str] = {}

    def __iter__(self) -> Iterator[Item | SourceEvent]:
        raise NotImplementedError

    def close(self) -> None:
        pass


def check_readable(path: Path) -> None:
    """OSError naming ``path`` unless it is a file this process may read (checked without
    opening it: a FIFO must not be opened twice)."""
    if not path.exists():
        raise FileNotFoundError(f"capture file not found: {path}")
    if path.is_dir():
        raise IsADirectoryError(f"capture path is a directory, not a file: {path}")
    if not os.access(path, os.R_OK):
        raise PermissionError(f"cannot read {path}: permission denied")


class RawBytesReader(CaptureReader):
    """A raw dump of a serial line: bytes only, no timing."""

    single_stream = True

    def __init__(self, path: str | os.PathLike[str], bus: str | None = None) -> None:
        super().__init__(path, bus)
        self._file = self.path.open("rb")

    def __iter__(self) -> Iterator[Item | SourceEvent]:
        bus = self.bus or "serial"
        read = self._file.read
        while data := read(READ_SIZE):
            self.position += len(data)
            yield Item(bus, Chunk(data))

    def close(self) -> None:
        self._file.close()


class GzipBytesReader(CaptureReader):
    """A gzip compressed raw dump of a serial line. A cut or damaged file yields every byte
    before the damage and says so in ``errors``. ``position`` counts compressed bytes."""

    single_stream = True

    def __init__(self, path: str | os.PathLike[str], bus: str | None = None) -> None:
        super().__init__(path, bus)
        self._raw = self.path.open("rb")
        self._file = gzip.GzipFile(fileobj=self._raw, mode="rb")

    def __iter__(self) -> Iterator[Item | SourceEvent]:
        bus = self.bus or "serial"
        total = 0
        try:
            while data := self._file.read1(READ_SIZE):  # read1: nothing held back at a cut
                total += len(data)
                self.position = self._raw.tell()
                yield Item(bus, Chunk(data))
        except (OSError, EOFError, zlib.error) as exc:
            after = f" after {total} bytes"
            words = compression_damage(exc, at_start=total == 0, after=after)
            self.errors.append(
                words or f"read error{after} ({type(exc).__name__}: {exc}); the rest is lost"
            )
        self.position = self.size

    def close(self) -> None:
        self._file.close()
        self._raw.close()


def can_bus_name(channel: str | None) -> str:
    """python-can channels are often numbers (ASC, BLF): name them the SocketCAN way."""
    if channel is None or channel == "":
        return "can0"
    if channel.isdigit():
        return f"can{channel}"
    return channel


class CanLogReader(CaptureReader):
    """A CAN capture in any format ``can_files`` knows."""

    kind = "can"
    single_stream = True

    def __init__(self, path: str | os.PathLike[str], bus: str | None = None) -> None:
        super().__init__(path, bus)
        self._reader = can_files.open_can_file(self.path)

    def __iter__(self) -> Iterator[Item | SourceEvent]:
        reader = self._reader
        fixed = self.bus
        names: dict[str | None, str] = {}
        size = max(self.size, 1)
        last_channel: str | None = None
        name = fixed or can_bus_name(None)
        for count, frame in enumerate(reader, 1):
            channel = frame.channel
            if channel != last_channel and not fixed:
                last_channel = channel
                name = names.get(channel) or names.setdefault(channel, can_bus_name(channel))
            if not count & 0x3FF:
                self.position = min(size, _tell(reader, count, size))
            yield Item(name, frame)
        self.position = self.size
        self.errors += reader.errors

    def close(self) -> None:
        self._reader.__exit__(None, None, None)


def _tell(reader: Any, count: int, size: int) -> int:
    tell = getattr(reader, "tell", None)
    if callable(tell):
        try:
            return int(tell())
        except (OSError, ValueError):
            pass
    return size // 2  # unknown position: show an indeterminate half-way bar


def reader_for(path: str | os.PathLike[str]) -> str:
    """The ``"module:Class"`` of the reader for ``path``: by what it holds, else by its longest
    registered suffix (``.log.gz`` before ``.gz``). UsageError for a compressed file of a kind
    that cannot be read compressed (``.mcap.gz``, ``.mf4.gz``)."""
    p = Path(path)
    held = sniff.sniff(p)
    if held == "bytes":
        return CAPTURE_READERS[".gz"] if can_files.is_gzip(p) else RAW_BYTES
    if held is not None:
        if can_files.is_gzip(p) and held not in can_files.GZIP_FORMATS:
            raise UsageError(can_files.compressed_unreadable(p, f".{held}"))
        return CAPTURE_READERS[".mcap"] if held == "mcap" else _CAN_LOG
    suffixes = [s.lower() for s in p.suffixes]
    for i in range(len(suffixes)):
        tail = "".join(suffixes[i:])
        if tail in CAPTURE_READERS and tail != ".gz":
            return CAPTURE_READERS[tail]
        inner = "".join(suffixes[i:-1])
        if suffixes[-1] == ".gz" and inner in CAPTURE_READERS:
            raise UsageError(can_files.compressed_unreadable(p, inner))
    if suffixes and suffixes[-1] == ".gz":
        return CAPTURE_READERS[".gz"]
    return RAW_BYTES


def _load(target: str) -> type[CaptureReader]:
    module, _, name = target.partition(":")
    reader: type[CaptureReader] = getattr(importlib.import_module(module), name)
    return reader


def open_capture(path: str | os.PathLike[str], bus: str | None = None) -> CaptureReader:
    """Open a capture by its suffix; anything unknown is read as raw serial bytes."""
    return _load(reader_for(path))(Path(path), bus)
