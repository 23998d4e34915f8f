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
  analyzer/parquet/native.py), and there is no ``--speed`` (a timed replay).

Other CAN captures (PCAN traces, python-can's formats, CAN recordings) are read in Python and
decoded by the session, natively where the core is built
(analyzer/session/batches.py); a session on a
candump log (``plot``, ``tui``) gets its frames from the core's reader (``candump_frames``)
when it decodes natively and no listener wants the raw items. A session on a raw dump
(``--speed``, ``stats``, ``cycles``, ``plot``, the TUI) decodes its one byte stream natively
too; several byte streams (recordings of serial lines, live taps) stay with the Python
decoders, the readable reference.
``--engine python`` forces the Python engine, ``--engine native`` the native one: the core's
own decode where it applies, the session's native decoding for the other CAN captures and raw
dumps, a usage error saying why for the rest.
"""

from __future__ import annotations

import os
from typing import Any

from ..extension import WHY_NOT, _native  # the core, for the modules that ask here
from ..sources.can_files import CandumpReader
from ..sources.capture import CanLogReader, CaptureReader, GzipBytesReader, RawBytesReader

ENGINES = ("auto", "python", "native")
FORMATS = ("jsonl", "csv", "text")
_I64_MAX = (1 << 63) - 1


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
    ``CanStage`` decodes with no Python object per frame), or None: the Python reader reads it
    (not a candump log on a regular file, or the core does not read it)."""
    if ineligible(reader, "jsonl", None, None):
        return None
    assert _native is not None  # ineligible() said so
    try:
        return _native.CandumpFrames(str(reader.path), reader.bus or None)
    except (_native.Unsupported, OSError):
        return None  # the Python reader reads it (and says why it cannot, if it cannot)
