"""Capture files chosen by their full suffix (``.log.gz`` is a gzipped candump log, not serial
bytes), compressed and cut captures, unreadable files, and the lazy reader registry."""

from __future__ import annotations

import gzip
import os
import subprocess
import sys
import zlib
from pathlib import Path

import can
import pytest

from analyzer.errors import UsageError
from analyzer.sources.capture import (
    CAPTURE_READERS,
    CanLogReader,
    GzipBytesReader,
    RawBytesReader,
    open_capture,
    reader_for,
)
from decoders.model import CanFrame, Chunk

ROOT = Path(__file__).resolve().parents[2]
T0 = 1600000000.0
CAN_LOG = "analyzer.sources.capture:CanLogReader"


@pytest.mark.parametrize(
    "name,target",
    [
        ("can.log", CAN_LOG),
        ("can.log.gz", CAN_LOG),
        ("trace.asc.gz", CAN_LOG),
        ("trace.BLF.GZ", CAN_LOG),
        ("trace.trc.gz", CAN_LOG),
        ("trace.csv.gz", CAN_LOG),
        ("trace.mf4", CAN_LOG),
        ("run.2024.05.log", CAN_LOG),
        ("run.mcap", "analyzer.recording.reader:McapCaptureReader"),
        ("RUN.MCAP", "analyzer.recording.reader:McapCaptureReader"),
        ("dump.bin.gz", "analyzer.sources.capture:GzipBytesReader"),
        ("dump.gz", "analyzer.sources.capture:GzipBytesReader"),
        ("dump.bin", "analyzer.sources.capture:RawBytesReader"),
        ("dump", "analyzer.sources.capture:RawBytesReader"),
        ("can.log.bak", "analyzer.sources.capture:RawBytesReader"),
    ],
)
def test_reader_by_full_suffix(name: str, target: str) -> None:
    assert reader_for(name) == target


@pytest.mark.parametrize("name", ["trace.mf4.gz", "run.mcap.gz", "RUN.MCAP.GZ"])
def test_compressed_kinds_that_cannot_be_read_compressed(tmp_path: Path, name: str) -> None:
    path = tmp_path / name
    path.write_bytes(gzip.compress(b"whatever"))
    with pytest.raises(UsageError, match=rf"cannot be read .*decompress it first \(gunzip {name}"):
        open_capture(path)


def test_registry_is_lazy_names() -> None:
    assert all(":" in target for target in CAPTURE_READERS.values())
    assert CAPTURE_READERS[".mcap"] == "analyzer.recording.reader:McapCaptureReader"
    code = (
        "import sys\n"
        "from analyzer.sources.capture import open_capture\n"
        "open_capture(sys.argv[1]).close()\n"
        "print('analyzer.recording.reader' in sys.modules, 'mcap' in sys.modules)\n"
    )
    log = ROOT / "tests" / "sources" / "test_capture_readers.py"  # any file: read as bytes
    out = subprocess.run(
        [sys.executable, "-c", code, str(log)], capture_output=True, text=True, cwd=ROOT, check=True
    )
    assert out.stdout.split() == ["False", "False"]


def _messages(n: int) -> list[can.Message]:
    return [
        can.Message(
            timestamp=T0 + i * 0.001,
            arbitration_id=0x01180001 + i % 3,
            data=i.to_bytes(4, "little") * 2,
            channel=0,
        )
        for i in range(n)
    ]


def _write(path: Path, messages: list[can.Message]) -> None:
    with can.Logger(str(path)) as logger:
        for m in messages:
            logger.on_message_received(m)


def _frames(path: Path) -> tuple[list[CanFrame], list[str], str]:
    with open_capture(path) as reader:
        items = list(reader)
    frames = [i.payload for i in items]
    assert all(isinstance(f, CanFrame) for f in frames)
    return frames, reader.errors, reader.kind  # type: ignore[return-value]


@pytest.mark.parametrize("fmt", [".log", ".asc", ".blf", ".trc", ".csv"])
def test_gzipped_can_captures_are_read_as_can(tmp_path: Path, fmt: str) -> None:
    plain = tmp_path / f"capture{fmt}"
    _write(plain, _messages(300))
    packed = tmp_path / f"capture{fmt}.gz"
    packed.write_bytes(gzip.compress(plain.read_bytes()))
    want, errors, kind = _frames(plain)
    got, errors_gz, kind_gz = _frames(packed)
    assert (kind, kind_gz) == ("can", "can")
    assert errors == errors_gz == []
    assert got == want and len(got) == 300
    with open_capture(packed) as reader:
        assert isinstance(reader, CanLogReader)


def _recoverable(packed: bytes) -> bytes:
    """What a gzip stream cut short still gives."""
    return zlib.decompressobj(wbits=31).decompress(packed)


@pytest.mark.parametrize("fmt", [".log", ".asc", ".blf", ".trc", ".csv"])
@pytest.mark.parametrize("keep", [0.5, 0.9])
def test_cut_gzipped_can_captures(tmp_path: Path, fmt: str, keep: float) -> None:
    plain = tmp_path / f"capture{fmt}"
    _write(plain, _messages(12000))
    packed = gzip.compress(plain.read_bytes())
    cut = tmp_path / f"cut{fmt}.gz"
    cut.write_bytes(packed[: int(len(packed) * keep)])
    whole, _, _ = _frames(plain)
    got, errors, kind = _frames(cut)
    assert kind == "can"
    assert 0 < len(got) < len(whole)
    assert got == whole[: len(got)]  # every frame before the cut, none changed
    assert errors  # and it says so
    if fmt in (".log", ".csv"):  # one frame per line: every complete line was read
        complete = _recoverable(cut.read_bytes()).count(b"\n")
        header = 1 if fmt == ".csv" else 0
        assert len(got) == complete - header


def test_gzipped_serial_bytes(tmp_path: Path) -> None:
    data = bytes(range(256)) * 2000
    packed = gzip.compress(data)
    whole = tmp_path / "dump.bin.gz"
    whole.write_bytes(packed)
    with open_capture(whole) as reader:
        assert isinstance(reader, GzipBytesReader) and reader.kind == "bytes"
        got = b"".join(i.payload.data for i in reader if isinstance(i.payload, Chunk))
    assert got == data and reader.errors == []
    cut = tmp_path / "cut.gz"
    cut.write_bytes(packed[: len(packed) // 2])
    with open_capture(cut) as reader:
        got = b"".join(i.payload.data for i in reader if isinstance(i.payload, Chunk))
    assert got == _recoverable(cut.read_bytes()) and 0 < len(got) < len(data)
    assert reader.errors and "cut short" in reader.errors[0]
    assert reader.position == reader.size


def test_raw_bytes_still_read_whole(tmp_path: Path) -> None:
    path = tmp_path / "dump.bin"
    path.write_bytes(b"\xeb\x90\x01\x01\x12\x14" * 30000)
    with open_capture(path) as reader:
        assert isinstance(reader, RawBytesReader)
        got = b"".join(i.payload.data for i in reader if isinstance(i.payload, Chunk))
    assert got == path.read_bytes() and reader.position == reader.size


# -- unreadable files: the same OSError, naming the file, for every format ------------------------

UNREADABLE = ["x.log", "x.log.gz", "x.asc", "x.blf", "x.trc", "x.csv", "x.bin", "x.gz", "x.mcap"]


def _open_error(path: Path) -> str:
    """How opening ``path`` fails for an unprivileged user (a child process that drops root;
    chmod 000 is enough when the tests do not run as root)."""
    if os.geteuid() != 0:
        try:
            open_capture(path).close()
        except OSError as exc:
            return f"{type(exc).__name__}|{exc}"
        return "opened"
    import analyzer.recording.reader  # noqa: F401  (imported here: the child cannot read /root)

    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        try:
            os.close(r)
            os.setgid(65534)
            os.setuid(65534)
            try:
                open_capture(path).close()
                text = "opened"
            except OSError as exc:
                text = f"{type(exc).__name__}|{exc}"
            except BaseException as exc:
                text = f"other|{type(exc).__name__}|{exc}"
            os.write(w, text.encode())
        finally:
            os._exit(0)
    os.close(w)
    with os.fdopen(r, "rb") as f:
        text = f.read().decode()
    os.waitpid(pid, 0)
    return text


@pytest.fixture
def shared_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A directory everyone may look into (pytest's own are private to root)."""
    d = tmp_path_factory.mktemp("shared")
    for p in (d, *d.parents):
        if str(p).startswith("/tmp/") or p == d:
            p.chmod(0o755)
    return d


@pytest.mark.parametrize("name", UNREADABLE)
def test_unreadable_file_is_an_os_error_naming_it(shared_dir: Path, name: str) -> None:
    path = shared_dir / name
    path.write_bytes(b"\x00" * 100)
    path.chmod(0)
    assert _open_error(path) == f"PermissionError|cannot read {path}: permission denied"


@pytest.mark.parametrize("engine", ["python", "native"])
@pytest.mark.parametrize("garbled", ["11ZZZ", "1180002x Rx d 8 00 0Z"])
def test_a_garbled_asc_frame_line_is_damage_where_it_is(
    tmp_path: Path, engine: str, garbled: str
) -> None:
    """A frame line python-can's ASC reader skips in silence is reported with its line number,
    exit 3, and every other frame is decoded (both engines read .asc through python-can)."""
    path = tmp_path / "corrupt.asc"
    messages = _messages(20)
    _write(path, messages)
    lines = path.read_text().splitlines(keepends=True)
    frame_lines = [n for n, line in enumerate(lines) if " Rx " in line]
    bad = frame_lines[7]
    lines[bad] = f" 0.043885 1  {garbled}\n"
    path.write_text("".join(lines))
    proc = subprocess.run(
        [sys.executable, "-m", "analyzer", "decode", str(path), "-f", "jsonl", "--engine", engine],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 3, proc.stderr
    assert f"line {bad + 1}: cannot parse: '0.043885 1  {garbled}'" in proc.stderr
    assert len(proc.stdout.splitlines()) == len(messages) - 1
