"""Which files a batch run takes, and their content hash.

Each argument is a file, a folder (searched recursively for captures, by suffix) or a glob
pattern (``site-a/**/*.mcap``; ``**`` spans folders). A file named or matched explicitly is
taken whatever its suffix (as ``decode`` takes it); a folder contributes only files with a
capture suffix, so notes, scripts and READMEs beside the captures are left alone.
"""

from __future__ import annotations

import glob
import hashlib
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Final

from ..errors import UsageError
from ..sources.can_files import CAN_SUFFIXES

# raw serial dumps (regular protocol or Modbus RTU), as the simulator and `record` write them
RAW_SUFFIXES: Final = frozenset({".bin", ".raw", ".dump", ".bin.gz", ".raw.gz", ".dump.gz"})
CAPTURE_SUFFIXES: Final = frozenset({*CAN_SUFFIXES, ".mcap", *RAW_SUFFIXES})
HASH_NAME: Final = "sha256"  # `sha256sum FILE` finds a capture's rows


def capture_suffix(path: Path) -> str:
    """The suffix that says a file's format: compound where compressed (``.log.gz``)."""
    suffixes = [s.lower() for s in path.suffixes]
    if len(suffixes) >= 2 and suffixes[-1] == ".gz":
        return "".join(suffixes[-2:])
    return suffixes[-1] if suffixes else ""


def is_capture(path: Path) -> bool:
    return capture_suffix(path) in CAPTURE_SUFFIXES


def _hidden(path: Path, top: Path) -> bool:
    return any(part.startswith(".") for part in path.relative_to(top).parts)


def _in_folder(folder: Path) -> list[Path]:
    return [
        p for p in folder.rglob("*") if p.is_file() and is_capture(p) and not _hidden(p, folder)
    ]


def expand(arguments: Iterable[str], exclude: Path | None = None) -> list[Path]:
    """The capture files the arguments name, each once, in a stable order; a usage error for
    an argument that names nothing (a typo must not look like an empty folder)."""
    found: dict[Path, None] = {}
    for arg in arguments:
        path = Path(arg)
        if path.is_dir():
            matches = _in_folder(path)
        elif path.exists():
            matches = [path]
        elif glob.has_magic(arg):
            matches = [Path(p) for p in glob.glob(arg, recursive=True) if os.path.isfile(p)]
            if not matches:
                raise UsageError(f"no file matches {arg!r}")
        else:
            raise UsageError(f"capture not found: {arg}")
        for match in sorted(matches):
            found.setdefault(match.resolve(), None)
    if exclude is not None:
        out = exclude.resolve()
        found = {p: None for p in found if not p.is_relative_to(out)}
    return list(found)


def content_hash(path: Path) -> str:
    """The hex SHA-256 of a file's bytes (``sha256sum`` prints the same)."""
    with path.open("rb") as f:
        return hashlib.file_digest(f, HASH_NAME).hexdigest()
