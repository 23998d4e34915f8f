"""Captures chosen by what they hold, not by their names: every kind of input (the raw serial and
Modbus dumps, the candump log, python-can's .asc and .blf, a PCAN trace, an MCAP recording of
``record --demo``, a real .mf4) decodes the same under any name, with both engines; a .blf
padded at its end is complete and a cut one is not; ``--protocol`` says when it looks wrong."""

from __future__ import annotations

import gzip
import os
import shutil
import subprocess
import sys
import threading
from pathlib import Path

import can
import pytest
from capture_helpers import CAPTURES, ENGINES, ROOT, decode, decode_both, records, sample_frames

from analyzer.sources import capture, mf4, sniff
from analyzer.sources.can_message import frame_to_message

THIRD_PARTY = ROOT / "tests" / "data" / "third_party"


@pytest.fixture(scope="module")
def demo_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A mixed three-bus recording, as the issue's users make one."""
    out = tmp_path_factory.mktemp("demo") / "x.mcap"
    cmd = [sys.executable, "-m", "analyzer", "record", "--demo", "-o", str(out), "--duration", "5"]
    subprocess.run(cmd, cwd=ROOT, check=True, capture_output=True, timeout=120)
    return out


def _python_can_file(tmp_path: Path, suffix: str) -> Path:
    path = tmp_path / f"capture{suffix}"
    with can.Logger(str(path)) as logger:
        for frame in sample_frames():
            logger.on_message_received(frame_to_message(frame))
    return path


def _inputs(tmp_path: Path, demo_recording: Path) -> dict[str, Path]:
    return {
        "serial": CAPTURES / "serial_session.bin",
        "modbus": CAPTURES / "modbus_session.bin",
        "candump": CAPTURES / "can_pick_place.log",
        "asc": _python_can_file(tmp_path, ".asc"),
        "blf": _python_can_file(tmp_path, ".blf"),
        "trc": THIRD_PARTY / "python-can" / "test_CanMessage_V2_1.trc",
        "mcap": demo_recording,
    }


@pytest.mark.parametrize("kind", ["serial", "modbus", "candump", "asc", "blf", "trc", "mcap"])
def test_every_input_decodes_the_same_under_any_name(
    tmp_path: Path, demo_recording: Path, kind: str
) -> None:
    original = _inputs(tmp_path, demo_recording)[kind]
    renamed = [tmp_path / name for name in ("renamed", "renamed.txt", "renamed.dat")]
    for path in renamed:
        shutil.copy(original, path)
    if kind in ("candump", "asc", "trc", "serial"):  # compressed: by its content inside
        renamed.append(tmp_path / "renamed.gz")
        renamed[-1].write_bytes(gzip.compress(original.read_bytes()))
    for engine in ENGINES:  # a mixed recording is the Python engine's (a usage error here)
        want = _named(decode(original, engine), original)
        assert want[0] in (0, 2 if kind == "mcap" and engine == "native" else 0)
        for path in renamed:
            assert _named(decode(path, engine), path) == want, f"{path.name} --engine {engine}"


def _named(result: tuple[int, str, str], path: Path) -> tuple[int, str, str]:
    """A decode's result with the capture's name in its messages made neutral."""
    code, text, err = result
    return code, text, err.replace(str(path), "CAPTURE").replace(path.name, "CAPTURE")


@pytest.mark.parametrize(
    "content,fmt",
    [
        (b"\x89MCAP0\r\n", "mcap"),
        (b"LOGG\x90\x00\x00\x00", "blf"),
        (b"MDF     4.10    ", "mf4"),
        (b"\xef\xbb\xbf(1.0) can0 123#11\n", "candump"),
        (b"\n\n  can0  123   [1]  11\r\n", "candump"),
        (b"# made by hand\n(000.000000)  can0  123   [1]  11\n", "candump"),
        (b";$FILEVERSION=1.1\n;$STARTTIME=1\n", "trc"),
        (b"     1)     17535  00000100  8  00 00 00 00 00 00 00 00\n", "trc"),
        (b"date Sam Sep 30 15:06:13.191 2017\nbase hex timestamps absolute\n", "asc"),
        (b"timestamp,arbitration_id,extended,remote,error,dlc,data\n", "csv"),
        (b"\xeb\x90\x01\x01\x41\x43", "bytes"),  # a serial frame
        (b"\x01\x03\x00\x3c\x00\x06\x05\xc4", "bytes"),  # a Modbus request
        (b"\x1b[1mcolour\x1b[0m\n", None),  # escapes are text
        (b"hello\nworld\n", None),
    ],
)
def test_formats_told_by_content(content: bytes, fmt: str | None) -> None:
    assert sniff.sniff_head(content) == fmt


def test_a_log_holding_another_format_is_read_as_that_format(tmp_path: Path) -> None:
    trc = THIRD_PARTY / "python-can" / "test_CanMessage_V1_1.trc"
    as_log = tmp_path / "trace.log"
    shutil.copy(trc, as_log)
    assert decode_both(as_log) == decode_both(trc)
    assert capture.reader_for(as_log) == "analyzer.sources.capture:CanLogReader"


@pytest.mark.parametrize("name", ["serial_session.bin", "modbus_session.bin"])
@pytest.mark.parametrize("saved_as", ["dump.log", "dump.txt", "dump.log.gz"])
def test_a_serial_dump_is_read_as_one_whatever_its_name(
    tmp_path: Path, name: str, saved_as: str
) -> None:
    """A raw dump saved as ``.log`` (a candump suffix) is still a dump, by its bytes."""
    dump = CAPTURES / name
    renamed = tmp_path / saved_as
    data = dump.read_bytes()
    renamed.write_bytes(gzip.compress(data) if saved_as.endswith(".gz") else data)
    code, text, err = decode_both(renamed)
    assert (code, err) == decode_both(dump)[::2]
    assert records(text) == records(decode_both(dump)[1])
    assert "cannot parse" not in err


def test_a_blf_padded_at_its_end_is_complete_and_a_cut_one_is_not(tmp_path: Path) -> None:
    padded = THIRD_PARTY / "python-can" / "logfile.blf"  # its last object: 2 bytes of padding
    code, text, err = decode_both(padded)
    assert (code, err, len(records(text))) == (0, "", 2)
    whole = _python_can_file(tmp_path, ".blf")
    cut = tmp_path / "cut.blf"
    cut.write_bytes(whole.read_bytes()[: whole.stat().st_size - 40])
    code, text, err = decode_both(cut)
    assert code == 3 and "truncated" in err
    assert 0 < len(records(text)) < len(sample_frames())


def test_a_real_mf4_with_both_engines(tmp_path: Path) -> None:
    """Written by python-can's MF4Writer (asammdf), read back: the frames of the sample."""
    mf4.load()
    path = _python_can_file(tmp_path, ".mf4")
    assert path.read_bytes()[:4] == b"MDF "
    code, text, err = decode_both(path)
    assert (code, err) == (0, "")
    got = records(text)
    want = records(decode_both(CAPTURES / "can_pick_place.log")[1])
    assert [(r["name"], r["raw"], r["device"]) for r in got] == [
        (r["name"], r["raw"], r["device"]) for r in want
    ]
    assert [r["t"] for r in got] == pytest.approx([r["t"] for r in want], abs=1e-6)


def test_importing_eg2scope_and_python_can_does_not_load_asammdf() -> None:
    """python-can imports asammdf for .mf4 alone (1-2 s); eg2scope defers it to the first one."""
    code = "import analyzer, can, sys; print('asammdf' in sys.modules, can.MF4Reader.__name__)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "MF4Reader"]


@pytest.mark.parametrize(
    "dump,forced,detected",
    [("serial_session.bin", "modbus", "serial"), ("modbus_session.bin", "serial", "modbus")],
)
def test_a_wrong_protocol_gets_a_hint(dump: str, forced: str, detected: str) -> None:
    code, text, err = decode_both(CAPTURES / dump, "--protocol", forced)
    assert code == 0 and text  # decoded as asked
    words = "EG2 serial" if detected == "serial" else "Modbus RTU"
    assert f"--protocol {forced} finds no valid frame" in err
    assert "detection finds" in err and f"{words} frames there" in err
    assert f"--protocol {detected}" in err
    assert decode_both(CAPTURES / dump, "--protocol", detected)[2] == ""  # right: no hint


@pytest.mark.parametrize("name", ["can_pick_place.log", "x.mcap"])
def test_a_byte_protocol_on_a_can_capture_is_a_usage_error(
    tmp_path: Path, demo_recording: Path, name: str
) -> None:
    path = CAPTURES / name if name.endswith(".log") else demo_recording
    if name.endswith(".log"):
        for engine in ("python", "native"):
            code, text, err = decode(path, engine, "--protocol", "serial")
            assert code == 2 and text == ""
            assert "is a CAN capture" in err and "--protocol serial is for byte streams" in err
    else:  # a recording says each of its serial buses' protocol: no other is forced on it
        code, text, err = decode(path, "python", "--protocol", "serial")
        assert code == 2 and text == ""
        assert "says which protocol each of its serial buses speaks" in err


def test_a_fifo_is_read_by_its_name_and_read_once(tmp_path: Path) -> None:
    """Content cannot be looked at in a FIFO without losing it: its name decides."""
    want = decode_both(CAPTURES / "can_pick_place.log")
    for engine in ENGINES:
        fifo = tmp_path / f"live-{engine}.log"
        os.mkfifo(fifo)
        writer = threading.Thread(target=lambda f=fifo: f.write_bytes(CAN_LOG_BYTES), daemon=True)
        writer.start()
        code, text, err = decode(fifo, engine)
        writer.join(10)
        assert (code, text) == want[:2], err


CAN_LOG_BYTES = (CAPTURES / "can_pick_place.log").read_bytes()
