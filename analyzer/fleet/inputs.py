"""Which files a batch run takes, and their content hash.

Each argument is a file, a folder (searched recursively) or a glob pattern
(``site-a/**/*.mcap``; ``**`` spans folders). A file named or matched explicitly is taken
whatever it holds (as ``decode`` takes it). A folder contributes the files that are captures by
their suffix or by their content (``sources.sniff``: ``candump can0 > run.txt``, a log with no
suffix), so notes, scripts and READMEs beside the captures are left alone; those it leaves are
counted (``Inputs.passed_over``), so the run can say so. A raw dump is told by its suffix only
(any bytes could be one).
"""

from __future__ import annotations

import glob
import hashlib
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

from ..errors import UsageError
from ..sources import sniff
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
    """Whether a file in a folder is a capture: by its suffix, else by what it holds."""
    return capture_suffix(path) in CAPTURE_SUFFIXES or sniff.sniff(path) is not None


def _hidden(path: Path, top: Path) -> bool:
    return any(part.startswith(".") for part in path.relative_to(top).parts)


@dataclass
class Inputs:
    """The capture files a batch takes, and the files in its folders it passed over."""

    paths: list[Path] = field(default_factory=list)
    passed_over: list[Path] = field(default_factory=list)


def _in_folder(folder: Path, inputs: Inputs) -> list[Path]:
    files = [p for p in folder.rglob("*") if p.is_file() and not _hidden(p, folder)]
    taken = [p for p in files if is_capture(p)]
    inputs.passed_over += sorted(set(files) - set(taken))
    return taken


def expand(arguments: Iterable[str], exclude: Path | None = None) -> Inputs:
    """The capture files the arguments name, each once, in a stable order; a usage error for
    an argument that names nothing (a typo must not look like an empty folder)."""
    inputs = Inputs()
    found: dict[Path, None] = {}
    for arg in arguments:
        path = Path(arg)
        if path.is_dir():
            matches = _in_folder(path, inputs)
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
        inputs.passed_over = [p for p in inputs.passed_over if not p.resolve().is_relative_to(out)]
    inputs.paths = list(found)
    taken = set(found)
    inputs.passed_over = [p for p in inputs.passed_over if p.resolve() not in taken]
    return inputs


def passed_over_note(passed_over: list[Path], shown: int = 3) -> str:
    """What the run says of the files in its folders that it did not take."""
    names = ", ".join(p.name for p in passed_over[:shown])
    more = ", ..." if len(passed_over) > shown else ""
    files = "file" if len(passed_over) == 1 else "files"
    return (
        f"passed over {len(passed_over)} {files} in the folders that are no capture by "
        f"suffix or content ({names}{more}); name a file, or a pattern, to take it as a raw "
        "serial dump"
    )


def content_hash(path: Path) -> str:
    """The hex SHA-256 of a file's bytes (``sha256sum`` prints the same)."""
    with path.open("rb") as f:
        return hashlib.file_digest(f, HASH_NAME).hexdigest()


def check_protocol(paths: Iterable[Path], protocol: str | None) -> None:
    """``--protocol`` on a capture it cannot apply to (serial or modbus on a CAN log, CAN on a
    raw dump) is a usage error before anything is written, as ``decode`` makes it."""
    if protocol is None:
        return
    from ..session.capture import CaptureOptions, open_reader
    from ..sources.capture import open_capture

    for path in paths:
        try:
            open_capture(path).close()
        except (OSError, ValueError):
            continue  # unreadable: its task says why, and the others go on
        open_reader(CaptureOptions(str(path), protocol)).close()
