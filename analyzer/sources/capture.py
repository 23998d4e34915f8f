"""Capture files as a stream of pipeline Items, chosen by suffix (as python-can's LogReader).

- CAN logs: candump -L ``.log`` and everything python-can's LogReader reads (``can_files``);
- eg2scope recordings: ``.mcap`` (the raw topics are decoded again);
- anything else: raw bytes of a serial line (regular serial protocol or Modbus RTU).

Every reader is a context manager and an iterable of Items, with ``size``/``position`` (bytes)
for progress bars and ``errors``: damage found in the file, reported instead of raised, after
yielding everything before it.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from decoders.model import Chunk

from ..lifecycle import Closing
from ..pipeline import Item
from . import can_files

READ_SIZE = 1 << 16


class CaptureReader(Closing):
    """Base: a capture file opened for reading. Subclasses implement ``__iter__``."""

    kind = "bytes"  # or "can"
    # one byte stream, or CAN frames numbered across the file: records can be numbered by
    # their place in the input (offset / index), which parallel decoding relies on
    single_stream = False

    def __init__(self, path: str | os.PathLike[str], bus: str | None = None) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise FileNotFoundError(f"capture file not found: {self.path}")
        if self.path.is_dir():
            raise IsADirectoryError(f"capture path is a directory, not a file: {self.path}")
        self.bus = bus
        self.size = self.path.stat().st_size
        self.position = 0
        self.errors: list[str] = []
        self.metadata: dict[str, Any] = {}

    def __iter__(self) -> Iterator[Item]:
        raise NotImplementedError

    def close(self) -> None:
        pass


class RawBytesReader(CaptureReader):
    """A raw dump of a serial line: bytes only, no timing."""

    single_stream = True

    def __iter__(self) -> Iterator[Item]:
        bus = self.bus or "serial"
        with self.path.open("rb") as f:
            while data := f.read(READ_SIZE):
                self.position += len(data)
                yield Item(bus, Chunk(data))


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

    def __iter__(self) -> Iterator[Item]:
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


Opener = Callable[[Path, str | None], CaptureReader]

# suffix -> reader; filled from can_files' registry, plus .mcap (recordings)
CAPTURE_READERS: dict[str, Opener] = {suffix: CanLogReader for suffix in can_files.CAN_READERS}


def register_reader(suffix: str, opener: Opener) -> None:
    CAPTURE_READERS[suffix.lower()] = opener


def open_capture(path: str | os.PathLike[str], bus: str | None = None) -> CaptureReader:
    """Open a capture by its suffix; anything unknown is read as raw serial bytes."""
    p = Path(path)
    opener = CAPTURE_READERS.get(p.suffix.lower(), RawBytesReader)
    return opener(p, bus)


from . import mcap_reader  # noqa: E402, F401  (registers .mcap; imported last: it imports this module)
