"""CAN error frames in ``stats``: counted by class (linux/can/error.h), the error counters read
where a frame carries them, and the error-passive and bus-off periods. The frames are real
SocketCAN layouts: candump log lines (the identifier with CAN_ERR_FLAG, as candump writes an
error frame, and its ``ERRORFRAME`` form) and python-can error frames on its virtual bus,
captured by a live tap."""

from __future__ import annotations

import threading
import time
import uuid
from pathlib import Path
from typing import Any

import can
import pytest
from health_helpers import ENGINES, cli_buses, session_buses

from analyzer.health.listener import HealthListener
from analyzer.session.session import live_session
from analyzer.sources.can_tap import CanTap
from analyzer.sources.live import wait_open
from decoders.can_errors import error_report

CAN_ERR_FLAG = 0x20000000
# (time, class, data) as a SocketCAN driver reports a controller going downhill and back
EPISODE = [
    (10.0, 0x004 | 0x200, "0008000000006000"),  # controller: TX warning; counters 96/0
    (10.5, 0x008, "0000020800000000"),  # protocol violation (form error, in the ACK delimiter)
    (11.0, 0x004 | 0x200, "0020000000008000"),  # controller: TX passive; counters 128/0
    (11.2, 0x020, "0000000000000000"),  # no ACK
    (12.0, 0x040, "0000000000000000"),  # bus off
    (13.5, 0x100, "0000000000000000"),  # controller restarted: error active again
    (14.0, 0x001, "0000000000000000"),  # TX timeout
    (14.1, 0x002, "0000000000000000"),  # lost arbitration
    (14.2, 0x010, "0000000000000000"),  # transceiver
    (14.3, 0x004, "0010000000000000"),  # controller: RX passive (no counters)
    (14.4, 0x080, "0000000000000000"),  # bus error
    (15.0, 0x004, "0040000000000000"),  # controller: error active again
    (16.0, 0x040, "0000000000000000"),  # bus off, still when the capture ends
]
COUNTS = {"total": 13, "tx_timeout": 1, "lost_arbitration": 1, "controller": 4,
          "error_warning": 1, "error_passive": 2, "protocol_violation": 1, "transceiver": 1,
          "no_ack": 1, "bus_off": 2, "bus_error": 1, "restarted": 1, "unspecified": 0}  # fmt: skip
PERIODS = [
    {"start": 11.0, "end": 12.0, "state": "error_passive", "to_end": False},
    {"start": 12.0, "end": 13.5, "state": "bus_off", "to_end": False},
    {"start": 14.3, "end": 15.0, "state": "error_passive", "to_end": False},
    {"start": 16.0, "end": 16.5, "state": "bus_off", "to_end": True},
]


def test_reports_read_the_layout() -> None:
    warning = error_report(0x204, bytes.fromhex("0008000000006000"))
    assert warning.keys == ("controller", "error_warning")
    assert (warning.state, warning.tx_errors, warning.rx_errors) == ("error_warning", 0x60, 0)
    passive = error_report(0x004, bytes.fromhex("0010000000000000"))
    assert (passive.keys, passive.state, passive.tx_errors) == (
        ("controller", "error_passive"), "error_passive", None)  # fmt: skip
    assert error_report(0x040, bytes(8)).state == "bus_off"
    assert error_report(0x100, bytes(8)).state == "error_active"
    assert error_report(0, b"").keys == ("unspecified",)
    # an older driver fills the counters without CAN_ERR_CNT
    assert error_report(0x004, bytes.fromhex("0020000000008805")).rx_errors == 5


def episode_log(path: Path) -> Path:
    lines = [f"({t:.6f}) can0 {CAN_ERR_FLAG | cls:08X}#{data}" for t, cls, data in EPISODE[:-1]]
    t, cls, data = EPISODE[-1]  # candump's other form: the mark after the data
    spaced = " ".join(data[i : i + 2] for i in range(0, 16, 2))
    lines.append(f" ({t:.6f})  can0  {CAN_ERR_FLAG | cls:08X}   [8]  {spaced}   ERRORFRAME")
    lines.append("(16.500000) can0 01180001#04")  # the capture goes on after the last one
    path.write_text("\n".join(lines) + "\n")
    return path


def error_figures(bus: dict[str, Any]) -> tuple[Any, ...]:
    return bus["error_frames"], bus["error_counters"], bus["error_states"]


@pytest.mark.parametrize("engine", ENGINES)
def test_an_episode_on_each_engine(tmp_path: Path, engine: str) -> None:
    (bus,), _ = session_buses(episode_log(tmp_path / "episode.log"), engine)
    counters = {"tx": 128, "rx": 0, "tx_max": 128, "rx_max": 0}
    assert error_figures(bus) == (COUNTS, counters, PERIODS)
    assert bus["frames"] == 1  # error frames are reports, not frames on the wire: no bits
    assert bus["bits"] == cli_buses(tmp_path / "episode.log")[0]["bits"]


def test_the_command_says_it(tmp_path: Path) -> None:
    (bus,) = cli_buses(episode_log(tmp_path / "episode.log"))
    assert error_figures(bus)[0] == COUNTS and bus["error_states"] == PERIODS


def test_error_frames_from_python_can_on_a_live_tap() -> None:
    channel = f"eg2scope-health-{uuid.uuid4().hex}"
    health = HealthListener()
    session = live_session([CanTap("can0", "virtual", channel)], [health])
    thread = threading.Thread(target=session.run, daemon=True)
    thread.start()
    assert wait_open(session.source.taps, 5.0)
    with can.Bus(interface="virtual", channel=channel) as bus:
        for _, cls, data in EPISODE:
            bus.send(can.Message(arbitration_id=cls, data=bytes.fromhex(data),
                                 is_error_frame=True, is_extended_id=True))  # fmt: skip
            time.sleep(0.01)
        bus.send(can.Message(arbitration_id=0x01180001, data=b"\x04"))
        time.sleep(0.3)
    session.stop()
    thread.join(5)
    (got,) = health.buses()
    assert got["error_frames"] == COUNTS and got["frames"] == 1
    states = got["error_states"]
    assert [s["state"] for s in states] == [p["state"] for p in PERIODS]
    assert all(s["start"] < s["end"] for s in states) and states[-1]["to_end"]
