"""Files named .mcap that are not recordings one can read: a FIFO, a file this process may not
read, random bytes. Each gets its own clear message and exit status, at once."""

from __future__ import annotations

import ctypes
import os
import tempfile
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from analyzer.cli import main
from analyzer.errors import EXIT_DAMAGED, EXIT_ERROR, EXIT_USAGE, UsageError
from analyzer.model import Item
from analyzer.recording.reader import (
    McapCaptureReader,
    read_events,
    read_metadata,
    read_records,
    read_states,
)
from analyzer.recording.recorder import McapRecorder
from analyzer.sources.capture import open_capture
from decoders import build as b

T0 = 1_763_700_000.0
NOBODY = 65534


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    try:
        code = main(list(argv))
    except SystemExit as exc:  # usage errors leave through argparse
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


def recording(path: Path) -> Path:
    with McapRecorder(path, {}) as rec:
        rec.on_raw([Item("can0", b.can_read_request(1, 1120, 8, t=T0))])
    return path


def finishes_within(seconds: float, call: Callable[[], object]) -> BaseException | None:
    """Run ``call`` on a thread; fail if it is still blocked after ``seconds`` (a FIFO open
    blocks until a writer comes). Returns what it raised."""
    raised: list[BaseException] = []

    def run() -> None:
        try:
            call()
        except BaseException as exc:
            raised.append(exc)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(seconds)
    assert not thread.is_alive(), "hangs on a FIFO"
    return raised[0] if raised else None


@pytest.fixture
def fifo(tmp_path: Path) -> Iterator[Path]:
    path = tmp_path / "x.mcap"
    os.mkfifo(path)
    yield path
    # unblock anything still waiting to open it for reading
    try:
        fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
        os.close(fd)
    except OSError:
        pass


@pytest.mark.parametrize(
    "call",
    [
        lambda p: open_capture(p),
        lambda p: McapCaptureReader(p),
        lambda p: list(read_records(p)),
        lambda p: list(read_events(p)),
        lambda p: list(read_states(p)),
        lambda p: read_metadata(p),
    ],
    ids=["open_capture", "reader", "records", "events", "states", "metadata"],
)
def test_a_fifo_is_refused_at_once(fifo: Path, call: Callable[[Path], object]) -> None:
    exc = finishes_within(5, lambda: call(fifo))
    assert isinstance(exc, UsageError), exc
    assert str(fifo) in str(exc) and "not a regular file" in str(exc)


@pytest.mark.parametrize("command", ["decode", "stats"])
def test_a_fifo_on_the_command_line_is_a_usage_error(
    fifo: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    result: list[tuple[int, str, str]] = []
    assert finishes_within(10, lambda: result.append(run_cli(capsys, command, str(fifo)))) is None
    code, out, err = result[0]
    assert code == EXIT_USAGE and out == ""
    assert f"{fifo}: not a regular file" in err and "Traceback" not in err


@contextmanager
def unreadable(path: Path) -> Iterator[None]:
    """``path`` cannot be opened for reading: mode 000 and, for root (whose capabilities read
    anything), this thread's filesystem uid set to nobody while the block runs."""
    path.chmod(0)
    try:
        if os.geteuid() != 0:
            yield
            return
        libc = ctypes.CDLL(None, use_errno=True)
        libc.setfsuid(NOBODY)
        try:
            if libc.setfsuid(-1) != NOBODY:  # -1 changes nothing and returns the current one
                pytest.skip("cannot change the filesystem uid here")
            yield
        finally:
            libc.setfsuid(0)
    finally:
        path.chmod(0o644)


@pytest.fixture
def readable_dir() -> Iterator[Path]:
    """A directory anyone may search (pytest's own are root's alone), so only the file's
    own permissions stop the reader."""
    path = Path(tempfile.mkdtemp(prefix="eg2scope-perm-"))
    path.chmod(0o755)
    yield path
    for child in path.iterdir():
        child.unlink()
    path.rmdir()


def test_an_unreadable_recording_raises_permission_error(readable_dir: Path) -> None:
    path = recording(readable_dir / "locked.mcap")
    with unreadable(path):
        for call in (
            lambda: open_capture(path),
            lambda: list(read_records(path)),
            lambda: read_metadata(path),
        ):
            with pytest.raises(PermissionError) as info:
                call()
            assert str(path) in str(info.value)
    with open_capture(path) as reader:  # and is read as soon as it may be
        assert len(list(reader)) == 1 and reader.errors == []


@pytest.mark.parametrize("command", ["decode", "stats"])
def test_an_unreadable_recording_exits_1_like_other_formats(
    readable_dir: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    path = recording(readable_dir / "locked.mcap")
    other = readable_dir / "locked.log"
    other.write_text(f"({T0:.6f}) can0 01180001#08\n")
    assert run_cli(capsys, command, str(path))[0] == 0  # imports everything while readable
    for target in (path, other):
        with unreadable(target):
            code, out, err = run_cli(capsys, command, str(target))
        assert code == EXIT_ERROR, (target, err)
        assert "permission denied" in err.lower() and str(target) in err, err
        assert "damaged" not in err and "Traceback" not in err
        if command == "stats":
            assert out == ""  # no empty tables


@pytest.mark.parametrize(
    "content", [os.urandom(2000), b"PK\x03\x04" + bytes(500)], ids=["random", "zip"]
)
def test_random_bytes_named_mcap_are_not_an_mcap_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: bytes
) -> None:
    path = tmp_path / "x.mcap"
    path.write_bytes(content)
    with open_capture(path) as reader:
        assert list(reader) == []
        assert reader.errors == ["not an MCAP file: it does not begin with the MCAP magic bytes"]
    code, _out, err = run_cli(capsys, "decode", str(path))
    assert code == EXIT_DAMAGED
    assert "not an MCAP file" in err and "killed" not in err and "Traceback" not in err


def test_a_candump_log_named_mcap_is_read_as_what_it_is(tmp_path: Path) -> None:
    """Text logs are told by their content (analyzer/sources/sniff.py), whatever their name."""
    path = tmp_path / "x.mcap"
    path.write_bytes(b"(1763700000.0) can0 123#00\n" * 20)
    with open_capture(path) as reader:
        assert reader.kind == "can" and len(list(reader)) == 20 and reader.errors == []
