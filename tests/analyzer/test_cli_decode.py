"""``eg2scope decode`` and ``eg2scope stats`` on real files in every input format."""

from __future__ import annotations

import csv
import io
import json
import os
import pty
import select
import subprocess
import sys
import time
from pathlib import Path

import can
import pytest

from analyzer.cli import main
from decoders.build import can_id

ROOT = Path(__file__).resolve().parents[2]
CAPTURES = ROOT / "captures"
CONTRACT_KEYS = {
    "t",
    "bus",
    "protocol",
    "kind",
    "offset",
    "index",
    "length",
    "direction",
    "device",
    "code",
    "name",
    "fields",
    "raw",
    "errors",
    "warnings",
}


def run_cli(capsysbinary: pytest.CaptureFixture[bytes], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsysbinary.readouterr()
    return code, out.decode(), err.decode()


def jsonl(capsysbinary: pytest.CaptureFixture[bytes], *argv: str) -> list[dict]:
    code, out, err = run_cli(capsysbinary, "decode", "--format", "jsonl", *argv)
    assert code == 0, err
    return [json.loads(line) for line in out.splitlines()]


@pytest.mark.parametrize(
    ("name", "protocol"),
    [("serial_session.bin", "eg2-serial"), ("modbus_session.bin", "modbus-rtu")],
)
def test_byte_captures_account_for_every_byte(capsysbinary, name: str, protocol: str) -> None:
    path = CAPTURES / name
    records = jsonl(capsysbinary, str(path))  # protocol detected from the bytes
    assert records, "no records"
    for rec in records:
        assert rec.keys() >= CONTRACT_KEYS
        assert rec["protocol"] == protocol
    offset = 0
    for rec in records:
        assert rec["offset"] == offset
        assert len(bytes.fromhex(rec["raw"])) == rec["length"]
        offset += rec["length"]
    assert offset == path.stat().st_size
    assert records[-1]["kind"] == "truncated"
    frames = [r for r in records if r["kind"] == "frame"]
    assert any(r["errors"] for r in frames), "the sample's corrupt frame was not reported"
    assert any(r["kind"] == "garbage" for r in records)
    # in a capture file a record's seq is its place in the input: here its byte offset
    assert all(r["seq"] == r["offset"] for r in records)
    by_seq = {r["seq"]: r for r in records}
    paired = [r for r in frames if r["direction"] == "response" and r["pair"] is not None]
    assert paired
    for resp in paired:
        req = by_seq[resp["pair"]]
        assert req["direction"] == "request" and req["pair"] == resp["seq"]


def test_serial_sample_decodes_in_words(capsysbinary) -> None:
    code, out, _ = run_cli(
        capsysbinary, "decode", str(CAPTURES / "serial_session.bin"), "--colour", "never"
    )
    assert code == 0
    assert "CMD_MC_MOVE_CATCH_XG" in out and "speed=500" in out and "force=100 g" in out
    assert "checksum error: expected 0x" in out
    assert "unknown command 0x77" in out
    assert "no response" in out  # ID 2 never answers
    assert "→" in out and "←" in out


def test_can_log_decodes_and_pairs(capsysbinary) -> None:
    records = jsonl(capsysbinary, str(CAPTURES / "can_pick_place.log"))
    assert [r["index"] for r in records] == list(range(len(records)))
    protocols = {r["protocol"] for r in records}
    assert protocols == {"eg2-can", "can"}
    writes = [r for r in records if r["name"] == "CMD_OPENLEN_SET..CMD_FORCE_SET"]
    assert writes and writes[0]["fields"]["address"] == 1020
    responses = [r for r in records if r["direction"] == "response" and r["pair"] is not None]
    assert responses and all(r["latency_ms"] is not None and r["latency_ms"] > 0 for r in responses)
    unanswered = [r for r in records if any("no response" in w for w in r["warnings"])]
    assert [r["device"] for r in unanswered] == [3]
    assert any(r["errors"] for r in records if r["protocol"] == "can")  # the error frame


def sample_can_frames() -> list[can.Message]:
    msgs = []
    for i, (arb, data, ext) in enumerate(
        [
            (can_id(1, 1020, 1), bytes.fromhex("0000F401F401"), True),
            (can_id(1, 1020, 1), b"\x06", True),
            (can_id(0, 1120, 2), b"\x08", True),
            (can_id(0, 1120, 2), bytes.fromhex("F300E80300002200"), True),
            (0x123, b"\x01\x02", False),
        ]
    ):
        msgs.append(
            can.Message(
                timestamp=1000.0 + i * 0.01,
                arbitration_id=arb,
                data=data,
                is_extended_id=ext,
                channel=0,
            )
        )
    return msgs


@pytest.mark.parametrize("suffix", [".asc", ".blf", ".log", ".csv", ".trc"])
def test_python_can_formats_decode_alike(capsysbinary, tmp_path: Path, suffix: str) -> None:
    path = tmp_path / f"capture{suffix}"
    with can.Logger(str(path)) as writer:
        for msg in sample_can_frames():
            writer.on_message_received(msg)
    records = jsonl(capsysbinary, str(path))
    summary = [(r["protocol"], r["direction"], r["name"], r["raw"]) for r in records]
    assert summary == [
        ("eg2-can", "request", "CMD_OPENLEN_SET..CMD_FORCE_SET", "00 00 F4 01 F4 01"),
        ("eg2-can", "response", "CMD_OPENLEN_SET..CMD_FORCE_SET", "06"),
        ("eg2-can", "request", "CMD_FORCE_ACT..CMD_TEMP", "08"),
        ("eg2-can", "response", "CMD_FORCE_ACT..CMD_TEMP", "F3 00 E8 03 00 00 22 00"),
        ("can", None, None, "01 02"),
    ]
    assert records[3]["fields"]["values"]["CMD_OPENLEN_ACT"] == 1000
    assert records[1]["pair"] == 0 and records[3]["pair"] == 2


def test_csv_output(capsysbinary) -> None:
    code, out, _ = run_cli(
        capsysbinary, "decode", "-f", "csv", str(CAPTURES / "modbus_session.bin")
    )
    assert code == 0
    rows = list(csv.DictReader(io.StringIO(out)))
    assert rows[0]["protocol"] == "modbus-rtu"
    assert any("CRC error: expected 54 F2, got 86 21" in r["errors"] for r in rows)
    assert json.loads(rows[0]["fields"])["start"] == 1010


def test_device_and_errors_only_filters(capsysbinary) -> None:
    dev2 = jsonl(capsysbinary, str(CAPTURES / "can_pick_place.log"), "--device", "2")
    assert dev2 and {r["device"] for r in dev2} == {2}
    problems = jsonl(capsysbinary, str(CAPTURES / "serial_session.bin"), "--errors-only")
    assert problems and all(r["errors"] or r["warnings"] for r in problems)
    everything = jsonl(capsysbinary, str(CAPTURES / "serial_session.bin"))
    assert len(problems) < len(everything)


def test_explicit_protocol_overrides_detection(capsysbinary) -> None:
    records = jsonl(capsysbinary, "--protocol", "modbus", str(CAPTURES / "serial_session.bin"))
    assert {r["protocol"] for r in records} == {"modbus-rtu"}
    assert sum(r["length"] for r in records) == (CAPTURES / "serial_session.bin").stat().st_size


def test_stats(capsysbinary) -> None:
    code, out, _ = run_cli(
        capsysbinary, "stats", "--format", "json", str(CAPTURES / "can_pick_place.log")
    )
    assert code == 0
    data = json.loads(out)
    devices = {d["device"]: d for d in data["devices"]}
    assert set(devices) == {1, 2, 3, 16383}
    assert devices[1]["p50_ms"] is not None and devices[1]["max_ms"] >= devices[1]["p50_ms"]
    assert devices[3]["unanswered"] == 1
    assert data["flags"].get("out_of_range", 0) >= 1
    code, text, _ = run_cli(capsysbinary, "stats", str(CAPTURES / "serial_session.bin"))
    assert code == 0 and "Devices" in text and "CMD_MC_MOVE_CATCH_XG" in text


def test_id_scan_is_named(capsysbinary, tmp_path: Path) -> None:
    from decoders.build import serial_frame

    path = tmp_path / "scan.bin"
    path.write_bytes(b"".join(serial_frame(i, 0x41) for i in range(1, 30)))
    code, out, _ = run_cli(capsysbinary, "stats", "-f", "json", str(path))
    assert code == 0
    assert any("ID scan" in note for note in json.loads(out)["notes"])


@pytest.mark.parametrize(
    ("argv", "message", "exit_code"),
    [
        (["decode", "/nonexistent/file.log"], "capture file not found", 1),
        (
            ["decode", "--protocol", "zigbee", str(CAPTURES / "serial_session.bin")],
            "unknown protocol",
            2,
        ),
    ],
)
def test_clear_errors(capsysbinary, argv: list[str], message: str, exit_code: int) -> None:
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's usage errors
        code = int(exc.code or 0)
    err = capsysbinary.readouterr().err.decode()
    assert code == exit_code
    assert message in err and "Traceback" not in err


def test_truncated_blf_yields_frames_before_the_damage(capsysbinary, tmp_path: Path) -> None:
    path = tmp_path / "cut.blf"
    with can.Logger(str(path)) as writer:
        for i in range(3000):
            writer.on_message_received(
                can.Message(
                    timestamp=i * 0.001, arbitration_id=can_id(0, 1120, 1), data=b"\x08", channel=0
                )
            )
    data = path.read_bytes()
    path.write_bytes(data[: len(data) * 2 // 3])
    code, out, err = run_cli(capsysbinary, "decode", "-f", "jsonl", str(path))
    assert code == 3  # decoded as far as possible, but the input is damaged
    assert 0 < len(out.splitlines()) < 3000
    assert "truncated" in err or "damaged" in err or "error" in err


def test_colour_follows_the_terminal_conventions(capsysbinary, monkeypatch) -> None:
    monkeypatch.setenv("FORCE_COLOR", "1")
    _, out, _ = run_cli(capsysbinary, "decode", str(CAPTURES / "serial_session.bin"))
    assert "\x1b[31m" in out
    monkeypatch.delenv("FORCE_COLOR")
    monkeypatch.setenv("NO_COLOR", "1")
    _, out, _ = run_cli(capsysbinary, "decode", str(CAPTURES / "serial_session.bin"))
    assert "\x1b[" not in out


def test_progress_bar_only_on_a_terminal(tmp_path: Path) -> None:
    big = tmp_path / "big.bin"
    from decoders.build import serial_frame

    big.write_bytes(serial_frame(1, 0xD9) * 200_000)
    master, slave = pty.openpty()
    env = {**os.environ, "PYTHONPATH": str(ROOT), "COLUMNS": "100"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "analyzer", "decode", "-f", "jsonl", str(big)],
        stdout=subprocess.DEVNULL,
        stderr=slave,
        env=env,
    )
    os.close(slave)
    # read the terminal while it runs: a bar that fills the pty's buffer must not stall it
    seen = b""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        ready, _, _ = select.select([master], [], [], 0.2)
        if ready:
            try:
                chunk = os.read(master, 65536)
            except OSError:  # EIO: every holder of the terminal closed it
                break
            seen += chunk
        elif proc.poll() is not None:
            break  # exited, and nothing more to read
    os.close(master)
    assert proc.wait(10) == 0
    assert b"big.bin" in seen and b"records" in seen
    plain = subprocess.run(
        [sys.executable, "-m", "analyzer", "decode", "-f", "jsonl", str(big)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        env=env,
        timeout=120,
        check=True,
    )
    assert plain.stderr == b""


@pytest.mark.parametrize("kind", ["bytes", "candump"])
def test_parallel_decode_equals_one_piece(
    capsysbinary, tmp_path: Path, monkeypatch, kind: str
) -> None:
    """Large captures are decoded in parts on every core; the output must not change."""
    import random

    import analyzer.session.parallel as parallel
    from decoders import build as b

    # small parts, so that a small file is split into many, with joins everywhere
    monkeypatch.setitem(parallel.PART_BYTES, kind, 20_000)
    monkeypatch.setitem(parallel.WARMUP, kind, 8_000)
    monkeypatch.setitem(parallel.MIN_PARALLEL_BYTES, kind, 40_000)
    rng = random.Random(4)
    if kind == "bytes":
        path = tmp_path / "noisy.bin"
        out = bytearray()
        while len(out) < 200_000:
            dev = rng.randint(1, 3)
            out += b.serial_frame(dev, 0xD9)
            reply = bytearray(
                b.serial_frame(dev, 0xD9, b.u16le(rng.randint(0, 1000)), response=True)
            )
            if rng.random() < 0.05:
                reply[-1] ^= 0xFF  # bad checksum
            out += reply
            if rng.random() < 0.05:
                out += bytes(rng.randrange(256) for _ in range(rng.randint(1, 9)))  # garbage
        path.write_bytes(bytes(out))
    else:
        path = tmp_path / "busy.log"
        lines = []
        t = 1000.0
        for i in range(6000):
            dev = 1 + i % 3
            t += 0.0003
            lines.append(b.candump_line(b.can_read_request(dev, 1120, 8, t=t)))
            if rng.random() > 0.02:  # a few go unanswered
                t += 0.0004
                data = b.u16le(rng.randint(0, 500), rng.randint(0, 1000), 0, 36)
                lines.append(b.candump_line(b.can_read_response(dev, 1120, data, t=t)))
        path.write_text("\n".join(lines) + "\n")
    assert parallel.splittable(path, "jsonl", kind)
    # -j 2: split even when the machine is busy (by default a busy machine decodes in one piece)
    py = ("--engine", "python")  # the parts are the Python engine's
    code, split, err = run_cli(capsysbinary, "decode", *py, "-f", "jsonl", "-j", "2", str(path))
    assert code == 0 and "one piece" not in err
    code, whole, _ = run_cli(capsysbinary, "decode", *py, "-f", "jsonl", "--jobs", "1", str(path))
    assert code == 0
    assert split == whole
    records = [json.loads(line) for line in whole.splitlines()]
    assert sum(1 for r in records if r["pair"] is not None) > 1000
    if kind == "bytes":
        assert sum(r["length"] for r in records) == path.stat().st_size
    code, split_csv, _ = run_cli(capsysbinary, "decode", *py, "-f", "csv", "-j", "2", str(path))
    code, whole_csv, _ = run_cli(capsysbinary, "decode", *py, "-f", "csv", "-j", "1", str(path))
    assert split_csv == whole_csv


def test_split_decode_that_fails_a_join_midway_goes_on_in_one_piece(
    capsysbinary, tmp_path: Path, monkeypatch
) -> None:
    """Parts already written stay; the rest comes from a one-piece decode, nothing doubled."""
    import analyzer.session.parallel as parallel
    from decoders import build as b

    monkeypatch.setitem(parallel.PART_BYTES, "bytes", 20_000)
    monkeypatch.setitem(parallel.WARMUP, "bytes", 8_000)
    monkeypatch.setitem(parallel.MIN_PARALLEL_BYTES, "bytes", 40_000)
    pair = b.serial_frame(1, 0xD9) + b.serial_frame(1, 0xD9, b.u16le(500), response=True)
    head = pair * (49_990 // len(pair))
    # a request that waits across the second cut (25,000 bytes a part), then silence longer
    # than the warm-up: that part cannot be decided on its own
    data = head + b.serial_frame(2, 0xD9) + b"\x00" * 10_000
    data += pair * ((100_000 - len(data)) // len(pair))
    path = tmp_path / "stalled.bin"
    path.write_bytes(data)
    py = ("--engine", "python")  # the parts are the Python engine's
    code, split, err = run_cli(capsysbinary, "decode", *py, "-f", "csv", "-j", "2", str(path))
    assert code == 0 and "decoding the rest of stalled.bin in one piece" in err
    code, whole, _ = run_cli(capsysbinary, "decode", *py, "-f", "csv", "-j", "1", str(path))
    assert split == whole
    assert split.count("seq,t,bus") == 1  # one header
