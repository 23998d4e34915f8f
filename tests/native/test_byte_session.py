"""A session on one byte stream (a raw serial or Modbus dump) decodes with the native
``ByteStage`` and tracks with the native ``Tracker`` (``analyzer/session/batches.py``): ``stats
--format json``, ``cycles --format jsonl`` and ``decode`` through a session (``--speed``) write
the same bytes as on the Python engine, and a capture stopped mid-way gives the same listener
calls, ``cut_off`` records included. Each input runs through both engines in this process."""

from __future__ import annotations

import gzip
import random
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from native_core import skip_or_fail, why_not

from analyzer import cli
from analyzer.session import batches, native_run
from analyzer.session.session import Session, SessionOptions
from analyzer.sources.capture import GzipBytesReader, RawBytesReader
from analyzer.sources.source import CAPTURE_BATCH_BYTES, CaptureSource
from decoders.model import EG2_SERIAL, MODBUS_RTU

if why := why_not():
    skip_or_fail(why)

import test_byte_stage as bs  # after the check (tests/native is on sys.path)
import test_native_session as ns

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = [ROOT / "captures" / "serial_session.bin", ROOT / "captures" / "modbus_session.bin"]


def damaged_dump(protocol: str, n: int, seed: int) -> bytes:
    """Realistic polling with damage throughout, a stretch of noise and zeros in the middle,
    and a frame cut short at the end."""
    data = bs.damaged(bs.traffic(protocol, n, seed), seed)
    rng = random.Random(seed)
    middle = len(data) // 2
    hole = rng.randbytes(3000) + bytes(500)
    return data[:middle] + hole + data[middle + 700 :] + data[:5]


@pytest.fixture(scope="module")
def dumps(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The sample dumps, and generated ones (several batches long; one gzip compressed)."""
    folder = tmp_path_factory.mktemp("dumps")
    out = {p.stem: p for p in SAMPLES}
    for protocol, name in ((EG2_SERIAL, "serial"), (MODBUS_RTU, "modbus")):
        path = out[f"damaged_{name}"] = folder / f"damaged_{name}.bin"
        path.write_bytes(damaged_dump(protocol, 30_000, seed=len(name)))
    gz = out["damaged_modbus_gz"] = folder / "damaged_modbus.bin.gz"
    gz.write_bytes(gzip.compress(out["damaged_modbus"].read_bytes()))
    return out


@pytest.fixture
def made(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[Any]]:
    """The native byte decodings the sessions make (to tell which engine ran)."""
    seen: list[Any] = []

    class Seen(batches.NativeByteDecoding):
        def __init__(self, protocol: str | None) -> None:
            super().__init__(protocol)
            seen.append(self)

    monkeypatch.setattr(batches, "NativeByteDecoding", Seen)
    yield seen


def run_cli(
    argv: list[str], python: bool, capsysbinary: pytest.CaptureFixture[bytes]
) -> tuple[int, bytes, bytes]:
    """(exit code, stdout, stderr) of a command; ``python``: the session's decoding as where
    the core is not built."""
    with pytest.MonkeyPatch.context() as mp:
        if python:
            for module in (batches, native_run):
                mp.setattr(module, "native_session_available", lambda: False)
        code = cli.main(argv)
    out, err = capsysbinary.readouterr()
    return code, out, err


COMMANDS = {
    "stats": ["stats", "--format", "json", "--no-progress"],
    "cycles": ["cycles", "--format", "jsonl", "--no-progress"],
    "decode": ["decode", "--format", "jsonl", "--speed", "1e6", "--no-progress"],
    "decode-text": ["decode", "--format", "text", "--speed", "1e6", "-e", "--colour", "never"],
}
INPUTS = ["serial_session", "modbus_session", "damaged_serial", "damaged_modbus"]
# each input detected; the damaged ones also with each protocol named (the other one too)
PROTOCOLS = [
    (name, protocol)
    for name in [*INPUTS, "damaged_modbus_gz"]
    for protocol in (["auto", "serial", "modbus"] if name.startswith("damaged") else ["auto"])
]


@pytest.mark.parametrize("command", list(COMMANDS))
@pytest.mark.parametrize(("name", "protocol"), PROTOCOLS)
def test_commands_write_the_same_bytes_on_both_engines(
    name: str,
    protocol: str,
    command: str,
    dumps: dict[str, Path],
    made: list[Any],
    capsysbinary: pytest.CaptureFixture[bytes],
) -> None:
    argv = [*COMMANDS[command], str(dumps[name]), "--protocol", protocol]
    python = run_cli(argv, True, capsysbinary)
    assert not made
    native = run_cli(argv, False, capsysbinary)
    assert made, "the native engine decoded"
    assert native == python
    assert python[0] in (0, 3), python[2]
    assert python[1] or (command == "cycles" and protocol != "auto"), python[2]


@pytest.mark.parametrize("name", INPUTS)
def test_engine_options_of_cycles(
    name: str, dumps: dict[str, Path], made: list[Any], capsysbinary: pytest.CaptureFixture[bytes]
) -> None:
    """``cycles --engine python`` and ``--engine native`` (no longer a usage error on a raw
    dump) write the same cycles."""
    argv = [*COMMANDS["cycles"], str(dumps[name])]
    python = run_cli([*argv, "--engine", "python"], False, capsysbinary)
    assert not made
    native = run_cli([*argv, "--engine", "native"], False, capsysbinary)
    assert made
    assert native == python and python[1]


def test_decode_engine_native_with_speed(
    dumps: dict[str, Path], made: list[Any], capsysbinary: pytest.CaptureFixture[bytes]
) -> None:
    """``decode --speed`` on a raw dump runs a session, native with ``--engine native`` (no
    longer a usage error), the same bytes as the core's own run and the Python session."""
    path = str(dumps["damaged_serial"])
    argv = ["decode", path, "-f", "jsonl", "--no-progress"]
    own = run_cli([*argv, "--engine", "native"], False, capsysbinary)
    assert not made  # the core's own run, no session
    paced = run_cli([*argv, "--engine", "native", "--speed", "1e6"], False, capsysbinary)
    assert len(made) == 1
    python = run_cli([*argv, "--engine", "python", "--speed", "1e6"], False, capsysbinary)
    assert own == paced == python


# -- a capture stopped -----------------------------------------------------------------------


class StopAfter(ns.Collect):
    """Every call, and the session stopped once ``n`` calls of records came (a user's stop)."""

    def __init__(self, n: int) -> None:
        super().__init__()
        self.n = n
        self.session: Session | None = None

    def on_records(self, records: Any) -> None:
        super().on_records(records)
        self.n -= 1
        if self.n == 0 and self.session is not None:
            self.session.stop()


def stopped_run(path: Path, engine: str, n: int, protocol: str | None = None) -> StopAfter:
    reader = (GzipBytesReader if path.suffix == ".gz" else RawBytesReader)(path)
    listener = StopAfter(n)
    session = Session(CaptureSource(reader), [listener], SessionOptions(protocol, engine=engine))
    listener.session = session
    with reader:
        session.run()
    return listener


@pytest.mark.parametrize("protocol", [None, EG2_SERIAL, MODBUS_RTU])
@pytest.mark.parametrize("name", ["damaged_serial", "damaged_modbus", "damaged_modbus_gz"])
def test_a_stopped_capture_cuts_off_the_same_records(
    name: str, protocol: str | None, dumps: dict[str, Path], made: list[Any]
) -> None:
    path = dumps[name]
    size = len(gzip.decompress(path.read_bytes()) if path.suffix == ".gz" else path.read_bytes())
    flags = set()
    for n in (1, 2):  # stopped after one batch (64 KiB), or two
        python = stopped_run(path, "python", n, protocol)
        native = stopped_run(path, "native", n, protocol)
        assert len(made) == n
        assert native.calls == python.calls
        records = [r for kind, x in python.calls if kind == "records" for r in x]
        decoded = sum(len(r.raw) for r in records)
        assert decoded < size and (decoded == n * CAPTURE_BATCH_BYTES or path.suffix == ".gz")
        flags |= {f for r in records for f in r.flags}
    if protocol is None or name.split("_")[1] in protocol:
        assert "cut_off" in flags


def test_a_stop_cuts_off_a_frame_begun(tmp_path: Path, made: list[Any]) -> None:
    """The first batch (64 KiB) ends inside a frame: the stop makes it a ``cut_off`` record,
    on both engines."""
    frames = bs.traffic(EG2_SERIAL, 20_000)
    ends, at = set(), 0
    for f in frames:
        at += len(f)
        ends.add(at)
    lead = b"\x00" if CAPTURE_BATCH_BYTES in ends else b""  # a frame across the batch's end
    path = tmp_path / "cut.bin"
    path.write_bytes(lead + b"".join(frames))
    records = {}
    for engine in ("python", "native"):
        got = stopped_run(path, engine, 1)
        records[engine] = [r for kind, x in got.calls if kind == "records" for r in x]
    assert records["native"] == records["python"]
    last = records["python"][-1]
    assert last.kind == "cut_off" and not last.errors and last.flags == ["cut_off"]
    assert last.offset + len(last.raw) == CAPTURE_BATCH_BYTES
