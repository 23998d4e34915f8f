"""What a capture file holds, told from its first bytes, whatever its name: a candump log saved
as ``.txt`` or with no suffix at all is still a candump log, and a ``.log`` may hold a PCAN
trace. Binary formats by their magic (MCAP, BLF ``LOGG``, MF4 ``MDF``), text logs by their first
line that is not blank or a comment, a raw dump of a serial line by the control bytes no text
log holds and the valid frames in them (``bytes``: a serial dump saved as ``.log`` is still a
dump; random bytes are not). ``None``: nothing
recognised (the suffix decides).

native/src/sources/sniff.rs mirrors this module: both engines choose the same reader.
"""

from __future__ import annotations

import gzip
import os
import zlib
from pathlib import Path

from decoders.registry import detect_protocol

from ..extension import _native
from . import candump

HEAD_SIZE = candump.HEAD_SIZE
LINES = 32  # lines looked at for the first significant one

#: the first bytes of each binary format
MAGIC: dict[bytes, str] = {
    b"\x89MCAP0\r\n": "mcap",
    b"LOGG": "blf",
    b"MDF     ": "mf4",
    b"UnFinMF ": "mf4",  # an MF4 file its writer never finished
}
#: a text log's first significant line starts so (lower case): Vector ASC headers, python-can CSV
ASC_STARTS = (b"date ", b"base ", b"begin triggerblock", b"internal events logged",
              b"no internal events logged")  # fmt: skip
CSV_START = b"timestamp,arbitration_id,"
TRC_VERSION = b";$FILEVERSION"
#: bytes no text log holds (every C0 control but tab, line feed, vertical tab, form feed,
#: carriage return and escape): a head with one is a raw byte dump
BINARY = frozenset(range(0x20)) - {0x09, 0x0A, 0x0B, 0x0C, 0x0D, 0x1B}


def head(path: str | os.PathLike[str]) -> bytes:
    """The first HEAD_SIZE bytes (decompressed for a ``.gz`` name; what a damaged one gives
    before the damage); empty when the file cannot be read or is no regular file."""
    p = Path(path)
    try:
        if not p.is_file():  # a FIFO must not be read twice (nor a device): its name decides
            return b""
        if p.suffix.lower() == ".gz":
            data = b""
            with gzip.open(p, "rb") as f:
                try:
                    while len(data) < HEAD_SIZE and (block := f.read1(HEAD_SIZE - len(data))):
                        data += block
                except (OSError, EOFError, zlib.error):
                    pass
            return data
        with p.open("rb") as f:
            return f.read(HEAD_SIZE)
    except OSError:
        return b""


def sniff(path: str | os.PathLike[str]) -> str | None:
    """The format of a capture file from its content: "mcap", "blf", "mf4", "candump", "trc",
    "asc", "csv", "bytes" (a raw serial dump), or None."""
    return sniff_head(head(path))


def sniff_head(data: bytes) -> str | None:
    for magic, fmt in MAGIC.items():
        if data.startswith(magic):
            return fmt
    if not BINARY.isdisjoint(data) and _detect_protocol(data):
        return "bytes"
    full = len(data) >= HEAD_SIZE
    if data.startswith(candump.BOM):
        data = data[len(candump.BOM) :]
    lines = data.split(b"\n" if b"\n" in data or b"\r" not in data else b"\r")
    if full:
        lines.pop()  # the head may end inside a line
    commented = False  # ";" comments: a PCAN trace's header
    for line in lines[:LINES]:
        text = line.strip()
        if not text or text[:2] == b"//":
            continue
        if text[:1] == b";":
            if text.upper().startswith(TRC_VERSION):
                return "trc"
            commented = True
            continue
        lower = text.lower()
        if lower.startswith(ASC_STARTS):
            return "asc"
        if lower.startswith(CSV_START):
            return "csv"
        if text[:1] == b"#":
            continue
        return _frame_line(text, commented)
    return None


def _detect_protocol(data: bytes) -> str | None:
    """``detect_protocol``, by the native core when it is built (the same answer: tests/native
    checks it; the Python decoders take a third of a second over a 64 KiB head)."""
    return detect_protocol(data) if _native is None else _native.detect_protocol(data)


def _frame_line(text: bytes, commented: bool) -> str | None:
    """The format of a log's first frame line."""
    try:
        if candump.parse_line(text + b"\n", {}, candump.Clock()) is not None:
            return "candump"
    except (ValueError, IndexError):
        pass
    first = text.split()[0]
    if first[-1:] == b")" and first[:-1].isdigit():  # a PCAN trace 1.x message number "12)"
        return "trc"
    if commented and first.isdigit():  # 2.x: "12" after the ";" header
        return "trc"
    return None
