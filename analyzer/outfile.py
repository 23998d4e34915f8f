"""Output files that never destroy a user's file.

- An output that is the same file as an input (compared by device and inode, so links and other
  spellings of the path are caught) is refused before anything is opened.
- An output is written under a temporary name beside it and renamed over the real name only at
  the end, so an existing file is never truncated by a run that then fails to start; a run that
  fails with an error leaves the old file as it was.
- Errors name the file: "cannot write out.jsonl: [Errno 28] No space left on device".
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO, Any

from .errors import UsageError


def check_not_input(
    output: str | os.PathLike[str], inputs: Iterable[str | os.PathLike[str]]
) -> None:
    """UsageError if ``output`` is one of ``inputs`` (same device and inode)."""
    try:
        out = os.stat(output)
    except OSError:
        return  # does not exist yet: cannot be an input
    for path in inputs:
        try:
            st = os.stat(path)
        except OSError:
            continue
        if (st.st_dev, st.st_ino) == (out.st_dev, out.st_ino):
            raise UsageError(
                f"the output {os.fspath(output)} is the input {os.fspath(path)}: "
                "writing it would destroy the capture; choose another output name"
            )


class OutputError(OSError):
    """Writing an output failed; the message names the file."""


def check_new_file(path: str | os.PathLike[str], force: bool) -> None:
    """Before a command makes ``path`` (a recording: the user's data, not derived from an
    input): UsageError if a file is there already, unless ``force``; OutputError, in words,
    if its folder is missing or not writable."""
    target = Path(path)
    if target.is_dir():
        raise UsageError(f"the output {os.fspath(path)} is a directory")
    if target.exists() and not force:
        raise UsageError(
            f"{os.fspath(path)} already exists: give --force to replace it, or another name"
        )
    folder = target.parent
    if not folder.is_dir():
        raise OutputError(f"cannot write {os.fspath(path)}: there is no folder {folder}")
    if not os.access(folder, os.W_OK):
        raise OutputError(f"cannot write {os.fspath(path)}: the folder {folder} is not writable")


@contextlib.contextmanager
def output_stream(
    path: str | None, binary: bool, inputs: Iterable[str | os.PathLike[str]] = ()
) -> Iterator[IO[Any]]:
    """stdout when ``path`` is None or "-", else a new file written under a temporary name and
    renamed into place when the block ends without an error."""
    if path is None or path == "-":
        yield sys.stdout.buffer if binary else sys.stdout
        return
    check_not_input(path, inputs)
    target = Path(path)
    if target.is_dir():
        raise UsageError(f"the output {path} is a directory")
    if target.exists() and not target.is_file():  # a device or a pipe: write to it as it is
        yield from _special(path, binary)
        return
    try:
        fd, tmp = tempfile.mkstemp(
            prefix=f".{target.name}.", suffix=".part", dir=target.parent or "."
        )
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    f: IO[Any] = os.fdopen(fd, "wb") if binary else os.fdopen(fd, "w", newline="", encoding="utf-8")
    ok = False
    try:
        yield f
        ok = True
    finally:
        try:
            f.close()
            if ok:
                _keep_mode(target, tmp)
                os.replace(tmp, target)
        except OSError as exc:
            ok = False
            raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
        finally:
            if not ok:
                with contextlib.suppress(OSError):
                    os.unlink(tmp)


def _special(path: str, binary: bool) -> Iterator[IO[Any]]:
    try:
        f = open(path, "wb" if binary else "w")  # noqa: SIM115 - closed below
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    try:
        yield f
    finally:
        try:
            f.close()
        except OSError as exc:
            raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None


def _keep_mode(target: Path, tmp: str) -> None:
    """A new file gets the usual permissions (mkstemp makes it 0600); a replaced one keeps its."""
    try:
        mode = target.stat().st_mode & 0o777
    except OSError:
        umask = os.umask(0)
        os.umask(umask)
        mode = 0o666 & ~umask
    os.chmod(tmp, mode)
