"""A live serial bus is named by its protocol, as ``--help`` says: rs232 for the regular serial
protocol, rs485 for Modbus RTU, given (``--protocol``) or detected, so recordings and a fleet
dataset never mix the two under one name. Real ptys, real recordings read back, and a fleet
dataset made from them."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import orjson
import pytest
from taps.tap_helpers import Pty

from analyzer.model import INFO, WARNING, Item, SourceEvent
from analyzer.recording.reader import McapCaptureReader
from analyzer.sources.live import Tap
from analyzer.sources.naming import BusNamer
from decoders import build as b
from decoders.model import Chunk

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "NO_COLOR": "1"}

SERIAL = b.serial_frame(1, 0x41) + b.serial_frame(1, 0x41, bytes((1, 0, 40, 0, 0, 0, 0)), True)
MODBUS = b.modbus_read_request(1, 1060, 2) + b.modbus_read_response(1, [500, 0])


@pytest.fixture
def pty() -> Iterator[Pty]:
    p = Pty()
    yield p
    p.close()


def record_live(
    tmp_path: Path, pty: Pty, traffic: bytes, *options: str
) -> tuple[list[dict], Path, str]:
    """``eg2scope live --serial PTY -o run.mcap -f jsonl`` while the pty carries ``traffic``,
    stopped by SIGINT: its JSONL records and events, the recording, stderr."""
    out = tmp_path / "run.mcap"
    with (tmp_path / "out.jsonl").open("w+") as stdout, (tmp_path / "err").open("w+") as err:
        proc = subprocess.Popen(
            [sys.executable, "-m", "analyzer", "live", "--serial", pty.name, *options,
             "-o", str(out), "-f", "jsonl"],
            stdout=stdout, stderr=err, env=ENV, cwd=ROOT, text=True,
        )  # fmt: skip
        deadline = time.monotonic() + 60
        while not out.exists():
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.05)
        for _ in range(20):
            pty.write(traffic)
            time.sleep(0.03)
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        assert proc.wait(60) == 0
        stdout.seek(0)
        err.seek(0)
        return [orjson.loads(x) for x in stdout], out, err.read()


@pytest.mark.parametrize(
    ("traffic", "name", "protocol"),
    [(SERIAL, "rs232", "eg2-serial"), (MODBUS, "rs485", "modbus-rtu")],
    ids=["serial", "modbus"],
)
def test_a_detected_protocol_names_the_bus(
    tmp_path: Path, pty: Pty, traffic: bytes, name: str, protocol: str
) -> None:
    lines, out, err = record_live(tmp_path, pty, traffic)
    records = [r for r in lines if r["kind"] != "event"]
    assert len(records) >= 40 and {r["bus"] for r in records} == {name}
    assert {r["protocol"] for r in records} == {protocol}
    events = [r for r in lines if r["kind"] == "event"]
    # the events before the bytes showed the protocol (passive, opened) keep the provisional
    # name; from the naming on, the bus's own
    named = next(i for i, e in enumerate(events) if e["message"].endswith(f"bus named {name}"))
    assert {e["bus"] for e in events[:named]} == {"serial"}
    assert {e["bus"] for e in events[named:]} == {name}
    assert events[-1]["event"] == "closed"
    with McapCaptureReader(out) as reader:
        assert {x.bus for x in reader if isinstance(x, Item)} == {name}
    from mcap.reader import make_reader

    with out.open("rb") as f:
        topics = {c.topic for c in make_reader(f).get_summary().channels.values()}
    assert {f"/raw/{name}", f"/decoded/{name}"} <= topics
    assert not {"/raw/serial", "/decoded/serial"} & topics
    assert "Traceback" not in err


def test_a_given_protocol_names_the_bus_at_once(tmp_path: Path, pty: Pty) -> None:
    lines, _, _ = record_live(tmp_path, pty, MODBUS, "--protocol", "modbus")
    assert {r["bus"] for r in lines} == {"rs485"}  # the events too, from the first


def test_a_given_bus_name_wins(tmp_path: Path, pty: Pty) -> None:
    lines, _, _ = record_live(tmp_path, pty, MODBUS, "--bus", "line7")
    assert {r["bus"] for r in lines} == {"line7"}


def test_the_recordings_of_both_protocols_stay_apart_in_their_records(
    tmp_path: Path, pty: Pty
) -> None:
    """Decoded again into the Parquet records a fleet dataset is made of (``batch`` writes
    these columns and partitions them by ``bus``), each protocol keeps its own bus name."""
    import pyarrow.parquet as pq

    pairs = set()
    for traffic, folder in ((SERIAL, tmp_path / "a"), (MODBUS, tmp_path / "b")):
        folder.mkdir()
        _, run, _ = record_live(folder, pty, traffic)
        out = folder / "records.parquet"
        res = subprocess.run(
            [sys.executable, "-m", "analyzer", "decode", str(run), "-f", "parquet", "-o", str(out)],
            capture_output=True, text=True, env=ENV, cwd=ROOT, timeout=300,
        )  # fmt: skip
        assert res.returncode == 0, res.stderr
        table = pq.read_table(out, columns=["bus", "protocol"])
        pairs |= set(zip(table["bus"].to_pylist(), table["protocol"].to_pylist(), strict=True))
    assert pairs == {("rs232", "eg2-serial"), ("rs485", "modbus-rtu")}


# -- the namer on its own ----------------------------------------------------------------------


class _Port(Tap):
    named_by_protocol = True

    def start(self, out: object) -> None:
        pass

    def stop(self) -> None:
        pass


def _chunk(data: bytes, t: float, stream: str = "/dev/ttyUSB0") -> Item:
    return Item("serial", Chunk(data, t), stream)


def test_events_pass_at_once_and_bytes_wait_for_their_name() -> None:
    tap = _Port("serial")
    namer = BusNamer([tap])
    opened = SourceEvent(1.0, "serial", INFO, "opened /dev/ttyUSB0", "open")
    first = namer.sort([opened, _chunk(MODBUS[:5], 2.0)])
    assert first == [opened]  # a person sees the port open; the bytes wait
    second = namer.sort([_chunk(MODBUS[5:], 2.1)])
    assert [type(x).__name__ for x in second] == ["SourceEvent", "Item", "Item"]
    assert second[0].message == "Modbus RTU detected: bus named rs485" and second[0].t == 2.0
    assert [x.bus for x in second] == ["rs485"] * 3 and tap.bus == "rs485"
    assert namer.protocols == {"rs485": "modbus-rtu"}
    later = namer.sort([_chunk(b"\x00", 3.0), SourceEvent(3.1, "serial", INFO, "x", "info")])
    assert [x.bus for x in later] == ["rs485", "rs485"]


def test_a_loss_decides_the_name_so_the_bytes_before_it_end_there() -> None:
    namer = BusNamer([_Port("serial")])
    lost = SourceEvent(5.0, "serial", WARNING, "lost /dev/ttyUSB0", "lost")
    out = namer.sort([_chunk(b"\xeb\x90\x01", 4.0), lost])
    assert [(type(x).__name__, x.bus) for x in out] == [
        ("SourceEvent", "rs232"),  # no frame showed: the decoding's choice, the serial protocol
        ("Item", "rs232"),
        ("SourceEvent", "rs232"),
    ]
    assert out[-1].kind == "lost"


def test_a_tap_that_captured_nothing_keeps_its_provisional_name() -> None:
    tap = _Port("serial")
    namer = BusNamer([tap])
    closed = SourceEvent(1.0, "serial", INFO, "closed", "closed")
    assert namer.sort([closed]) == [closed]
    assert namer.finish() == [] and tap.bus == "serial"


def test_a_line_of_noise_is_named_once_the_sample_is_full() -> None:
    namer = BusNamer([_Port("serial")])
    assert namer.sort([_chunk(bytes(2000), 1.0)]) == []
    out = namer.sort([_chunk(bytes(3000), 2.0)])
    assert out[0].message == "the regular serial protocol detected: bus named rs232"
    assert len(out) == 3
