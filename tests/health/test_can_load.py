"""A CAN bus's load in ``stats``, against a second count of the bits (tests/can_wire.py: the
frame as a string of fields, a bit-serial CRC, stuff bits inserted; no code of
decoders/can_bits.py or its native mirror): a candump log of known frames at known times,
through the real command and through a session on each engine."""

from __future__ import annotations

import math
import random
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
from health_helpers import ENGINES, cli_buses, session_buses, wire_bits, write_candump

from decoders.build import can_id
from decoders.model import CanFrame

BITRATE = 500_000
T0 = 1_763_700_000.25  # a quarter into a second: the first and last seconds are partial
SECONDS = 30
SILENT = 17  # a whole second without a frame: 0 % load, and it counts


def traffic(seed: int = 7) -> list[CanFrame]:
    """EG2 frames and a few standard and remote ones, 20 to 300 in each second."""
    rng = random.Random(seed)
    frames = []
    for second in range(SECONDS):
        if second == SILENT:
            continue
        lo = T0 if second == 0 else math.floor(T0) + second
        n = rng.randint(20, 300)
        for t in sorted(rng.uniform(lo, math.floor(T0) + second + 0.999) for _ in range(n)):
            frames.append(frame(rng, round(t, 6)))
    return frames


def frame(rng: random.Random, t: float) -> CanFrame:
    kind = rng.random()
    data = bytes(rng.choice((0, 0xFF, rng.randrange(256))) for _ in range(rng.randint(0, 8)))
    if kind < 0.1:  # other traffic: a standard identifier
        return CanFrame(t, rng.randrange(0x800), data, is_extended=False)
    aid = can_id(rng.randrange(2), rng.choice((1128, 1120, 1064)), rng.randint(1, 3))
    return CanFrame(t, aid, data)


def expected(frames: list[CanFrame], bitrate: int) -> dict[str, Any]:
    """The figures docs/contracts.md defines, from the second count of the bits."""
    bits = [wire_bits(f) for f in frames]
    first = min(range(len(frames)), key=lambda i: frames[i].t or 0.0)
    start = (frames[first].t or 0.0) - bits[first] / bitrate
    end = max(f.t or 0.0 for f in frames)
    per_second: Counter[int] = Counter()
    for f, b in zip(frames, bits, strict=True):
        per_second[math.floor(f.t or 0.0)] += b
    whole = range(math.ceil(start), math.floor(end))  # seconds the span covers whole
    loads = sorted(100 * per_second[s] / bitrate for s in whole)
    return {
        "frames": len(frames),
        "bits": sum(bits),
        "duration_s": pytest.approx(end - start, abs=1e-6),
        "frames_per_s": pytest.approx(len(frames) / (end - start), abs=1e-3),
        "load_pct": {
            "mean": pytest.approx(100 * sum(bits) / bitrate / (end - start), abs=1e-3),
            "p95": pytest.approx(loads[math.ceil(0.95 * len(loads)) - 1], abs=1e-3),
            "max": pytest.approx(loads[-1], abs=1e-3),
        },
    }


def figures(bus: dict[str, Any]) -> dict[str, Any]:
    return {k: bus[k] for k in ("frames", "bits", "duration_s", "frames_per_s", "load_pct")}


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[CanFrame]]:
    frames = traffic()
    return write_candump(tmp_path_factory.mktemp("load") / "cell.log", frames), frames


def test_the_traffic_has_a_silent_second_and_seconds_of_every_load(log) -> None:
    _, frames = log
    seconds = Counter(math.floor(f.t or 0.0) for f in frames)
    assert math.floor(T0) + SILENT not in seconds and len(set(seconds.values())) > 20


@pytest.mark.parametrize("engine", ENGINES)
def test_load_on_each_engine_is_the_second_count(log, engine: str) -> None:
    path, frames = log
    (bus,), session = session_buses(path, engine)
    assert (bus["bus"], bus["kind"], bus["bitrate"], bus["bitrate_from"]) == (
        "can0", "can", BITRATE, "default")  # fmt: skip
    assert figures(bus) == expected(frames, BITRATE)
    assert bus["uncounted_frames"] == 0 and bus["timing"] is None
    if engine == "native":  # the health listener did not cost the native read of the log
        assert session.source.frames is not None


def test_load_from_the_command_at_a_bitrate_given(log) -> None:
    path, frames = log
    (bus,) = cli_buses(path, "--bitrate", "250000")
    assert (bus["bitrate"], bus["bitrate_from"]) == (250_000, "--bitrate")
    assert figures(bus) == expected(frames, 250_000)


def test_frames_without_times_have_bits_but_no_load(tmp_path: Path) -> None:
    frames = traffic()[:50]
    lines = [f"can0 {f.arbitration_id:08X}#{f.data.hex()}" for f in frames if f.is_extended]
    path = tmp_path / "untimed.log"
    path.write_text("\n".join(lines) + "\n")
    (bus,) = cli_buses(path)
    sent = [f for f in frames if f.is_extended]
    assert bus["bits"] == sum(map(wire_bits, sent)) and bus["frames"] == len(sent)
    assert bus["timing"] == "no timing in this capture"
    assert bus["load_pct"] == {"mean": None, "p95": None, "max": None}
    assert bus["frames_per_s"] is None and bus["duration_s"] is None


def test_remote_and_fd_frames(tmp_path: Path) -> None:
    # a remote frame has no data field whatever its DLC; CAN FD frames are not counted
    path = tmp_path / "kinds.log"
    path.write_text(
        "(100.000000) can0 123#R4\n"
        "(100.100000) can0 0118C001##1" + "00" * 12 + "\n"
        "(100.200000) can0 01180001#04\n"
    )
    (bus,) = cli_buses(path)
    remote = CanFrame(100.0, 0x123, b"", is_extended=False, is_remote=True, dlc=4)
    assert bus["bits"] == wire_bits(remote) + wire_bits(CanFrame(100.2, 0x01180001, b"\x04"))
    assert (bus["frames"], bus["uncounted_frames"]) == (3, 1)
