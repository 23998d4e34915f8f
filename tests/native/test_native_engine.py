"""Choosing the decode engine: ``--engine auto|python|native``, what ``eg2scope --version`` says,
and the pure-Python fallback when the extension is missing (these run with or without it)."""

from __future__ import annotations

import gzip
import io
import os
import subprocess
import sys
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import pytest
from native_core import needs_native

from analyzer.cli import main
from analyzer.session import engine as native
from analyzer.session import native_run

ROOT = Path(__file__).resolve().parents[2]
SERIAL = ROOT / "captures" / "serial_session.bin"
CAN = ROOT / "captures" / "can_pick_place.log"
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "NO_COLOR": "1"}
# the interpreter as if the extension were not built (an import of it fails)
WITHOUT = "import sys; sys.modules['analyzer._native'] = None; from analyzer.cli import main; "


def run(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        try:
            code = main(list(argv))
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 2
    return code, out.getvalue(), err.getvalue()


def python_without_native(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", WITHOUT + code],
        capture_output=True,
        text=True,
        env=ENV,
        cwd=ROOT,
        timeout=60,
    )


def test_version_names_the_engine() -> None:
    code, out, _ = run("--version")
    assert code == 0
    if native.available():
        assert out.strip() == "eg2scope 0.1.0 (native core: available)"
    else:
        assert out.startswith("eg2scope 0.1.0 (native core: not ")
        assert out.strip().endswith("; pure Python)")


def test_without_the_extension_everything_is_pure_python(tmp_path: Path) -> None:
    res = python_without_native("main(['--version'])")
    assert res.stdout.startswith("eg2scope 0.1.0 (native core: not built: "), res.stderr
    assert res.stdout.strip().endswith("; pure Python)")
    out = tmp_path / "out.jsonl"
    res = python_without_native(f"sys.exit(main(['decode', {str(SERIAL)!r}, '-f', 'jsonl', "
                                f"'-o', {str(out)!r}]))")  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert out.read_bytes().count(b"\n") > 10
    res = python_without_native(
        f"sys.exit(main(['decode', {str(SERIAL)!r}, '--engine', 'native']))"
    )
    assert res.returncode == 2
    assert "--engine native: the native core is not built" in res.stderr


def serial_recording(path: Path) -> Path:
    """A recording of one serial line (the sample dump's bytes): several byte streams to a
    session, which the native engine does not decode."""
    from test_native_session import Batches
    from test_native_session import run as run_session

    from analyzer.model import Item
    from analyzer.recording.recorder import McapRecorder
    from decoders.model import Chunk

    class SerialTap(Batches):
        kind = "bytes"

    chunk = Chunk(SERIAL.read_bytes(), 1_700_000_000.0)
    run_session(SerialTap([[Item("rs232", chunk)]]), "python", McapRecorder(path))
    return path


@needs_native
def test_engine_native_refuses_what_it_cannot_do(tmp_path: Path) -> None:
    asc = tmp_path / "x.asc"
    asc.write_text("date Mon Nov 23 00:00:00 2026\nbase hex  timestamps absolute\n")
    recording = str(serial_recording(tmp_path / "serial.mcap"))
    for argv, words in [
        ([recording], "does not read this kind of capture"),
        ([recording, "--speed", "1000"], "--speed"),
    ]:
        code, _, err = run("decode", *argv, "--engine", "native")
        assert code == 2, err
        assert "--engine native: " in err and words in err
        assert "Traceback" not in err
    # CAN captures the core does not read are read in Python and decoded by the session's
    # native decoding (tests/sources/test_third_party_captures.py compares the engines), and a
    # raw dump replayed with --speed by its native decoding of one byte stream
    # (test_byte_session.py compares them)
    assert run("decode", str(asc), "--engine", "native")[0] == 0
    assert run("decode", str(SERIAL), "--speed", "1000", "--engine", "native")[0] == 0


def test_engine_python_and_usage_errors_come_first(tmp_path: Path) -> None:
    code, _, err = run("decode", str(tmp_path / "missing.bin"), "--engine", "native")
    assert code == 1 and "capture file not found" in err  # the same message for both engines
    code, _, err = run("decode", str(SERIAL), "-p", "can", "--engine", "native")
    assert code == 2 and "CAN is chosen by the file" in err
    code, _, err = run("decode", str(SERIAL), "--engine", "fast")
    assert code == 2 and "invalid choice" in err


@needs_native
def test_auto_uses_the_native_core_where_it_applies(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    used: list[str] = []
    real = native_run.open_run

    def spy(opts, fmt, colour, absolute_time):  # type: ignore[no-untyped-def]
        used.append(fmt)
        return real(opts, fmt, colour, absolute_time)

    monkeypatch.setattr(native_run, "open_run", spy)
    out = tmp_path / "o"
    for fmt in ("jsonl", "csv", "text"):
        assert run("decode", str(CAN), "-f", fmt, "-o", str(out))[0] == 0
    assert used == ["jsonl", "csv", "text"]
    assert run("decode", str(CAN), "-o", str(out), "--engine", "python")[0] == 0
    assert run("decode", str(CAN), "-o", str(out), "--speed", "1e6")[0] == 0
    assert used == ["jsonl", "csv", "text"]  # neither went native


@needs_native
def test_unsupported_falls_back_to_a_session(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Where the core's own run does not take a capture, a session decodes it: for a raw
    dump, natively (``--engine native`` too); the same bytes."""
    out = tmp_path / "o.jsonl"
    assert run("decode", str(SERIAL), "-f", "jsonl", "-o", str(out), "--engine", "python")[0] == 0
    want = out.read_text()
    monkeypatch.setattr(native_run, "open_run", lambda *a: None)  # the core says Unsupported
    assert run("decode", str(SERIAL), "-f", "jsonl", "-o", str(out))[0] == 0
    assert out.read_text() == want
    code, _, err = run("decode", str(SERIAL), "-f", "jsonl", "-o", str(out), "--engine", "native")
    assert code == 0 and out.read_text() == want, err

    from analyzer import _native  # type: ignore[attr-defined]

    def unsupported(*args: object) -> None:
        raise _native.Unsupported("x.bin: not this one")

    monkeypatch.setattr(native_run, "open_run", unsupported)
    assert run("decode", str(SERIAL), "-f", "jsonl", "-o", str(out))[0] == 0  # a session did it
    code, _, err = run("decode", str(SERIAL), "-f", "jsonl", "-o", str(out), "--engine", "native")
    assert code == 0 and out.read_text() == want, err
    monkeypatch.setattr(native_run, "_session_decodes", lambda reader: False)  # nor a session
    code, _, err = run("decode", str(SERIAL), "-o", str(out), "--engine", "native")
    assert code == 2 and "--engine native: x.bin: not this one; use --engine python" in err
    monkeypatch.setattr(native_run, "open_run", lambda *a: None)
    code, _, err = run("decode", str(SERIAL), "-o", str(out), "--engine", "native")
    assert code == 2 and "does not support" in err


@needs_native
def test_stdout_and_colour(tmp_path: Path) -> None:
    """Output on stdout (a pipe: no colour unless asked) is the same from both engines."""
    outs = []
    for engine in ("python", "native"):
        res = subprocess.run(
            [sys.executable, "-m", "analyzer", "decode", str(SERIAL), "--engine", engine,
             "--jobs", "1", "-e"],
            capture_output=True, env={**ENV, "FORCE_COLOR": "1", "NO_COLOR": ""}, cwd=ROOT,
            timeout=60,
        )  # fmt: skip
        assert res.returncode == 0, res.stderr
        outs.append(res.stdout)
    assert outs[0] == outs[1]
    assert b"\x1b[" in outs[0]  # FORCE_COLOR: coloured even on a pipe


@needs_native
def test_native_output_errors_name_the_file() -> None:
    code, _, err = run(
        "decode", str(SERIAL), "-f", "jsonl", "-o", "/dev/full", "--engine", "native"
    )
    assert code == 1
    assert "cannot write /dev/full" in err


@needs_native
def test_the_extension_directly(tmp_path: Path) -> None:
    from analyzer import _native  # type: ignore[attr-defined]

    log = tmp_path / "many.log"
    log.write_bytes(CAN.read_bytes() * 40)
    run_ = _native.DecodeRun(str(log), "jsonl", batch_bytes=4096)
    assert run_.size == log.stat().st_size
    batches = list(run_)
    assert all(isinstance(x, bytes) and x for x in batches)
    assert len(batches) > 1  # small batches: many of them
    assert run_.position == run_.size
    assert run_.records_written == b"".join(batches).count(b"\n")
    assert run_.errors == []
    assert list(run_) == []  # exhausted
    # straight to a file descriptor: the same bytes
    with (tmp_path / "direct.jsonl").open("wb") as f:
        direct = _native.DecodeRun(str(log), "jsonl", batch_bytes=4096)
        while direct.write_batch(f.fileno()):
            pass
        assert direct.write_batch(f.fileno()) == 0
    assert (tmp_path / "direct.jsonl").read_bytes() == b"".join(batches)
    rfd, wfd = os.pipe()
    os.close(rfd)
    try:
        # a writer thread writes the batches: the failure comes with the next call, at the latest
        # with the last (the one that says 0)
        with pytest.raises(BrokenPipeError):
            broken = _native.DecodeRun(str(log), "jsonl", batch_bytes=4096)
            while broken.write_batch(wfd):
                pass
    finally:
        os.close(wfd)
    with pytest.raises(FileNotFoundError):
        _native.DecodeRun(str(tmp_path / "nope.log"), "jsonl")
    with pytest.raises(ValueError):
        _native.DecodeRun(str(CAN), "parquet")
    with pytest.raises(_native.Unsupported):
        _native.DecodeRun(str(SERIAL), "jsonl", protocol="eg2-can")


@needs_native
@pytest.mark.parametrize("fmt", ["jsonl", "csv", "text"])
def test_in_memory_stdout_gets_the_same_bytes(fmt: str) -> None:
    """A stdout without a file descriptor (as under capsys) takes the batches as bytes."""
    outs = []
    for engine in ("python", "native"):
        raw = io.BytesIO()
        text = io.TextIOWrapper(raw, encoding="utf-8", newline="")
        with redirect_stdout(text), redirect_stderr(io.StringIO()):
            code = main(["decode", str(CAN), "-f", fmt, "--engine", engine, "--jobs", "1"])
        text.flush()
        assert code == 0
        outs.append(raw.getvalue())
    assert outs[0] == outs[1] and outs[0].count(b"\n") > 50


@needs_native
def test_a_file_name_that_is_not_utf8_goes_to_python(tmp_path: Path) -> None:
    """Damage messages name the file as Python prints it (surrogate escapes), which the native
    core cannot spell: such a capture is decoded by the Python engine."""
    name = os.fsdecode(b"\xffcut.bin.gz")
    packed = gzip.compress(SERIAL.read_bytes())
    (tmp_path / name).write_bytes(packed[: len(packed) // 2])
    for engine in ("auto", "native"):  # native: the session's native decoding
        code, _, err = run(
            "decode", str(tmp_path / name), "-o", str(tmp_path / "o"), "--engine", engine
        )
        assert (
            code == 3
            and "\\udcffcut.bin.gz: the compressed file is cut short"
            in err.encode("utf-8", "backslashreplace").decode()
        ), err
