"""The command line as a hostile tester uses it: usage errors fail at once with exit 2, damaged
input exits 3, no input is ever changed or destroyed, output errors name the file, Ctrl-C in a
parallel decode is one clean line, and live streams carry their source events."""

from __future__ import annotations

import gzip
import json
import os
import signal
import subprocess
import sys
import time
import zlib
from pathlib import Path

import pytest
from cli_process import ENV, eg2scope
from native_core import require_native
from recording.mcap_checks import assert_time_ordered

from decoders import build as b

ROOT = Path(__file__).resolve().parents[2]
CAPTURES = ROOT / "captures"


# -- usage errors: exit 2 at once ------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["decode", "captures/serial_session.bin", "--device", "-1"], "must be 0 or more"),
        (["decode", "captures/serial_session.bin", "--jobs", "-3"], "must be 0 or more"),
        (["decode", "captures/serial_session.bin", "--speed", "1e-300"], "replay speed"),
        (["decode", "captures/serial_session.bin", "--speed", "1e400"], ""),
        (["decode", "captures/serial_session.bin", "--speed", "-2"], "replay speed"),
        (["decode", "captures/serial_session.bin", "--speed", "fast-ish"], "replay speed"),
        (["decode", "captures/serial_session.bin", "-p", "can"], "CAN is chosen by the file"),
        (["decode", "captures/serial_session.bin", "-p", "eg2-can"], "CAN is chosen by the file"),
        (["stats", "captures/modbus_session.bin", "-p", "can"], "CAN is chosen by the file"),
        (["decode", "captures/serial_session.bin", "-p", "nope"], "unknown protocol"),
        (["live", "--serial", "/dev/null", "--queue-size", "-5"], "must be 1 or more"),
        (["live", "--serial", "/dev/null", "--duration", "-1"], "positive number"),
        (["demo", "--noise", "-1"], "probability"),
        (["demo", "--noise", "1.5"], "probability"),
        (["live", "--serial", "/dev/null", "--baud", "7"], "impossible baud rate 7"),
        (["live", "--serial", "/dev/null", "--baud", "20000000"], "300 to 12,000,000 baud"),
        (["bridge", "/dev/null", "/dev/zero", "--baud", "50"], "impossible baud rate 50"),
    ],
)
def test_usage_errors_fail_at_once_with_exit_2(args: list[str], words: str) -> None:
    start = time.monotonic()
    res = eg2scope(*args, timeout=30)
    if "1e400" in args:  # float('1e400') is inf: 'as fast as possible', like 'max'
        assert res.returncode == 0, res.stderr
        return
    assert res.returncode == 2, (res.returncode, res.stderr)
    assert words in res.stderr
    assert "Traceback" not in res.stderr
    assert time.monotonic() - start < 20


# -- the user's files are never changed or destroyed -----------------------------------------


@pytest.mark.parametrize("how", ["same", "symlink", "hardlink", "relative"])
def test_output_naming_the_input_is_refused_and_the_input_kept(tmp_path: Path, how: str) -> None:
    data = (CAPTURES / "serial_session.bin").read_bytes()
    src = tmp_path / "self.bin"
    src.write_bytes(data)
    out = {
        "same": src,
        "symlink": tmp_path / "link.bin",
        "hardlink": tmp_path / "hard.bin",
        "relative": Path("self.bin"),
    }[how]
    if how == "symlink":
        out.symlink_to(src)
    elif how == "hardlink":
        os.link(src, out)
    res = eg2scope("decode", str(src), "-o", str(out), cwd=tmp_path)
    assert res.returncode == 2, res.stderr
    assert "is the input" in res.stderr
    assert src.read_bytes() == data


def test_an_existing_output_is_not_truncated_when_the_run_cannot_start(tmp_path: Path) -> None:
    out = tmp_path / "out.jsonl"
    out.write_text("precious\n")
    res = eg2scope("decode", str(tmp_path / "missing.bin"), "-f", "jsonl", "-o", str(out))
    assert res.returncode == 1 and "not found" in res.stderr
    assert out.read_text() == "precious\n"
    res = eg2scope("decode", "captures/serial_session.bin", "-f", "jsonl", "-o", str(out))
    assert res.returncode == 0
    assert out.read_text().count("\n") == 27
    assert not list(tmp_path.glob(".out.jsonl.*"))  # no temporary left behind


def test_output_errors_name_the_file() -> None:
    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full")
    res = eg2scope("decode", "captures/can_pick_place.log", "-f", "jsonl", "-o", "/dev/full")
    assert res.returncode == 1
    assert "/dev/full" in res.stderr and "No space left" in res.stderr
    assert "Traceback" not in res.stderr


def test_stats_into_head_exits_quietly() -> None:
    res = subprocess.run(
        f"{sys.executable} -m analyzer stats captures/can_pick_place.log | head -1",
        shell=True,
        capture_output=True,
        text=True,
        env=ENV,
        cwd=ROOT,
        timeout=60,
    )
    assert res.returncode == 0
    assert res.stdout.count("\n") == 1
    assert res.stderr == ""


# -- damaged input: exit 3, everything before the damage decoded -----------------------------


def test_damaged_input_exits_3_after_decoding_what_is_there(tmp_path: Path) -> None:
    log = (CAPTURES / "can_pick_place.log").read_bytes()
    damaged = tmp_path / "cut.log.gz"
    whole = gzip.compress(log)
    damaged.write_bytes(whole[: len(whole) * 2 // 3])  # cut inside the compressed stream
    res = eg2scope("decode", str(damaged), "-f", "jsonl")
    assert res.returncode == 3, res.stderr
    records = [json.loads(line) for line in res.stdout.splitlines()]
    assert records and all(r["protocol"] in ("eg2-can", "can") for r in records)
    assert str(damaged) in res.stderr
    clean = eg2scope("decode", "captures/can_pick_place.log", "-f", "jsonl")
    assert clean.returncode == 0 and clean.stderr == ""


def test_help_documents_the_exit_codes() -> None:
    for cmd in ([], ["decode"], ["stats"]):
        res = eg2scope(*cmd, "--help")
        assert "3 decoded as far as possible" in res.stdout.replace("\n", " ").replace("  ", " ")


# -- parallel decoding ----------------------------------------------------------------------


def _modbus_dump_with_a_request_waiting_across_a_boundary(path: Path) -> None:
    """A Modbus dump whose read request sits just before the first part boundary (1 MiB) and
    is followed by a run of garbage longer than the warm-up (64 KiB), then more traffic."""
    request = b.modbus_read_request(1, 1061, 5)
    response = b.modbus_read_response(1, [500, 0, 35, 0, 1])
    pair = request + response
    head = bytearray()
    while len(head) < (1 << 20) - 40:
        head += pair
    head += request  # waits for an answer that never comes
    # then another request (not a retransmission of the same one) and its answer, and more
    other = b.modbus_read_request(1, 1061, 2) + b.modbus_read_response(1, [500, 0])
    tail = bytearray()
    while len(tail) < (2 << 20):
        tail += other
    path.write_bytes(bytes(head) + b"\x00" * 100_000 + bytes(tail))


@pytest.mark.slow
def test_parallel_output_equals_one_piece_when_state_crosses_a_boundary(tmp_path: Path) -> None:
    dump = tmp_path / "modbus.bin"
    _modbus_dump_with_a_request_waiting_across_a_boundary(dump)
    py = ("--engine", "python")  # the parts are the Python engine's
    one = eg2scope("decode", str(dump), *py, "-p", "modbus", "-f", "jsonl", "-j", "1", timeout=300)
    two = eg2scope("decode", str(dump), *py, "-p", "modbus", "-f", "jsonl", "-j", "2", timeout=300)
    assert one.returncode == two.returncode == 0
    assert two.stdout == one.stdout
    waiting = [json.loads(x) for x in one.stdout.splitlines() if "no response" in x]
    assert len(waiting) == 1 and waiting[0]["flags"] == ["unanswered"]
    assert waiting[0]["offset"] < 1 << 20 < waiting[0]["offset"] + 100_000  # across the cut


@pytest.mark.slow
def test_ctrl_c_in_a_parallel_decode_is_one_clean_line(tmp_path: Path) -> None:
    dump = tmp_path / "big.bin"
    frame = b.serial_frame(1, 0xD9) + b.serial_frame(1, 0xD9, b.u16le(500), response=True)
    dump.write_bytes(frame * ((40 << 20) // len(frame)))
    env = {**ENV, "TMPDIR": str(tmp_path)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "analyzer", "decode", str(dump), "--engine", "python", "-f",
         "jsonl", "-j", "2",
         "-o", str(tmp_path / "out.jsonl")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT,
        start_new_session=True,
    )  # fmt: skip
    time.sleep(2.5)
    os.killpg(proc.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the whole process group
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.strip() == "eg2scope: interrupted", err
    assert not list(tmp_path.glob("eg2scope-*")) and not list(tmp_path.glob(".out.jsonl*"))
    assert not (tmp_path / "out.jsonl").exists()


# -- live streams --------------------------------------------------------------------------


def test_live_jsonl_carries_source_events(tmp_path: Path) -> None:
    res = eg2scope(
        "live", "--serial", str(tmp_path / "ttyGone"), "--wait", "-f", "jsonl", "--duration", "1.5"
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    events = [json.loads(x) for x in res.stdout.splitlines()]
    assert events and all(e["kind"] == "event" for e in events)
    assert any("ttyGone" in e["message"] for e in events)
    assert all(set(e) >= {"t", "bus", "event", "level", "message"} for e in events)


def test_record_without_show_prints_events_as_they_happen(tmp_path: Path) -> None:
    res = eg2scope(
        "record", "--serial", str(tmp_path / "ttyGone"), "--wait", "-o", str(tmp_path / "r.mcap"),
        "--duration", "1.5",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "-- " in res.stderr and "ttyGone" in res.stderr  # the event line, on stderr
    assert res.stdout == ""


@pytest.mark.parametrize("sig", ["SIGHUP", "SIGTERM"])
def test_a_closed_terminal_finishes_the_recording(tmp_path: Path, sig: str) -> None:
    from analyzer.recording.reader import McapCaptureReader

    path = tmp_path / "demo.mcap"
    proc = subprocess.Popen(
        [sys.executable, "-m", "analyzer", "record", "--demo", "-o", str(path)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV, cwd=ROOT,
    )  # fmt: skip
    time.sleep(3)
    proc.send_signal(getattr(signal, sig))
    proc.communicate(timeout=30)
    with McapCaptureReader(path) as reader:
        items = list(reader)
    assert items and not reader.errors  # finished: footer and index written
    assert_time_ordered(path)


# -- damaged compression ----------------------------------------------------------------------


def _bad_deflate_block(data: bytes) -> bytes:
    """``data`` gzip-compressed, with its first deflate block's type set to the invalid 11: zlib
    says "invalid block type" (not an OSError: it must be caught as damage all the same)."""
    import gzip

    packed = bytearray(gzip.compress(data))
    packed[10] |= 0x06
    return bytes(packed)


@pytest.mark.parametrize("engine", ["python", "auto"])
@pytest.mark.parametrize(
    ("name", "payload", "message"),
    [
        ("dump.bin.gz", b.serial_frame(1, 0x41) * 500, "the compressed data is damaged after 0"),
        ("bus.log.gz", b"(1.000000) can0 01180001#08\n" * 500, "line 1: the compressed data is"),
    ],
    ids=["raw-dump", "candump"],
)
def test_a_bad_deflate_block_is_damage_not_a_traceback(
    tmp_path: Path, engine: str, name: str, payload: bytes, message: str
) -> None:
    path = tmp_path / name
    path.write_bytes(_bad_deflate_block(payload))
    res = eg2scope("decode", str(path), "--engine", engine, "-f", "jsonl")
    assert res.returncode == 3, res.stderr
    assert message in res.stderr and "invalid block type" in res.stderr
    assert "Traceback" not in res.stderr


ENGINES = ["python", "native"]


def _decode(path: Path, engine: str, *args: str) -> subprocess.CompletedProcess[str]:
    if engine == "native":
        require_native()  # skips without a Rust toolchain, fails with one
    return eg2scope("decode", str(path), "--engine", engine, *args)


def _damage_lines(stderr: str, path: Path) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith(f"eg2scope: {path}:")]


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("name", ["can.log.gz", "dump.bin.gz"])
def test_a_cut_gz_capture_says_so_in_one_line_and_keeps_what_came_before(
    tmp_path: Path, engine: str, name: str
) -> None:
    """A .gz cut short: one line in words ("the compressed file is cut short"; no EOFError, no
    second line for the line the cut went through), exit 3, every frame before the cut."""
    source = "can_pick_place.log" if name.startswith("can") else "serial_session.bin"
    packed = gzip.compress((CAPTURES / source).read_bytes())
    path = tmp_path / name
    path.write_bytes(packed[: len(packed) * 2 // 3])
    args = ["-p", "serial"] if name.startswith("dump") else []
    res = _decode(path, engine, "-f", "jsonl", *args)
    assert res.returncode == 3, res.stderr
    said = _damage_lines(res.stderr, path)
    assert len(said) == 1 and "EOFError" not in res.stderr, res.stderr
    assert said[0].endswith("the compressed file is cut short; the rest is lost") or (
        "the compressed file is cut short after " in said[0]
    ), said
    whole = zlib.decompressobj(wbits=31).decompress(path.read_bytes())
    records = [json.loads(line) for line in res.stdout.splitlines()]
    if name.startswith("can"):  # one frame a line: every whole line before the cut
        lines = whole.count(b"\n")
        assert len(records) == lines > 0
        assert said[0].startswith(f"eg2scope: {path}: line {lines + 1}: ")
    else:  # every byte recovered is in a record
        assert sum(r["length"] for r in records) == len(whole) > 0


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("name", ["trace.asc.gz", "bus.log.gz"])
def test_a_gz_name_on_data_that_is_no_gzip_says_so_in_words(
    tmp_path: Path, engine: str, name: str
) -> None:
    path = tmp_path / name
    path.write_bytes(b"this is not gzip at all\n" * 20)
    res = _decode(path, engine)
    assert res.returncode == 3, res.stderr
    said = _damage_lines(res.stderr, path)
    assert len(said) == 1 and said[0].endswith("not gzip data, though its name ends in .gz")
    assert "BadGzipFile" not in res.stderr and "gzip." not in res.stderr


@pytest.mark.parametrize("engine", ENGINES)
def test_bytes_that_are_no_text_are_quoted_escaped(tmp_path: Path, engine: str) -> None:
    """A line of undecodable bytes is quoted as ``\\xff``, never as stand-in characters: in a
    bad line and in "does not look like a candump log"."""
    bad = tmp_path / "bad.log"
    bad.write_bytes(b"(1.000000) can0 123#00\n\xff\xfe\x80 junk \xc3( line\n")
    res = _decode(bad, engine)
    assert res.returncode == 3
    assert _damage_lines(res.stderr, bad) == [
        f"eg2scope: {bad}: line 2: cannot parse: '\\xff\\xfe\\x80 junk \\xc3( line' "
        "(not a candump frame)"
    ]
    junk = tmp_path / "junk.log"
    junk.write_bytes(b"\xff\xfe one\n" + b"\xe9t\xe9\n" * 6)
    res = _decode(junk, engine)
    assert res.returncode == 3 and "\ufffd" not in res.stderr
    assert "does not look like a candump log" in res.stderr
    assert "(the first is '\\xff\\xfe one')" in res.stderr
